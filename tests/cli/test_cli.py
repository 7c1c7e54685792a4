"""The simfab command in-process: help, exit codes, one-line errors, JSON output."""

import json

import pytest
import trimesh

from simfab.cli import SUBCOMMANDS, main
from simfab.io.mjcf import MJCFBuilder


def test_help_and_subcommand_help(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    for name in SUBCOMMANDS:
        assert name in out
    for name in SUBCOMMANDS:
        assert main([name, "--help"]) == 0, name
    capsys.readouterr()


def test_no_command_is_usage_error(capsys):
    assert main([]) == 2


def test_unknown_flag_one_line(capsys):
    assert main(["render", "--bogus"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("simfab: error:") and "\n" not in err and "Traceback" not in err


def test_missing_file_exit_2(tmp_path, capsys):
    assert main(["inspect", str(tmp_path / "nope.stl")]) == 2
    err = capsys.readouterr().err.strip()
    assert "nope.stl: file not found" in err and len(err.splitlines()) == 1


def test_inspect_broken_mesh_json(tmp_path, capsys):
    box = trimesh.creation.box()
    trimesh.Trimesh(box.vertices, box.faces[:-1]).export(tmp_path / "open.stl")
    assert main(["inspect", str(tmp_path / "open.stl"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["watertight"] is False and any("watertight" in p for p in out["problems"])


def test_render_mjcf_and_json(tmp_path, capsys):
    b = MJCFBuilder("r")
    b.floor()
    b.geom(b.body("ball", pos=[0, 0, 0.2]), type="sphere", size=0.1, rgba=[0.2, 0.6, 0.9, 1])
    xml = b.save(tmp_path / "r.xml")
    assert main(["render", str(xml), "-o", str(tmp_path / "r.png"), "--width", "120", "--height", "90", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["png"].endswith("r.png") and (tmp_path / "r.png").stat().st_size > 1000


def test_bad_device_is_input_error(capsys):
    assert main(["--device", "tpu", "inspect", "x"]) == 2


def test_cuda_without_a_driver_is_one_line(tmp_path, capfd):
    # on a machine without CUDA, --device cuda is bad input: exit 2 and one line on stderr (also at
    # the file-descriptor level, where Warp's native library would print its driver errors)
    from simfab._warp import wp

    if wp.is_cuda_available():
        pytest.skip("CUDA is available here")
    out = tmp_path / "o"
    assert main(["couple", "simulate", "cclamp2d", "--device", "cuda", "--out", str(out)]) == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--device" in err[0] and "cuda" in err[0]
    assert not out.exists() or not any(out.iterdir())


def test_internal_error_exit_1(monkeypatch, capsys):
    import simfab.cli.inspect_ as mod

    def boom(args):
        raise RuntimeError("kaboom")

    monkeypatch.setattr(mod, "run", boom)
    assert main(["inspect", "x"]) == 1
    err = capsys.readouterr().err
    assert "internal error" in err and "Traceback" not in err


@pytest.mark.parametrize("outcome, code", [(None, 0), ("input", 2), ("internal", 1)])
def test_numeric_warnings_show_after_success_and_never_before_an_error(monkeypatch, capsys, outcome, code):
    # a NumPy RuntimeWarning raised on the way to an error must not precede the one error line
    import warnings

    import numpy as np

    import simfab.cli.inspect_ as mod
    from simfab.errors import InputError

    def run(args):
        np.divide(np.zeros(1), np.zeros(1))  # RuntimeWarning: invalid value encountered in divide
        if outcome == "input":
            raise InputError("bad field", where="f.toml")
        if outcome == "internal":
            raise RuntimeError("kaboom")
        return {"ok": 1}

    monkeypatch.setattr(mod, "run", run)
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        assert main(["inspect", "x"]) == code
    err = capsys.readouterr().err.strip().splitlines()
    if outcome is None:
        assert err == ["simfab: warning: invalid value encountered in divide"]
    else:
        assert len(err) == 1 and err[0].startswith("simfab: error: f.toml" if code == 2 else "simfab: internal error")


def test_python_dash_m_entry_point():
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "simfab", "--version"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and "simfab" in r.stdout


def test_import_is_light():
    # `import simfab` (and so `simfab --help`) must not pull in the heavy libraries: they load on demand.
    # Asserted on the modules imported, not on a wall time (timed tests flake on a loaded machine).
    import subprocess
    import sys

    code = ("import sys; b=set(sys.modules); import simfab, simfab.cli; "
            "print(' '.join(sorted({m.split('.')[0] for m in set(sys.modules)-b})))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    heavy = {"warp", "mujoco", "pxr", "trimesh", "scipy", "igl", "pytetwild", "matplotlib"}
    assert not heavy & set(r.stdout.split()), r.stdout


def test_demo_runs_a_pipeline_and_reports_json(tmp_path, capsys):
    # the fastest pipeline stands for all: the demo wiring, output folder and JSON summary
    assert main(["demo", "--only", "deploy", "--out", str(tmp_path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["out"] == str(tmp_path)
    res = out["pipelines"]["deploy"]
    assert res["seconds"] > 0
    written = [p for p in (tmp_path / "deploy").rglob("*") if p.is_file()]
    assert any(p.suffix == ".usda" for p in written) and any(p.suffix == ".xml" for p in written)
    assert not [p for p in written if ".tmp" in p.name]  # atomic writes leave no temporaries


def test_inspect_closed_stl_has_no_problems(tmp_path, capsys):
    # STL repeats every corner; shared vertices must not be reported as an open mesh
    trimesh.creation.box().export(tmp_path / "box.stl")
    assert main(["inspect", str(tmp_path / "box.stl"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["watertight"] is True and out["problems"] == [] and out["vertices"] == 8
