"""``simfab couple``: outputs of a run, and bad input -> exit 2 with one line, no outputs."""

import json
import shutil

import numpy as np
import pytest

from simfab.cli import main
from simfab.coupling.scene import bundled_dir

SUMMARY_KEYS = {"category", "E_max", "E_ss", "coupling_ratio", "F_in", "F_rm", "F_grip", "max_von_mises",
                "averaged_von_mises", "stress_radius",
                "max_penetration", "min_det_F", "steps", "newton_iterations", "seconds", "profile_csv", "profile_json",
                "plot_png", "usd", "mjcf"}


def test_simulate_writes_profile_plot_usd_and_mjcf(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["couple", "simulate", "clip2d_loose", "--steps", "10", "--out", str(out), "--json"]) == 0
    stdout = capsys.readouterr().out
    summary = json.loads(stdout)  # exactly one JSON object
    assert SUMMARY_KEYS <= set(summary) and summary["steps"] == 10
    keys = list(summary)  # the averaged stress stands beside the raw element maximum
    assert keys[keys.index("max_von_mises") + 1] == "averaged_von_mises"
    assert 0 < summary["averaged_von_mises"] <= summary["max_von_mises"] and summary["stress_radius"] == 5e-4
    # the phase split covers the run's wall time once (each phase counted once, "other" the rest)
    phases = summary["phase_split"]
    assert {"warm_start", "newton", "facet_check", "record", "rigid_check", "other"} <= set(phases)
    assert min(phases.values()) >= -1e-6 and sum(phases.values()) == pytest.approx(summary["seconds"], rel=1e-9)
    assert phases["newton"] > 0 and phases["record"] > 0  # the loop's phases were timed, not left to "other"
    for k in ("profile_csv", "profile_json", "plot_png", "usd", "mjcf"):
        assert (out / summary[k].split("/")[-1]).is_file()
    rows = np.genfromtxt(summary["profile_csv"], delimiter=",", names=True)
    assert len(rows) == 11 and rows["energy_J"].max() == pytest.approx(summary["E_max"])
    from simfab.io.usd import read_mesh_at

    meshes = {name: V for name, V, F, rgb in read_mesh_at(summary["usd"], 10)}
    assert any("part" in k for k in meshes) and any("object" in k for k in meshes)
    # one colour scale for the timeline, its top the largest 99th percentile of the nodes' stress over the
    # records: below the largest element stress (one element's peak does not set it), above most nodes
    from pxr import UsdGeom

    from simfab.io.usd_read import open_stage, read_scalar_at

    stage = open_stage(summary["usd"])
    sc = read_scalar_at(stage, 10)
    part = next(p for p in stage.Traverse() if p.GetName() == "part")
    pv = UsdGeom.PrimvarsAPI(part).GetPrimvar("von_mises")
    nodes = [np.asarray(pv.Get(t), float) for t in range(11)]
    top = max(float(np.percentile(v, 99.0)) for v in nodes)
    assert sc.range[0] == 0.0 and sc.range[1] == pytest.approx(top, rel=1e-6)  # (the primvar: float32)
    assert sc.range[1] < summary["max_von_mises"] and sc.clipped == (max(v.max() for v in nodes) > sc.range[1])
    import mujoco

    m = mujoco.MjModel.from_xml_path(summary["mjcf"])
    assert m.nkey == 11
    # the path is a straight push: the viewer plays it on a slide joint driven by the 'insertion' control
    assert m.nq == 1 and m.nu == 1 and m.nmocap == 0
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    d.ctrl[:] = m.key_ctrl[10]
    for _ in range(int(1.0 / m.opt.timestep)):
        mujoco.mj_step(m, d)
    assert d.qpos[0] == pytest.approx(m.key_qpos[10, 0], abs=1e-6 * abs(m.key_qpos[10, 0]) + 1e-9)


def test_converge_writes_its_report_table_and_plot(tmp_path, capsys):
    # the study's three files hold the figures it prints: the JSON report, one CSV row per level
    # (values and relative errors), the plot of the errors
    out = tmp_path / "out"
    assert main(["couple", "converge", "cclamp2d", "--factors", "0.25,0.5,1", "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    files = summary["outputs"]
    assert sorted(p.name for p in out.iterdir()) == ["cclamp2d_converge.csv", "cclamp2d_converge.json",
                                                     "cclamp2d_converge.png"]
    assert {k: str(out / v.split("/")[-1]) for k, v in files.items()} == files
    rep = json.loads((out / "cclamp2d_converge.json").read_text())
    assert rep["figures"] == summary["figures"] and rep["levels"] == summary["levels"]
    rows = np.genfromtxt(files["csv"], delimiter=",", names=True, dtype=None, encoding="utf-8")
    assert len(rows) == 3 and list(rows["elements"]) == [lv["elements"] for lv in summary["levels"]]
    for k, unit in (("E_max", "J"), ("F_in", "N"), ("F_grip", "N")):
        assert np.allclose(rows[f"{k}_{unit}"], summary["figures"][k]["values"], rtol=1e-6)
        assert np.allclose(rows[f"{k}_relative_error"], summary["figures"][k]["relative_error"], rtol=1e-6,
                           atol=1e-12)
    from PIL import Image

    assert Image.open(files["png"]).size[0] > 400


@pytest.mark.parametrize("order", [1, 2])
def test_summary_reports_the_averaged_stress_the_yield_constraint_reads(order):
    # averaged_von_mises is the figure the design's yield constraint and its mesh check read
    # (simfab.design.verify.level_figures: element means for P1, quadrature-point means for P2);
    # averaging over a radius smaller than any element gives back the raw element maximum (P1)
    from simfab.coupling.insertion import averaged_stress, stress_radius
    from simfab.coupling.scene import load_coupling_scene
    from simfab.coupling.simulate import simulate_insertion
    from simfab.design.brief import DesignConfig
    from simfab.design.verify import level_figures

    overrides = {"simulation": {"steps": 4, "element_order": order}}
    res = simulate_insertion(load_coupling_scene("block2d_tight", overrides=overrides))
    r = stress_radius("block2d_tight")
    assert r == DesignConfig().stress_radius  # the scene's brief leaves the default
    got = averaged_stress(res, r)
    assert got == {"averaged_von_mises": pytest.approx(level_figures(res, r)["von_mises"], rel=1e-12),
                   "stress_radius": r}
    assert 0 < got["averaged_von_mises"] <= res.column("max_von_mises").max() * (1 + 1e-12)
    if order == 1:
        raw = averaged_stress(res, 1e-9)["averaged_von_mises"]
        assert raw == pytest.approx(res.column("max_von_mises").max(), rel=1e-12)
        assert got["averaged_von_mises"] < 0.99 * raw  # the radius does average at the block's corners


def test_a_failing_writer_leaves_no_output_file(tmp_path, monkeypatch):
    # the outputs of a run appear together: the MJCF writer failing after the CSV, plot and USD
    # were written leaves none of them (and no temporary) behind
    import simfab.coupling.outputs as outputs
    from simfab.coupling import run

    res = run("clip2d_loose", steps=3)

    def broken(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(outputs, "write_mjcf", broken)
    out = tmp_path / "out"
    with pytest.raises(OSError, match="disk full"):
        outputs.write_all(res, out)
    assert not out.exists() or not any(out.iterdir())


def _run_err(args, capsys):
    code = main(args)
    err = capsys.readouterr().err.strip().splitlines()
    return code, err


@pytest.mark.parametrize("args", [
    ["couple", "simulate", "no_such_scene"],
    ["couple", "simulate", "cclamp2d", "--steps", "0"],
    ["couple", "simulate", "cclamp2d", "--h-in", "-0.001"],
    ["couple", "simulate", "cclamp2d", "--fixed-axes", "xz"],  # a 2D part has no z axis
    ["couple", "simulate", "clip3d", "--fixed-axes", "yz"],  # must hold the insertion axis x
    ["couple", "simulate", "clip3d", "--fixed-axes", "xw"],
    ["couple", "converge", "cclamp2d", "--factors", "1"],  # a study needs two levels
    ["couple", "converge", "cclamp2d", "--factors", "1,x"],
    ["couple"],
])
def test_bad_arguments_exit_2_with_one_line(args, tmp_path, capsys):
    out = tmp_path / "out"
    code, err = _run_err(args + ["--out", str(out)], capsys)
    assert code == 2 and len(err) == 1 and err[0].startswith("simfab: error:")
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("edit, where", [
    (("[simulation]", "[simulation]\nstepz = 3"), "stepz"),
    (("samples = 50", "samples = 2"), "samples"),
    (('generator = "c_clamp"', 'generator = "spiral"'), "generator"),
    (("opening_deg = 60.0", "opening_deg = 200.0"), "opening_deg"),
    (('name = "PLA"', 'name = "unobtainium"'), "material"),
])
def test_bad_scene_files_exit_2_naming_the_field(edit, where, tmp_path, capsys):
    src = bundled_dir()
    shutil.copy(src / "cclamp2d.xml", tmp_path / "s.xml")
    text = (src / "cclamp2d.toml").read_text()
    assert edit[0] in text
    (tmp_path / "s.toml").write_text(text.replace(edit[0], edit[1]))
    out = tmp_path / "out"
    code, err = _run_err(["couple", "simulate", str(tmp_path / "s.xml"), "--out", str(out)], capsys)
    assert code == 2 and len(err) == 1 and where in err[0]
    assert not out.exists()


def test_object_starting_inside_the_part_is_an_input_error(tmp_path, capsys):
    src = bundled_dir()
    xml = (src / "cclamp2d.xml").read_text()
    import re

    # move the first keyframe (and the mocap body) to the clamp's centre: O overlaps A
    xml = re.sub(r'<key name="k0" mpos="[^"]*"', '<key name="k0" mpos="0 0 0"', xml)
    (tmp_path / "s.xml").write_text(xml)
    shutil.copy(src / "cclamp2d.toml", tmp_path / "s.toml")
    code, err = _run_err(["couple", "simulate", str(tmp_path / "s.xml"), "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and len(err) == 1 and "inside" in err[0]


def test_scenes_lists_the_bundled_scenes_with_the_shared_flags(capsys, tmp_path):
    assert main(["couple", "scenes", "--json", "--out", str(tmp_path)]) == 0
    listed = json.loads(capsys.readouterr().out)["scenes"]
    assert {"cclamp2d", "clip3d", "clip2d_eject", "clip2d_loose", "knocker3d", "claw3d"} <= set(listed)
    assert listed == sorted(p.stem for p in bundled_dir().glob("*.xml"))
