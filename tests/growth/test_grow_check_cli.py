"""``simfab grow check`` / ``simfab grow --check`` end to end: outputs, --strengthen, bad input."""

import json
import pathlib
import shutil

import pytest
from test_growth_structure import _strut_scene, _strut_skeleton

from simfab.cli import main
from simfab.growth.skeleton import load_skeleton_json, to_json_dict
from simfab.io.atomic import write_json

SCENES = pathlib.Path(__file__).resolve().parents[2] / "scenes" / "growth"
CHECK_KEYS = {"safety_factor", "max_von_mises_Pa", "deflection_m", "mass_kg", "peak_point_m", "check_usd",
              "check_png"}


def _run(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def strut_json(tmp_path):
    xml = _strut_scene(tmp_path)
    path = tmp_path / "strut_skeleton.json"
    write_json(path, to_json_dict(_strut_skeleton(), scene=str(xml)))
    return path


def test_check_and_strengthen_a_strut(strut_json, tmp_path, capsys):
    """A 40 N side load on the 8 mm strut overloads PLA (beam stress ~ 70 MPa > 60 MPa):
    --strengthen 1.5 thickens it until the safety factor is at least 1.5, adding volume near the
    root, where the moment is largest."""
    out = tmp_path / "out"
    code, so, err = _run(["grow", "check", str(strut_json), "--load", "target_0=40,0,0", "--strengthen", "1.5",
                          "--buckling", "--out", str(out), "--json"], capsys)
    assert code == 0, err
    s = json.loads(so)
    assert CHECK_KEYS <= set(s)
    assert s["safety_factor"] < 1.0 and set(s["deflection_m"]) == {"target_0"}
    assert s["buckling_factor"] > 5  # a side load on a stubby strut: it yields long before it buckles
    st = s["strengthened"]
    assert st["reached"] and st["safety_factor"] >= 1.5 and st["safety_factor_before"] == s["safety_factor"]
    assert st["volume_after_m3"] > st["volume_before_m3"] and st["deflection_m"]["target_0"] < s["deflection_m"][
        "target_0"]
    for key in ("check_usd", "check_png"):
        assert pathlib.Path(s[key]).is_file() and pathlib.Path(st[key]).is_file()
        assert pathlib.Path(s[key]).parent == out
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(s["check_usd"])
    support = stage.GetPrimAtPath("/World/support")
    api = UsdGeom.PrimvarsAPI(support)
    vm = api.GetPrimvar("von_mises").Get(1)
    disp = api.GetPrimvar("displacement").Get(1)
    assert max(vm) == pytest.approx(s["max_von_mises_Pa"], rel=1e-6)  # float32 primvar
    assert max(disp) > s["deflection_m"]["target_0"] * 0.9  # the tip moves the most
    rest = UsdGeom.Mesh(support).GetPointsAttr().Get(0)
    loaded = UsdGeom.Mesh(support).GetPointsAttr().Get(1)
    assert max(abs(b[0] - a[0]) for a, b in zip(rest, loaded)) > 0  # the loaded state is displaced
    sk, doc = load_skeleton_json(st["skeleton_json"])
    r0 = _strut_skeleton().radius
    assert len(sk.nodes) == len(r0)  # same topology
    # thickened where the bending moment is large (the root), left alone near the tip
    assert sk.radius[0] > 1.1 * r0[0] and sk.radius[-1] == pytest.approx(r0[-1])
    assert sk.radius.min() >= r0.min()
    assert pathlib.Path(st["skin_stl"]).is_file()


def test_check_reads_the_scene_loads_and_material(tmp_path, capsys):
    """[loads] of the scene apply; --load replaces the scene's entry for its target."""
    xml = _strut_scene(tmp_path, "[loads]\ntarget_0 = [2.0, 0.0, 0.0]\n[material]\nyield_stress = 1e7\n")
    path = tmp_path / "strut_skeleton.json"
    write_json(path, to_json_dict(_strut_skeleton(), scene=str(xml)))
    code, so, err = _run(["grow", "check", str(path), "--out", str(tmp_path / "a"), "--json"], capsys)
    assert code == 0, err
    a = json.loads(so)
    assert a["target_forces_N"]["target_0"] == [2.0, 0.0, 0.0] and a["yield_stress_Pa"] == 1e7
    code, so, err = _run(["grow", "check", str(path), "--load", "target_0=4,0,0", "--out", str(tmp_path / "b"),
                          "--json"], capsys)
    b = json.loads(so)
    assert b["target_forces_N"]["target_0"] == [4.0, 0.0, 0.0]
    # linear statics: twice the load, about twice the stress (meshes differ run to run by fTetWild's threads)
    assert b["max_von_mises_Pa"] / a["max_von_mises_Pa"] == pytest.approx(2.0, rel=0.15)


BAD = [
    (["grow", "check"], "SKELETON_JSON"),
    (["grow", "check", "missing.json"], "file not found"),
    (["grow", str(SCENES / "phone_stand.xml"), "--check", "--load", "target_9=1,2,3"], "--load"),
    (["grow", str(SCENES / "phone_stand.xml"), "--check", "--load", "target_0=1,2"], "--load"),
    (["grow", str(SCENES / "phone_stand.xml"), "--check", "--load", "target_0=a,b,c"], "--load"),
    (["grow", str(SCENES / "phone_stand.xml"), "--strengthen", "-1"], "--strengthen"),
    (["grow", str(SCENES / "phone_stand.xml"), "--check", "--thin"], "--thin"),
    (["grow", "edit", "x.json", "--check"], "--check"),
]


@pytest.mark.parametrize("argv,needle", BAD)
def test_bad_check_input_exits_2_with_one_line(argv, needle, tmp_path, capsys):
    out_dir = tmp_path / "out"
    code, out, err = _run(argv + ["--out", str(out_dir)], capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], err
    assert not out_dir.exists() or not any(out_dir.iterdir())  # no partial outputs


def test_bad_material_key_names_file_and_key(tmp_path, capsys):
    shutil.copy(SCENES / "phone_stand.xml", tmp_path / "p.xml")
    (tmp_path / "p.toml").write_text((SCENES / "phone_stand.toml").read_text() + "\n[material]\nyeld_stress = 1e7\n")
    code, out, err = _run(["grow", str(tmp_path / "p.xml"), "--check", "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "p.toml" in err and "[material]" in err and "yeld_stress" in err
    assert not (tmp_path / "o").exists()


def test_check_of_a_skeleton_without_scene(strut_json, tmp_path, capsys):
    d = json.loads(strut_json.read_text())
    d["scene"] = str(tmp_path / "gone.xml")
    bad = tmp_path / "bad_skeleton.json"
    bad.write_text(json.dumps(d))
    code, out, err = _run(["grow", "check", str(bad), "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "scene" in err and len(err.strip().splitlines()) == 1


def test_grow_then_check(tmp_path, capsys):
    """``simfab grow SCENE --check``: the growth's outputs plus the check's, its figures under 'check'."""
    xml = _strut_scene(tmp_path, "[growth]\nattractors = 300\n[loads]\ntarget_0 = [0.5, 0.0, 0.0]\n")
    out = tmp_path / "out"
    code, so, err = _run(["grow", str(xml), "--check", "--out", str(out), "--json"], capsys)
    assert code == 0, err
    s = json.loads(so)
    assert s["targets_reached"] == 1 and CHECK_KEYS <= set(s["check"])
    assert s["check"]["target_forces_N"]["target_0"] == [0.5, 0.0, 0.0]
    assert 0 < s["check"]["safety_factor"] < float("inf") and s["check"]["deflection_m"]["target_0"] > 0
    assert {p.name for p in out.iterdir()} >= {"strut_skin.stl", "strut_check.usdc", "strut_check.png"}
