"""``simfab grow`` end to end: outputs, JSON summary, sketch edit, bad input."""

import json
import pathlib

import numpy as np
import pytest

from simfab.cli import main

SCENES = pathlib.Path(__file__).resolve().parents[2] / "scenes" / "growth"
KEYS = {"targets_total", "targets_reached", "nodes", "segments", "watertight", "bodies", "volume",
        "seconds_growth", "seconds_skin", "skin_stl", "skin_ply", "skeleton_json", "usd", "mjcf", "png"}


def _run(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_grow_writes_every_output(tmp_path, capsys):
    code, out, err = _run(["grow", str(SCENES / "watch_stand.xml"), "--out", str(tmp_path), "--json", "--seed", "2"],
                          capsys)
    assert code == 0, err
    s = json.loads(out)
    assert KEYS <= set(s)
    assert s["targets_reached"] == s["targets_total"] == 4
    assert s["watertight"] is True and s["bodies"] == 1 and s["volume"] > 0
    for k in ("skin_stl", "skin_ply", "skeleton_json", "usd", "mjcf", "png"):
        assert pathlib.Path(s[k]).is_file() and pathlib.Path(s[k]).stat().st_size > 0, k
    # skin files are in millimetres (slicer convention), watertight as written
    import trimesh

    stl = trimesh.load(s["skin_stl"])
    assert s["skin_units"] == "mm" and stl.is_watertight
    assert stl.volume == pytest.approx(s["volume"] * 1e9, rel=1e-4)
    # skeleton JSON: nodes, radii, parents, which node hits which target
    d = json.loads(pathlib.Path(s["skeleton_json"]).read_text())
    assert len(d["nodes"]) == len(d["radius"]) == len(d["parent"]) == s["nodes"]
    assert set(d["target_nodes"]) == {"target_0", "target_1", "target_2", "target_3"}
    # USD replays the growth: one time sample per step, then pruned, smoothed, skin
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(s["usd"])
    curves = UsdGeom.BasisCurves(stage.GetPrimAtPath("/World/growth/skeleton"))
    times = curves.GetPointsAttr().GetTimeSamples()
    assert times[0] == 0 and len(times) == s["steps"] + 3
    counts = [len(curves.GetCurveVertexCountsAttr().Get(t)) for t in times[: s["steps"] + 1]]
    assert counts == sorted(counts) and counts[-1] > counts[0]  # the tree grows step by step
    skin = UsdGeom.Imageable(stage.GetPrimAtPath("/World/growth/skin"))
    assert skin.ComputeVisibility(0) == UsdGeom.Tokens.invisible
    assert skin.ComputeVisibility(times[-1] + 1) == UsdGeom.Tokens.inherited
    assert stage.GetEndTimeCode() == times[-1] + 1
    # MJCF loads in MuJoCo with the grown part
    import mujoco

    m = mujoco.MjModel.from_xml_path(s["mjcf"])
    assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "grown") >= 0


def test_grow_edit(tmp_path, capsys):
    code, out, err = _run(["grow", str(SCENES / "table_legs.xml"), "--out", str(tmp_path), "--json"], capsys)
    assert code == 0, err
    s = json.loads(out)
    cam = {"eye": [0.0, -2.0, 0.3], "target": [0.0, 0.0, 0.25], "up": [0, 0, 1], "fovy_deg": 45,
           "width": 800, "height": 600}
    (tmp_path / "cam.json").write_text(json.dumps(cam))
    # the user redraws the longest chain, bulging 40 px sideways on screen
    from simfab.growth.skeleton import load_skeleton_json
    from simfab.growth.sketch import load_camera, skeleton_chains

    sk, _ = load_skeleton_json(s["skeleton_json"])
    camera = load_camera(str(tmp_path / "cam.json"))
    chains = skeleton_chains(sk)
    k = int(np.argmax([len(c) for c in chains]))
    chain = chains[k]
    P = camera.project(sk.nodes[chain])
    u = np.linspace(0, 1, len(P))
    stroke = P + np.column_stack([40 * np.sin(np.pi * u), np.zeros_like(u)])
    (tmp_path / "stroke.csv").write_text("x,y\n" + "\n".join(f"{x:.4f},{y:.4f}" for x, y in stroke))
    code, out, err = _run(["grow", "edit", s["skeleton_json"], "--stroke", str(tmp_path / "stroke.csv"),
                           "--camera", str(tmp_path / "cam.json"), "--chain", str(k), "--out", str(tmp_path / "edit"),
                           "--json"], capsys)
    assert code == 0, err
    e = json.loads(out)
    assert e["chain"] == k and e["nodes_moved"] + e["nodes_kept_for_collisions"] == len(chain) - 2
    assert e["nodes_moved"] >= 0.8 * (len(chain) - 2) and e["watertight"] is True and e["bodies"] == 1
    assert e["segments_colliding"] == 0
    assert pathlib.Path(e["skeleton_json"]).is_file() and pathlib.Path(e["skin_stl"]).is_file()
    # the library call: same figures, nothing written without out, the stroke as an array (rounded as the CSV)
    import dataclasses

    import simfab.growth

    before = sorted(tmp_path.rglob("*"))
    r = simfab.growth.edit(s["skeleton_json"], stroke=np.round(stroke, 4), camera=camera, chain=k)  # the CSV's
    assert sorted(tmp_path.rglob("*")) == before and r.outputs == {} and r.skin_stl is None
    lib, files = r.to_json(), ("skeleton_json", "skin_stl", "skin_ply", "png")
    assert list(lib) == list(e) and {k: v for k, v in lib.items() if k not in files} == \
        {k: v for k, v in e.items() if k not in files}
    assert len(r.skeleton.nodes) == e["nodes"] and r.mesh.is_watertight
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.chain = 0


BAD = [
    (["grow", "nope.xml"], "file not found"),
    (["grow", str(SCENES / "phone_stand.toml")], "MJCF"),
    (["grow", str(SCENES / "phone_stand.xml"), "--kill", "0.2", "--influence", "0.1"], "influence"),
    (["grow", str(SCENES / "phone_stand.xml"), "--attractors", "0"], "--attractors"),
    (["grow", str(SCENES / "phone_stand.xml"), "--mode", "sideways"], "invalid choice"),
    (["grow", "edit"], "SKELETON_JSON"),
    (["grow", "edit", str(SCENES / "phone_stand.xml"), "--stroke", "s.json", "--camera", "{}"], "not valid JSON"),
    (["grow", str(SCENES / "phone_stand.xml"), "--stroke", "s.json"], "edit"),
]


@pytest.mark.parametrize("argv,needle", BAD)
def test_bad_input_exits_2_with_one_line(argv, needle, tmp_path, capsys):
    out_dir = tmp_path / "out"
    code, out, err = _run(argv + ["--out", str(out_dir)], capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], err
    assert not out_dir.exists() or not any(out_dir.iterdir())  # no partial outputs


def test_bad_toml_names_the_key(tmp_path, capsys):
    import shutil

    shutil.copy(SCENES / "egg_holder_volume.xml", tmp_path / "egg.xml")
    (tmp_path / "egg.toml").write_text("[growth]\nmode = 'volume'\nkil = 0.01\n")
    code, out, err = _run(["grow", str(tmp_path / "egg.xml"), "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "kil" in err and "egg.toml" in err and len(err.strip().splitlines()) == 1
    (tmp_path / "egg.toml").write_text("[growth]\nattractors = -5\n")
    code, out, err = _run(["grow", str(tmp_path / "egg.xml"), "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "growth.attractors" in err


def test_uncarved_skin_beyond_tolerance_fails_without_outputs(tmp_path, capsys):
    import shutil

    shutil.copy(SCENES / "phone_stand.xml", tmp_path / "p.xml")
    base = (SCENES / "phone_stand.toml").read_text()
    (tmp_path / "p.toml").write_text(base + "\n[skin]\nsubtract_objects = false\ntolerance = 0.001\n")
    code, out, err = _run(["grow", str(tmp_path / "p.xml"), "--out", str(tmp_path / "o")], capsys)
    assert code == 1 and "penetrates" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())
    # carved (the default), the same scene passes with zero tolerance
    (tmp_path / "p.toml").write_text(base + "\n[skin]\ntolerance = 0.0\n")
    code, out, err = _run(["grow", str(tmp_path / "p.xml"), "--out", str(tmp_path / "o2"), "--json"], capsys)
    assert code == 0, err
    assert json.loads(out)["penetration"] < 1e-6


def test_step_cap_is_reported_naming_unreached_targets(tmp_path, capsys):
    # too few steps to reach anything: nothing to build -> exit 1, the reason and targets named
    code, out, err = _run(["grow", str(SCENES / "table_legs.xml"), "--max-steps", "3", "--out", str(tmp_path / "a")],
                          capsys)
    assert code == 1 and "step cap" in err and "target_0" in err
    assert not (tmp_path / "a").exists() or not any((tmp_path / "a").iterdir())
    # enough steps for some targets only: a failed growth (exit 1, the count named, nothing written) ...
    code, out, err = _run(["grow", str(SCENES / "table_legs.xml"), "--max-steps", "32", "--out", str(tmp_path / "b")],
                          capsys)
    assert code == 1 and "targets unreached" in err and "--best-effort" in err
    assert not (tmp_path / "b").exists()
    # ... unless best effort was asked for: outputs are written, the rest are listed
    code, out, err = _run(["grow", str(SCENES / "table_legs.xml"), "--max-steps", "32", "--out", str(tmp_path / "b"),
                           "--json", "--best-effort"], capsys)
    s = json.loads(out)
    assert code == 0 and "targets unreached" in err
    assert 0 < s["targets_reached"] < s["targets_total"]
    assert len(s["targets_unreached"]) == s["targets_total"] - s["targets_reached"]
    assert any(r.startswith("step cap") for r in s["stop_reasons"])
