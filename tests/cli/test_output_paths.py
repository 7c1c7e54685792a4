"""Outputs stay where the user put them: names taken from input files are sanitized, and every
file a subcommand writes lies inside its --out (or -o) folder; a test per subcommand."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from simfab.errors import InputError
from simfab.io.atomic import write_text
from simfab.io.outpaths import check_out_dir, confine, safe_name

ROOT = Path(__file__).resolve().parents[2]
SCENES = ROOT / "scenes"


def _run(argv, cwd):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-m", "simfab", *argv, "--json"], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=600)


def _files(d: Path) -> set:
    return {p for p in d.rglob("*") if p.is_file()}


@pytest.mark.parametrize("name, expected", [("../../x", "x"), ("/etc/passwd", "etc_passwd"), ("..", "unnamed"),
                                            (".hidden", "hidden"), ("a b/c", "a_b_c"),
                                            ("ok-name_1.v2", "ok-name_1.v2")])
def test_safe_name(name, expected):
    assert safe_name(name) == expected


def test_confine_refuses_paths_outside(tmp_path):
    out = tmp_path / "out"
    with confine([out]):
        write_text(out / "a" / "ok.txt", "x")
        with pytest.raises(InputError, match="outside the output folder"):
            write_text(out / ".." / "escape.txt", "x")
        (tmp_path / "link").symlink_to(tmp_path)
        with pytest.raises(InputError):
            write_text(out / ".." / "link" / "escape.txt", "x")
    assert _files(tmp_path) == {out / "a" / "ok.txt"}


def test_check_out_dir(tmp_path):
    f = tmp_path / "f"
    f.write_text("")
    for bad in (f, f / "sub"):
        with pytest.raises(InputError, match="--out"):
            check_out_dir(bad)
    for empty in ("", "  "):  # --out "$UNSET"
        with pytest.raises(InputError, match="--out: is an empty path"):
            check_out_dir(empty)
    check_out_dir(tmp_path / "new" / "deeper")
    assert not (tmp_path / "new").exists()  # the check creates nothing


def test_unwritable_out_folder_is_refused_before_computing(tmp_path, monkeypatch, capsys):
    # the suite runs as root, for whom every folder is writable: the permission bits are what
    # os.access reports, so deny it for the chosen folder and check every command's answer
    import os

    from simfab.cli import main

    locked = tmp_path / "locked"
    locked.mkdir()
    real = os.access
    monkeypatch.setattr(os, "access",
                        lambda p, mode, **kw: False if os.path.abspath(p) == str(locked) else real(p, mode, **kw))
    with pytest.raises(InputError, match="no permission"):
        check_out_dir(locked / "sub")
    for argv in (["couple", "simulate", "cclamp2d", "--steps", "1"],
                 ["couple", "optimize", "block2d_tight", "--iterations", "1"], ["grow", "phone_stand"]):
        code = main(argv + ["--out", str(locked / "o")])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and "no permission" in err[0] and "--out" in err[0], (argv, err)
    assert list(locked.iterdir()) == []  # nothing written


def test_couple_scene_name_cannot_escape(tmp_path):
    src = SCENES / "coupling" / "cclamp2d"
    (tmp_path / "s.xml").write_text(src.with_suffix(".xml").read_text())
    toml = src.with_suffix(".toml").read_text().replace('name = "cclamp2d"', 'name = "../../escape"')
    (tmp_path / "s.toml").write_text(toml.replace("steps = 35", "steps = 2"))
    out = tmp_path / "a" / "b"
    r = _run(["couple", "simulate", str(tmp_path / "s.xml"), "--out", str(out)], tmp_path)
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    written = _files(tmp_path) - {tmp_path / "s.xml", tmp_path / "s.toml"}
    assert written and all(out in p.parents for p in written)
    assert Path(s["usd"]).name == "escape.usda"


def test_deploy_body_name_cannot_escape(tmp_path):
    xml = (SCENES / "deploy" / "unit_cell.xml").read_text().replace('name="insert_small"',
                                                                    'name="insert_/../../../../x"')
    (tmp_path / "cell.xml").write_text(xml)
    out = tmp_path / "a" / "b"
    r = _run(["deploy", "--scene", str(tmp_path / "cell.xml"), "--insert", "insert_/../../../../x", "--increments", "1",
              "--out", str(out)], tmp_path)
    assert r.returncode == 2 and "outside the output folder" in r.stderr
    assert _files(tmp_path) == {tmp_path / "cell.xml"}


def test_crowd_labels_do_not_name_files(tmp_path):
    (tmp_path / "truth.csv").write_text("task,truth\n../../t1,3\n/etc/t2,7\n")
    out = tmp_path / "o"
    r = _run(["crowd", "simulate", "--truth", str(tmp_path / "truth.csv"), "--scale", "1", "10", "--out", str(out)],
             tmp_path)
    assert r.returncode == 0, r.stderr
    assert all(out in p.parents for p in _files(tmp_path) - {tmp_path / "truth.csv"})


def test_grow_outputs_stay_in_out(tmp_path):
    out = tmp_path / "o"
    r = _run(["grow", str(SCENES / "growth" / "phone_stand.xml"), "--out", str(out)], tmp_path)
    assert r.returncode == 0, r.stderr
    assert _files(tmp_path) and all(out in p.parents for p in _files(tmp_path))
    # the skin written is clean: closed and without zero-area faces
    from simfab.io.mesh import read_mesh

    s = json.loads(r.stdout)
    _, rep = read_mesh(s["skin_stl"], units="mm")
    assert rep.watertight and rep.degenerate_faces == 0 and rep.duplicate_faces == 0
    from simfab.io import inspect_file

    assert inspect_file(s["skin_stl"], units="mm")["interior_faces"] == 0  # a valid solid: no false alarm
    # the preview's camera is saved for 'grow edit', and the bundled sample stroke edits this skeleton
    r = _run(["grow", "edit", s["skeleton_json"], "--stroke", str(SCENES / "growth" / "phone_stand_stroke.json"),
              "--camera", s["camera_json"], "--out", str(out / "edit")], tmp_path)
    assert r.returncode == 0, r.stderr
    e = json.loads(r.stdout)
    assert e["watertight"] and e["bodies"] == 1 and e["max_move"] > 0 and Path(e["png"]).stat().st_size > 1000


def test_render_and_inspect_write_only_where_asked(tmp_path):
    b = tmp_path / "in.xml"
    b.write_text('<mujoco><worldbody><geom type="sphere" size="0.1"/></worldbody></mujoco>\n')
    d = tmp_path / "pngs"
    d.mkdir()
    r = _run(["render", str(b), "-o", str(d), "--width", "64", "--height", "48"], tmp_path)  # -o DIR
    assert r.returncode == 0, r.stderr
    assert _files(tmp_path) == {b, d / "in.png"}
    r = _run(["inspect", str(b), "--out", str(tmp_path / "unused")], tmp_path)
    assert r.returncode == 0 and _files(tmp_path) == {b, d / "in.png"}


def test_validate_outputs_stay_in_out(tmp_path):
    out = tmp_path / "o"
    r = _run(["validate", "buckling", "--n", "8", "--g-over-L", "0.9", "--support", "pinned", "--path", "direct",
              "--out", str(out)], tmp_path)
    assert r.returncode in (0, 1), r.stderr  # n = 8 is coarse; only the location matters here
    assert _files(tmp_path) and all(out in p.parents for p in _files(tmp_path))


def test_demo_outputs_stay_in_out(tmp_path):
    out = tmp_path / "o"
    r = _run(["demo", "--only", "deploy", "--out", str(out)], tmp_path)
    assert r.returncode == 0, r.stderr
    assert _files(tmp_path) and all(out in p.parents for p in _files(tmp_path))


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs Linux's /proc, where nothing can be created")
def test_a_folder_where_nothing_can_be_created_is_refused_before_computing(capsys):
    # os.access says yes to root everywhere (the suite runs as root): /proc takes no new folder, and
    # the run would otherwise fail only at its first output, after the whole simulation (an internal
    # error, exit 1)
    from simfab.cli import main

    with pytest.raises(InputError, match="cannot create anything in /proc"):
        check_out_dir("/proc/simfab-out-test/sub")
    code = main(["couple", "simulate", "clip3d", "--out", "/proc/simfab-out-test"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("simfab: error: --out") and "cannot create" in err[0], err
    assert not os.path.exists("/proc/simfab-out-test")
