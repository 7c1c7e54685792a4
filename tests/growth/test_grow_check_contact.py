"""Reached means touching: the check loads a held object's weight only through skin that meets
its surface, fails (or, with --best-effort, warns) when a weight has no load path, says where
each mass comes from, and refuses unusable skeletons and massless objects (exit 2, nothing written)."""

import json
import pathlib
import re
import shutil

import numpy as np
import pytest
from test_growth_structure import LENGTH, R, _strut_skeleton

from simfab.cli import main
from simfab.growth import grow
from simfab.growth.contact import GAP_PER_R, MIN_AREA_FRACTION
from simfab.growth.scene import load_growth_scene
from simfab.growth.skeleton import to_json_dict
from simfab.growth.structure import body_masses, target_loads
from simfab.io.atomic import write_json

SCENES = pathlib.Path(__file__).resolve().parents[2] / "scenes" / "growth"
G = 9.81


def _run(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def _plate_scene(tmp_path, gap: float, geom_mass: str = 'mass="0.2"'):
    """The strut scene (ground box, root at z = 0, target_0 at z = LENGTH) with a held plate
    whose underside is ``gap`` [m] above the target."""
    xml = tmp_path / "plate.xml"
    half = 0.004
    xml.write_text('<mujoco><worldbody><body name="ground"><geom type="box" size="0.03 0.03 0.005" '
                   'pos="0 0 -0.005"/></body>'
                   f'<body name="plate" pos="0 0 {LENGTH + gap + half}"><geom type="box" size="0.03 0.03 {half}" '
                   f'{geom_mass}/></body>'
                   f'<site name="root_0" pos="0 0 0"/><site name="target_0" pos="0 0 {LENGTH}"/></worldbody></mujoco>')
    return xml


def _skeleton_json(tmp_path, xml, sk=None):
    path = tmp_path / "plate_skeleton.json"
    write_json(path, to_json_dict(sk if sk is not None else _strut_skeleton(), scene=str(xml)))
    return path


@pytest.mark.parametrize("gap_mm", [1, 2, 3, 4, 6, 8, 10])
def test_strut_under_a_plate_carries_it_or_fails_loudly(gap_mm, tmp_path, capsys):
    """A fixed strut (radius R = 4 mm, its target node at z = LENGTH) under a 0.2 kg plate whose
    underside is 1-10 mm above the target: the skin's end ball reaches the plate, and is carved
    by it, when the gap is below R; the carved disc has area pi (R^2 - gap^2), at least
    MIN_AREA_FRACTION pi R^2 for gap <= sqrt(1 - 0.25) R = 3.46 mm. Then the plate's weight
    goes through target_0; otherwise the check fails (exit 1, one line naming the plate and the
    target, nothing written)."""
    gap = gap_mm * 1e-3
    xml = _plate_scene(tmp_path, gap)
    out = tmp_path / "out"
    code, so, err = _run(["grow", "check", str(_skeleton_json(tmp_path, xml)), "--out", str(out), "--json"], capsys)
    carries = gap <= np.sqrt(1.0 - MIN_AREA_FRACTION) * R - GAP_PER_R * R
    if carries:
        assert code == 0, err
        s = json.loads(so)
        t = s["targets"]["target_0"]
        assert t["touching"] and t["object"] == "plate" and t["gap_m"] == 0.0
        # the carved cap's flat face; the skin's sphere is a 12-segment polyhedron inside the
        # ball, whose section near its end is smaller (75 % of the disc at 3 mm)
        disc = np.pi * (R * R - gap * gap)
        assert 0.6 * disc < t["contact_area_m2"] <= disc * 1.01
        np.testing.assert_allclose(t["load_N"], [0.0, 0.0, -0.2 * G], rtol=1e-9)
        assert s["supported_objects"]["plate"]["carried_by"] == ["target_0"]
        assert s["dropped_weight_N"] == {}
        assert 0 < s["safety_factor"] < float("inf")
    else:  # no patch of the minimum area: the plate's weight would have no load path
        assert code == 1, err
        lines = err.strip().splitlines()
        assert len(lines) == 1 and "plate" in lines[0] and "target_0" in lines[0], err
        assert not out.exists() or not any(out.iterdir())


def test_best_effort_checks_without_the_weight_and_says_so(tmp_path, capsys):
    xml = _plate_scene(tmp_path, 0.008)
    out = tmp_path / "out"
    code, so, err = _run(["grow", "check", str(_skeleton_json(tmp_path, xml)), "--out", str(out), "--json",
                          "--best-effort"], capsys)
    assert code == 0, err
    assert "warning" in err and "plate" in err
    s = json.loads(so)
    assert s["dropped_weight_N"]["plate"] == pytest.approx(0.2 * G, rel=1e-9)
    t = s["targets"]["target_0"]
    assert not t["touching"] and t["gap_m"] == pytest.approx(0.008 - R, abs=2e-4) and t["contact_area_m2"] == 0
    assert t["load_N"] == [0.0, 0.0, 0.0]
    assert s["supported_objects"]["plate"]["carried_by"] == []


def _offset_phone(tmp_path, off: float) -> pathlib.Path:
    """phone_stand with every target moved ``off`` [m] off the phone's back, along its outward
    normal (the phone leans back 20 degrees about x: back normal (0, -cos 20, -sin 20))."""
    n = np.array([0.0, -np.cos(np.radians(20)), -np.sin(np.radians(20))])

    def move(m):
        p = np.array([float(v) for v in m.group(2).split()]) + off * n
        return f'{m.group(1)}pos="{p[0]:.9g} {p[1]:.9g} {p[2]:.9g}"'

    d = tmp_path / f"off{off * 1e3:g}mm"
    d.mkdir()
    xml = re.sub(r'(<site name="target_\d+" )pos="([^"]+)"', move, (SCENES / "phone_stand.xml").read_text())
    (d / "phone_stand.xml").write_text(xml)
    shutil.copy(SCENES / "phone_stand.toml", d / "phone_stand.toml")
    return d / "phone_stand.xml"


@pytest.mark.parametrize("off_mm", [1, 3, 6, 10])
def test_growth_aims_off_surface_targets_onto_the_phone(off_mm, tmp_path):
    """Targets 1-10 mm off the phone: growth ends its branches on the phone's surface, every
    target touches it with a contact patch, and their loads add up to the phone's weight."""
    xml = _offset_phone(tmp_path, off_mm * 1e-3)
    scene = load_growth_scene(xml)
    res = grow(scene, seed=0)
    assert res.summary()["targets_reached"] == 5
    loads = target_loads(scene, res.skeleton)
    assert all(ld.contact.touching and ld.contact.object == "phone" for ld in loads)
    assert all(ld.contact.contact_area_m2 >= ld.contact.min_area_m2 for ld in loads)
    np.testing.assert_allclose(sum(ld.force for ld in loads), [0, 0, -G * body_masses(scene)["phone"]], rtol=1e-9)


def test_grow_check_of_targets_8mm_off_carries_the_phone(tmp_path, capsys):
    """The issue's case (targets 8 mm off the phone) end to end: the phone's weight is carried,
    its mass reported as MuJoCo's default density's."""
    xml = _offset_phone(tmp_path, 0.008)
    code, so, err = _run(["grow", str(xml), "--check", "--out", str(tmp_path / "o"), "--json", "--quiet"], capsys)
    assert code == 0, err
    c = json.loads(so)["check"]
    m = 1000.0 * 0.075 * 0.008 * 0.15  # the phone box at MuJoCo's default density
    ph = c["supported_objects"]["phone"]
    assert ph["mass_kg"] == pytest.approx(m, rel=1e-9) and "default density" in ph["mass_source"]
    assert sorted(ph["carried_by"]) == [f"target_{i}" for i in range(5)]
    assert sum(t["load_N"][2] for t in c["targets"].values()) == pytest.approx(-m * G, rel=1e-9)
    assert c["dropped_weight_N"] == {}


@pytest.mark.parametrize("geom,source", [('mass="0.2"', "mass="), ('density="500"', "density=500 kg/m^3"),
                                         ("", "MuJoCo default density 1000 kg/m^3")])
def test_mass_sources(geom, source, tmp_path, capsys):
    xml = _plate_scene(tmp_path, 0.001, geom)
    code, so, err = _run(["grow", "check", str(_skeleton_json(tmp_path, xml)), "--out", str(tmp_path / "o"), "--json"],
                         capsys)
    assert code == 0, err
    p = json.loads(so)["supported_objects"]["plate"]
    assert p["mass_source"] == source
    volume = 0.06 * 0.06 * 0.008
    want = {"mass=": 0.2, "density=500 kg/m^3": 500 * volume}.get(source, 1000 * volume)
    assert p["mass_kg"] == pytest.approx(want, rel=1e-9) and p["weight_N"] == pytest.approx(want * G, rel=1e-9)


def _bad(tmp_path, edit):
    xml = _plate_scene(tmp_path, 0.001)
    path = _skeleton_json(tmp_path, xml)
    d = json.loads(path.read_text())
    edit(d)
    path.write_text(json.dumps(d))
    return path


BAD_SKELETONS = [
    (lambda d: d.update(nodes=[], radius=[], parent=[], birth_step=[], target=[], root=[], contact=[]), "nodes"),
    (lambda d: d["target"].__setitem__(-1, 7), "target"),
    (lambda d: d["radius"].__setitem__(3, float("nan")), "radius"),
    (lambda d: d.update(target_names=["target_9"], target_nodes={"target_9": 8}), "target_names"),
    (lambda d: d["parent"].__setitem__(2, 5), "parent"),
    (lambda d: d.update(parent=[-1] * len(d["parent"])), "parent"),
    (lambda d: d.pop("radius"), "radius"),
]


@pytest.mark.parametrize("edit,field", BAD_SKELETONS)
def test_bad_skeleton_exits_2_naming_file_and_field(edit, field, tmp_path, capsys):
    path = _bad(tmp_path, edit)
    out = tmp_path / "out"
    code, so, err = _run(["grow", "check", str(path), "--out", str(out)], capsys)
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and f"{field}" in lines[0], err
    assert "Traceback" not in err and not out.exists()


def test_massless_supported_object_exits_2_before_anything_is_written(tmp_path, capsys):
    xml = _plate_scene(tmp_path, 0.001, 'density="0"')
    out = tmp_path / "out"
    code, so, err = _run(["grow", "check", str(_skeleton_json(tmp_path, xml)), "--out", str(out)], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "plate.xml: body plate mass" in err and not out.exists()
    (tmp_path / "plate.toml").write_text("[growth]\nattractors = 300\n")
    code, so, err = _run(["grow", str(xml), "--check", "--out", str(out)], capsys)
    assert code == 2 and "body plate mass" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
