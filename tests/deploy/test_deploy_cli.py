"""``simfab validate buckling`` and ``simfab deploy`` through the CLI: outputs, --json, bad input."""

import json

import mujoco
import numpy as np
import pytest

from simfab.cli import main
from simfab.errors import InputError


def test_validate_buckling_small_case_writes_outputs(tmp_path, capsys):
    out = tmp_path / "vb"
    rc = main(["validate", "buckling", "--n", "20", "40", "--g-over-L", "0.9", "--support", "pinned",
               "--path", "direct", "--out", str(out), "--json"])
    assert rc == 0
    res = json.loads(capsys.readouterr().out)
    rows = res["rows"]
    assert len(rows) == 2
    for key in ("support", "g_over_L", "n", "delta_over_L", "delta_over_L_exact", "rel_err", "force_rel_err",
                "seconds"):
        assert key in rows[0]
    assert [r["increments"] for r in rows] == [1, 1]  # g/L 1 -> 0.9 is one step of the scene's beam_max_increment 0.1
    assert res["convergence_order"]["pinned"] == pytest.approx(2.0, abs=0.2)
    for f in ("buckling.csv", "buckling.json", "buckling_shapes.png"):
        assert (out / f).stat().st_size > 0


@pytest.mark.parametrize("argv", [
    ["validate", "buckling", "--g-over-L", "1.5"],
    ["validate", "buckling", "--n", "21"],
    ["validate", "buckling", "--n", "abc"],
    ["validate", "buckling", "--support", "hinged"],
    ["validate", "buckling", "--scene", "/nonexistent.xml"],
    ["validate"],
    ["deploy", "--insert", "no_such_insert"],
    ["deploy", "--increments", "0"],
    ["deploy", "--scene", "/nonexistent.xml"],
])
def test_bad_input_exits_2_without_outputs(argv, tmp_path, capsys):
    out = tmp_path / "o"
    assert main(argv + ["--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("simfab: error:") and len(err.strip().splitlines()) == 1
    assert not out.exists()


@pytest.mark.parametrize("rods", ["capsules", "flexcomp", "chain"])
def test_deploy_cli_small_insert(tmp_path, capsys, rods):
    out = tmp_path / "dep"
    assert main(["deploy", "--insert", "insert_small", "--increments", "4", "--mjcf-rods", rods,
                 "--out", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)["inserts"]["insert_small"]
    assert res["kind"] == "saddle"
    m = mujoco.MjModel.from_xml_path(res["outputs"]["mjcf"])
    if rods == "capsules":
        assert m.nbody >= 2 and m.ngeom > 100
    elif rods == "flexcomp":
        assert m.nflex == 16 and m.flex_dim[0] == 1
    else:  # simulatable: free insert and junctions, rods welded, deployed keyframe
        assert m.nkey == 2 and m.neq == 16 and m.nv > 100
    if rods != "capsules":  # the scene steps 2 s from its start (the deployed key) without blowing up
        d = mujoco.MjData(m)
        if m.nkey:
            mujoco.mj_resetDataKeyframe(m, d, 0)
        mujoco.mj_forward(m, d)
        x0 = d.xpos.copy()
        for _ in range(int(round(2.0 / m.opt.timestep))):
            mujoco.mj_step(m, d)
        assert np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel))
        from simfab.deploy.mjcf_sim import aligned_drift

        # the scene floats freely: shape change after the best rigid alignment [m]; the cell is 80 mm wide
        assert aligned_drift(x0[1:], d.xpos[1:]) < 0.01
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(res["outputs"]["usd"])
    assert stage.GetEndTimeCode() == 4
    rods = stage.GetPrimAtPath("/World/deploy/rods")
    strain = UsdGeom.PrimvarsAPI(rods).GetPrimvar("bending_strain")
    assert len(strain.Get(4)) == len(UsdGeom.BasisCurves(rods).GetPointsAttr().Get(4))
    assert max(strain.Get(0)) < 1e-9  # flat start is unstrained
    assert 0 < res["max_bending_strain"] < 0.1


def test_validation_failure_exits_1_after_writing_outputs(tmp_path, capsys):
    """A soft axial stiffness (extensible beam) misses the inextensible elastica at n = 80: exit 1."""
    from simfab.deploy.buckling import elastica_scene_path

    text = open(elastica_scene_path()).read().replace('name="beam_axial_ratio" data="1e8"',
                                                     'name="beam_axial_ratio" data="300"')
    scene = tmp_path / "soft.xml"
    scene.write_text(text)
    out = tmp_path / "vb"
    rc = main(["validate", "buckling", "--scene", str(scene), "--n", "80", "--g-over-L", "0.9", "--support", "pinned",
               "--path", "direct", "--out", str(out), "--quiet"])
    assert rc == 1
    assert "missed tolerance" in capsys.readouterr().err
    rows = json.loads((out / "buckling.json").read_text())["rows"]
    assert rows[0]["passed"] is False


@pytest.mark.parametrize("cmd, scene, field", [
    (["deploy"], "unit_cell.xml", "cell_young"),
    (["validate", "buckling"], "elastica.xml", "beam_thickness"),
])
def test_non_positive_scene_parameter_is_named(cmd, scene, field, tmp_path, capsys):
    """A scene parameter that is not positive: exit 2, the one-line error names the <numeric> field."""
    from pathlib import Path

    src = Path(__file__).resolve().parents[2] / "scenes" / "deploy" / scene
    text = src.read_text()
    start = text.index(f'<numeric name="{field}" data="') + len(f'<numeric name="{field}" data="')
    bad = tmp_path / scene
    bad.write_text(text[:start] + "-1" + text[text.index('"', start):])
    out = tmp_path / "o"
    assert main(cmd + ["--scene", str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{field}: must be a positive number (got -1" in err
    assert not out.exists()


def test_deploy_failure_while_writing_leaves_no_output_files(tmp_path, monkeypatch):
    """Outputs of all inserts and the summary appear together: a writer failing halfway leaves none."""
    import argparse

    from simfab.cli import deploy as cli_deploy
    from simfab.deploy import export

    def broken_png(png, mjcf_path):
        raise RuntimeError("renderer unavailable")

    monkeypatch.setattr(export, "write_png", broken_png)
    out = tmp_path / "dep"
    args = argparse.Namespace(out=str(out), seed=0, device="cpu", quiet=True, json=False, scene=None,
                              insert=["insert_small"], increments=2, mjcf_rods="capsules")
    with pytest.raises(RuntimeError, match="renderer unavailable"):
        cli_deploy.run(args)
    assert not [p for p in out.rglob("*") if p.is_file()]


def test_a_bad_pattern_value_names_its_file_and_field_once(tmp_path, capsys):
    scene = tmp_path / "cap.toml"
    scene.write_text('[target]\nkind = "spherical_cap"\nradius = 0.15\nangle_deg = 50\n'
                     '[pattern]\ninsert_half_sizes = [-1.0]\n')
    out = tmp_path / "o"
    assert main(["deploy", "surface", str(scene), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"simfab: error: {scene}: pattern.insert_half_sizes: entry 0 must be a positive number "
                   "(got -1.0)")
    assert not out.exists()


def test_cell_library_call_writes_nothing_without_out_and_matches_the_cli(tmp_path, capsys):
    """simfab.deploy.cell: the CLI's figures, a frozen typed result, no file without ``out``."""
    import dataclasses

    import simfab.deploy

    res = simfab.deploy.cell(inserts=["insert_small"], increments=2)
    assert res.outputs == {} and res.summary_json is None and res.inserts["insert_small"].outputs == {}
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.scene = ""
    ins = res.inserts["insert_small"]
    assert ins.kind == "saddle" and len(ins.deployment.states) == 3  # flat + 2 increments
    out = tmp_path / "dep"
    assert main(["deploy", "--insert", "insert_small", "--increments", "2", "--out", str(out), "--json"]) == 0
    cli = json.loads(capsys.readouterr().out)
    lib = res.to_json()
    assert list(lib) == list(cli) == ["scene", "inserts", "summary_json"]
    c, li = cli["inserts"]["insert_small"], lib["inserts"]["insert_small"]
    assert list(li) == list(c)
    assert {k: v for k, v in li.items() if k != "outputs"} == {k: v for k, v in c.items() if k != "outputs"}
    assert json.loads((out / "deploy.json").read_text()) == cli
    with pytest.raises(InputError, match="increments"):
        simfab.deploy.cell(increments=0, out=str(tmp_path / "x"))
    assert not (tmp_path / "x").exists()
