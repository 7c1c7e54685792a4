"""Where the bundled scenes live.

``simfab/scenes`` is a link to the repository's top-level ``scenes/`` folder in a source checkout
(an editable install reads them there) and a copy of that folder inside a built wheel (package
data), so ``pip install .`` finds the same scenes.
"""

from __future__ import annotations

from pathlib import Path

SCENES = Path(__file__).resolve().parent / "scenes"


def scenes_dir(*parts: str) -> Path:
    """Path of a bundled scene folder or file, e.g. ``scenes_dir("coupling")``."""
    return SCENES.joinpath(*parts)
