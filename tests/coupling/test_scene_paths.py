"""Scene names resolve to the bundled scenes unless a scene file of that name exists here."""

import os

from simfab.coupling.scene import bundled_dir, scene_paths


def test_a_folder_named_like_a_bundled_scene_does_not_hide_it(tmp_path):
    cwd = os.getcwd()
    try:
        os.chdir(tmp_path)
        (tmp_path / "cclamp2d").mkdir()  # e.g. `simfab couple simulate cclamp2d --out cclamp2d` ran before
        assert scene_paths("cclamp2d")[0] == bundled_dir() / "cclamp2d.xml"
        (tmp_path / "cclamp2d.xml").write_text("<mujoco/>")  # a local scene file wins
        assert scene_paths("cclamp2d")[0].resolve() == (tmp_path / "cclamp2d.xml").resolve()
    finally:
        os.chdir(cwd)
