"""The structural check gives the same mesh and figures, bit for bit, in two separate processes."""

import json
import os
import pathlib
import subprocess
import sys

from simfab.cli import main

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCENES = ROOT / "scenes" / "growth"
#: figures that depend on time or on the output folder
VOLATILE = {"seconds_check", "check_usd", "check_png", "skeleton", "outputs"}


def _check_in_subprocess(skeleton: pathlib.Path, out: pathlib.Path) -> dict:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    p = subprocess.run([sys.executable, "-m", "simfab", "grow", "check", str(skeleton), "--out", str(out), "--json",
                        "--quiet"], capture_output=True, text=True, env=env, timeout=600)
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout)


def test_two_processes_give_identical_check_figures(tmp_path, capsys, require_gmsh):
    """A grown phone stand (branched, the objects carved out) checked in two fresh processes: the
    same tet count and the same safety factor, stresses, deflections and forces, bit for bit
    (fTetWild, the former mesher, moved the safety factor by +-12 % from run to run)."""
    grown = tmp_path / "grown"
    assert main(["grow", str(SCENES / "phone_stand.xml"), "--attractors", "800", "--out", str(grown), "--quiet"]) == 0
    capsys.readouterr()
    skeleton = grown / "phone_stand_skeleton.json"
    a = _check_in_subprocess(skeleton, tmp_path / "a")
    b = _check_in_subprocess(skeleton, tmp_path / "b")
    assert a["mesher"] == "gmsh"
    assert a["tets"] > 1000 and a["tets"] == b["tets"] and a["fem_nodes"] == b["fem_nodes"]
    assert 0 < a["safety_factor"] < float("inf")
    for key in sorted(set(a) - VOLATILE):
        assert a[key] == b[key], key  # exact: the same mesh and the same arithmetic in both processes
