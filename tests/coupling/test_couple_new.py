"""``simfab couple new``: the coupling tutorial's commands on a user's own meshes give a valid profile.

The meshes are made here as a user's CAD would export them (trimesh): a C-clip STL in millimetres
and a cylinder STL, in assembly position (the cylinder sitting in the clip's seat).
"""

import json
from pathlib import Path

import numpy as np
import pytest

from simfab.cli import main


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    import trimesh

    from simfab.coupling.geometry import c_clamp_outline, extrude

    d = tmp_path_factory.mktemp("meshes")
    outline = c_clamp_outline(inner_radius=9.5, width=2.5, opening_deg=60.0, base_depth=4.0, base_height=20.0,
                              segments=48)  # mm: the bundled cclamp2d's clip
    extrude(outline, 5.0).export(d / "clip.stl")
    trimesh.creation.cylinder(radius=10.0, height=10.0, sections=64).export(d / "cylinder.stl")
    return d


def _new(meshes, out, *extra):
    return main(["couple", "new", str(meshes / "clip.stl"), str(meshes / "cylinder.stl"), "--into=-x",
                 "--out", str(out), "--json", *extra])


def test_tutorial_commands_give_a_tight_profile(meshes, tmp_path, capsys):
    scene_dir = tmp_path / "scene"
    assert _new(meshes, scene_dir, "--dim", "2", "--brief", "grip=tight") == 0
    made = json.loads(capsys.readouterr().out)
    xml = made["outputs"]["scene_xml"]
    assert made["next_commands"][0] == f"simfab couple simulate {xml}"
    # the cylinder sat in the seat (it overlaps the 9.5 mm arc by 0.5 mm): the start was moved out and said so
    assert any("starts inside the part" in n for n in made["notes"])
    # start: the 10 mm cylinder clears the arm tips (x = 9.5 cos 60 deg, y = 9.5 sin 60 deg): first contact at
    # x = 4.75 + sqrt(100 - 8.227^2) = 10.43 mm, the start 5 % of the cylinder's 20 mm before it
    assert made["start"][0] == pytest.approx(0.01043 + 0.001, abs=2e-4)
    assert made["seat"] == pytest.approx(made["start"][0], abs=2e-4)  # the seat: x = 0 (the arc's centre)
    assert made["to_rest"] and 0 < made["end"][0] <= 0.002  # ends just before the seat, runs on to rest
    out = tmp_path / "run"
    assert main(["couple", "simulate", xml, "--out", str(out), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    # the same clip as the bundled cclamp2d: a tight grip; the seated cylinder rests near x = 0
    assert s["category"] == "tight"
    assert 1.0 < s["F_in"] < 100.0 and s["F_grip"] > 1.0 and s["E_ss"] > 0
    rows = np.genfromtxt(s["profile_csv"], delimiter=",", names=True)
    assert np.all(np.isfinite(rows["energy_J"])) and rows["energy_J"].max() == pytest.approx(s["E_max"])
    assert s["max_penetration"] <= s["penetration_tolerance"]
    # profiles a user can read: the rest search's records are told apart from the planned insertion
    # (the path ended before the seat, so the run searched on for the rest point) ...
    phases = [str(p, "ascii") if isinstance(p, bytes) else str(p) for p in
              np.genfromtxt(s["profile_csv"], delimiter=",", names=True, dtype=None, encoding="ascii")["phase"]]
    n_insert = phases.count("insert")
    assert n_insert == 41 and set(phases[n_insert:]) == {"rest"} and len(phases) > n_insert
    # ... and every column's meaning and sign convention is in the JSON summary
    from simfab.coupling.outputs import CSV_HEADER

    summary = json.loads(open(s["profile_json"]).read())
    assert set(summary["profile_columns"]) == set(CSV_HEADER)
    assert "negative = the part resists" in summary["profile_columns"]["force_N"]


def test_a_2d_scene_from_an_assembly_off_the_xy_plane_meets_the_part(meshes, tmp_path, capsys):
    # the assembly 2.5 mm above the xy-plane (the clip on z = 0..5 mm, the cylinder centred on its
    # mid-plane): the section through the object's centre becomes the scene's plane z = 0 (keyframes
    # written at z = 2.5 mm left every point of the part beyond the object's field, and the first contact
    # was an infeasible step)
    import trimesh

    from simfab.coupling.scene import load_coupling_scene
    from simfab.coupling.simulate import simulate_insertion

    for name in ("clip", "cylinder"):
        m = trimesh.load(meshes / f"{name}.stl")
        m.apply_translation([0.0, 0.0, 2.5])
        m.export(tmp_path / f"{name}_up.stl")
    assert main(["couple", "new", str(tmp_path / "clip_up.stl"), str(tmp_path / "cylinder_up.stl"), "--into=-x",
                 "--dim", "2", "--out", str(tmp_path / "scene"), "--json"]) == 0
    made = json.loads(capsys.readouterr().out)
    assert made["start"][2] == 0.0 and made["end"][2] == 0.0
    assert any("z = 2.5 mm in the files" in n for n in made["notes"])
    cm = load_coupling_scene(made["outputs"]["scene_xml"], overrides={"simulation": {"steps": 12},
                                                                     "compliant": {"target_elements": 400}})
    res = simulate_insertion(cm)
    F = res.column("force")
    assert -F.min() > 1.0 and res.column("energy").max() > 0  # the arms resist: contact is seen


def test_3d_scene_loads_and_starts_outside(meshes, tmp_path, capsys):
    from simfab.coupling.scene import load_coupling_scene
    from simfab.coupling.simulate import check_start

    assert _new(meshes, tmp_path / "s3", "--elements", "800") == 0
    made = json.loads(capsys.readouterr().out)
    cm = load_coupling_scene(made["outputs"]["scene_xml"])
    check_start(cm)  # raises if the object starts inside the part
    assert cm.fem.rest.shape[1] == 3 and len(cm.fixed_vertices) > 0
    # the fixed slab is the clip's back (x = -16 mm) only
    assert np.all(cm.fem.rest[cm.fixed_vertices, 0] < -0.0155)


def test_depth_past_the_seat_is_refused_with_where(meshes, tmp_path, capsys):
    out = tmp_path / "bad"
    assert _new(meshes, out, "--dim", "2", "--depth", "25") == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--depth" in err and "inside the part" in err and "seat is at" in err
    assert not out.exists() or not any(out.iterdir())  # no partial output


def test_depth_before_the_seat_stops_there(meshes, tmp_path, capsys):
    assert _new(meshes, tmp_path / "d", "--dim", "2", "--depth", "5") == 0
    made = json.loads(capsys.readouterr().out)
    assert not made["to_rest"] and made["path_length"] == pytest.approx(0.005 + 0.001, abs=2e-4)
    toml = (tmp_path / "d" / "clip.toml").read_text()
    assert "L_max" in toml  # the run stops at the given depth instead of searching for rest


def test_in_plane_direction_required_in_2d(meshes, tmp_path, capsys):
    out = tmp_path / "m"
    assert _new(meshes, out, "--dim", "2", "--into=+z") == 2  # the last --into wins: out of the plane
    err = capsys.readouterr().err
    assert "--into" in err and "xy-plane" in err and not out.exists()


def test_point_direction_is_the_axis_towards_it(meshes, tmp_path, capsys):
    assert _new(meshes, tmp_path / "p", "--dim", "2", "--into=-50,0,0") == 0  # the cylinder's centre is the origin
    by_point = json.loads(capsys.readouterr().out)
    assert _new(meshes, tmp_path / "a", "--dim", "2") == 0
    by_axis = json.loads(capsys.readouterr().out)
    assert by_point["start"] == pytest.approx(by_axis["start"], abs=1e-12)
    assert by_point["end"] == pytest.approx(by_axis["end"], abs=1e-12)


def test_overlap_profile_of_a_disk_entering_a_block():
    """A disk of radius R whose centre starts at x = R + g to the right of the block x <= 0 overlaps
    it by max(0, s - g) after moving s along -x (the deepest point: the disk's leftmost point)."""
    from shapely.geometry import Point, box

    from simfab.coupling.author import _Shape2D, overlap_profile

    R, g = 0.01, 0.002
    block = _Shape2D(box(-0.05, -0.05, 0.0, 0.05))
    disk = _Shape2D(Point(R + g, 0.0).buffer(R, quad_segs=256))
    s = np.linspace(0.0, 0.006, 13)
    prof = overlap_profile(block, disk, np.array([R + g, 0.0]), np.array([-1.0, 0.0, 0.0]), s)
    # boundary samples every 2 pi R / 400 = 0.16 mm: the depth is resolved to (that spacing)^2 / (8 R)
    assert prof.depth == pytest.approx(np.maximum(0.0, s - g), abs=2e-6)


def test_3d_scene_keeps_its_tets_and_can_be_refined(meshes, tmp_path, capsys):
    # the 3D scene stores its tets (runs are reproducible: the level at factor 1 is that mesh) and the
    # surface they were meshed from, in the scene's frame, so a convergence study meshes the part again
    # at its other factors (it refused a scene with only the tets)
    import trimesh

    from simfab.coupling.converge import run_levels
    from simfab.coupling.scene import load_coupling_scene

    assert _new(meshes, tmp_path / "s3", "--elements", "600") == 0
    made = json.loads(capsys.readouterr().out)
    assert set(made["outputs"]) == {"scene_xml", "scene_toml", "part_npz", "part_ply"}
    assert made["warnings"] == []  # (the clip's 0.5 mm interference is resolved: the next test)
    xml = made["outputs"]["scene_xml"]
    cm = load_coupling_scene(xml)
    surf = trimesh.load(made["outputs"]["part_ply"])
    # the tets' surface in the scene's frame [m], up to the tetrahedralizer's envelope (1e-3 of the diagonal)
    diag = float(np.linalg.norm(np.ptp(cm.fem.rest, axis=0)))
    assert surf.is_watertight and np.allclose(surf.bounds, [cm.fem.rest.min(axis=0), cm.fem.rest.max(axis=0)],
                                              atol=2e-3 * diag)
    # (600 asked: the mesher's floor for this part is ~930 tets, and the scene's target is what it made)
    from simfab.coupling import run

    assert not [m for m in run(xml, steps=3).warnings if "departs" in m]  # (resolved: couple simulate agrees)
    levels = run_levels(xml, (1.0, 2.0), overrides={"simulation": {"steps": 4}})
    assert levels[0].elements == cm.fem.n_elements  # the stored mesh
    assert 1.5 < levels[1].elements / levels[0].elements < 2.5  # meshed again from the surface
    assert all(lv.figures["E_max"] > 0 for lv in levels)
    # the surface the scene names is part of it: missing, simulate refuses before running, naming the file
    Path(made["outputs"]["part_ply"]).unlink()
    capsys.readouterr()
    assert main(["couple", "simulate", xml, "--steps", "2", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "part.ply" in err[0] and "not found" in err[0] and not (tmp_path / "o").exists()


@pytest.mark.parametrize("dim,angle", [("2", 30.0), ("2", 137.0), ("3", 30.0)])
def test_a_moved_assembly_gives_the_same_scene(meshes, tmp_path, capsys, dim, angle):
    # the same clip and cylinder as a CAD assembly placed elsewhere (turned about z and moved): O starts
    # outside A (the search for the path's start began inside A when O's centre did not project to 0 on
    # the direction), the path is the same to the overlap profile's resolution, and the part is held on
    # its own back face (the box of the files' axes held a turned part at one edge: a hinge, F_in 3x low)
    import trimesh

    from simfab.coupling.author import PROFILE_POSITIONS_PER_SIZE
    from simfab.coupling.profile import analyze_run
    from simfab.coupling.scene import load_coupling_scene
    from simfab.coupling.simulate import check_start, simulate_insertion

    T = trimesh.transformations.rotation_matrix(np.radians(angle), [0, 0, 1])
    T[:3, 3] = [40.0, -25.0, 3.0]  # mm
    for name in ("clip", "cylinder"):
        m = trimesh.load(meshes / f"{name}.stl")
        m.apply_transform(T)
        m.export(tmp_path / f"{name}_moved.stl")
    into = T[:3, :3] @ [-1.0, 0.0, 0.0]
    point = ",".join(f"{v:.9f}" for v in T[:3, 3] + 30.0 * into)  # (the cylinder's centre is at the origin)
    runs, models = [], []
    for args in ([str(meshes / "clip.stl"), str(meshes / "cylinder.stl"), "--into=-x"],
                 [str(tmp_path / "clip_moved.stl"), str(tmp_path / "cylinder_moved.stl"), f"--into={point}"]):
        out = tmp_path / f"s{len(runs)}"
        n = "400" if dim == "2" else "900"
        assert main(["couple", "new", *args, "--dim", dim, "--elements", n, "--out", str(out), "--json"]) == 0
        runs.append(json.loads(capsys.readouterr().out))
        models.append(load_coupling_scene(runs[-1]["outputs"]["scene_xml"], overrides={"simulation": {"steps": 12}}))
        check_start(models[-1])  # raises if O starts inside A
    step = 0.020 / PROFILE_POSITIONS_PER_SIZE  # the profile's positions: the cylinder's 20 mm / 60
    for k in ("path_length", "first_contact", "seat"):
        assert abs(runs[1][k] - runs[0][k]) <= 1.01 * step, k  # [m]
    # the fixed vertices, moved back into the clip's frame, are its back (x = -16 mm) only
    X = models[1].fem.rest[models[1].fixed_vertices]
    back = (np.c_[X, np.zeros((len(X), 3 - X.shape[1]))] * 1e3 - T[:3, 3]) @ T[:3, :3]  # (the inverse move) [mm]
    assert len(X) >= 3 and np.all(back[:, 0] < -15.5)
    if dim == "2":
        a, b = (analyze_run(simulate_insertion(cm)) for cm in models)
        assert b.F_in == pytest.approx(a.F_in, rel=0.03) and b.E_max == pytest.approx(a.E_max, rel=0.03)


def test_an_interference_the_tets_do_not_resolve_is_warned_of(tmp_path, capsys):
    # a pin 0.15 mm larger than its bore (radius 4.6 in 4.5 mm) in a block meshed at ~1,400 tets: the tets'
    # surface cuts the bore in chords as deep as a good part of the interference, so the seat's forces depend
    # on the mesh; couple new says so and how many tets resolve it (the C-clip's 0.5 mm: no warning, above)
    import trimesh

    block = trimesh.creation.box(extents=(20, 14, 8))
    block.apply_translation((0, -1, 0))
    mouth = trimesh.creation.box(extents=(7.0, 8, 10))
    mouth.apply_translation((0, 6, 0))
    part = block.difference(trimesh.creation.cylinder(radius=4.5, height=10, sections=96)).difference(mouth)
    part.export(tmp_path / "block.stl")
    trimesh.creation.cylinder(radius=4.6, height=12, sections=128).export(tmp_path / "pin.stl")
    assert main(["couple", "new", str(tmp_path / "block.stl"), str(tmp_path / "pin.stl"), "--into=-y",
                 "--elements", "1500", "--out", str(tmp_path / "s"), "--json"]) == 0
    cap = capsys.readouterr()
    (w,) = json.loads(cap.out)["warnings"]
    assert "simfab: warning: couple new: near the object" in cap.err
    import re

    found = re.search(r"by ([0-9.]+) mm \(90th.*?of the object's ([0-9.]+) mm overlap", w)
    dev, overlap = (float(x) for x in found.groups())
    assert overlap == pytest.approx(0.15, abs=0.01) and 0.1 * overlap < dev < overlap  # [mm]
    need = int(re.search(r"--elements (\d+)", w).group(1))
    assert 5_000 < need < 50_000
    # couple simulate checks a scene whose part is stored beside its surface the same way (a user's
    # hand-written scene, or this one with its target_elements edited), where the object comes to rest
    # (measured: 0.26 mm short of the bore's centre, its overlap with the bore's wall 0.27 mm, the
    # departure there 0.035 mm)
    from simfab.coupling import run

    res = run(str(tmp_path / "s" / "block.xml"), steps=3)
    (w2,) = [m for m in res.warnings if "departs" in m]
    found = re.search(r"by ([0-9.]+) mm \(90th.*?of the object's ([0-9.]+) mm overlap", w2)
    dev2, overlap2 = (float(x) for x in found.groups())
    assert 0.14 < overlap2 < 0.4 and 0.1 * overlap2 < dev2 < overlap2  # [mm]
    assert "[compliant] target_elements" in w2
