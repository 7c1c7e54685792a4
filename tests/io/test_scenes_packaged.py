"""The bundled scenes are found through the package (simfab/scenes), so a wheel install finds them
too: in a checkout simfab/scenes is a link to the top-level scenes/ folder, and the wheel's package
data copies that folder (pyproject's package-data)."""

import tomllib
from pathlib import Path

from simfab._bundled import scenes_dir

ROOT = Path(__file__).resolve().parents[2]


def test_package_scenes_are_the_top_level_scenes_folder():
    for part in ("coupling", "crowd", "deploy", "growth"):
        assert scenes_dir(part).samefile(ROOT / "scenes" / part)
    assert (scenes_dir("coupling") / "clip3d.toml").is_file()


def test_wheel_package_data_includes_the_scenes():
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "scenes/**/*" in cfg["tool"]["setuptools"]["package-data"]["simfab"]
