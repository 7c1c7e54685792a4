"""Access to the published reference figures in ``../shared/reference/figures.json``."""

from __future__ import annotations

import json
import os
import pathlib

_CANDIDATES = [
    os.environ.get("SIMFAB_REFERENCE", ""),
    pathlib.Path(__file__).resolve().parents[3] / "shared" / "reference" / "figures.json",
    pathlib.Path.cwd().parent / "shared" / "reference" / "figures.json",
]


def figures() -> dict:
    """The reference figures, or ``{}`` when the shared folder is not beside the project."""
    for c in _CANDIDATES:
        if c and pathlib.Path(c).is_file():
            return json.loads(pathlib.Path(c).read_text())
    return {}


def required(key: str) -> dict:
    """One entry of the reference figures; a benchmark that needs it to define its run stops
    with a one-line message (exit 2) when the shared file is not beside the project."""
    entry = figures().get(key)
    if not entry:
        import sys

        print(f"bench: reference figure {key!r} not found: put ../shared/reference/figures.json beside the "
              "project or set SIMFAB_REFERENCE=/path/to/figures.json", file=sys.stderr)
        raise SystemExit(2)
    return entry
