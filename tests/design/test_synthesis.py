"""2D -> 3D synthesis (simfab.design.synthesis): a section's base revolved with its arms replicated
(the thesis' building blocks), and the 3D scene written from it."""

from pathlib import Path

import numpy as np
import pytest

from simfab.design.synthesis import revolve_arms

# a section in (x = axial, y = radial) with the axis along x: base x in [0, 1], |y| <= 1; arms
# x in [1, 3], y in [0.8, 1] and [-1, -0.7] (the lower one thicker)
SECTION = np.array([[0, -1], [3, -1], [3, -0.7], [1, -0.7], [1, 0.8], [3, 0.8], [3, 1], [0, 1]], float)


@pytest.mark.parametrize("arms", [2, 3, 4, 6])
def test_revolved_base_plus_arm_slabs_has_the_exact_volume(arms):
    # volume = revolved base (a cylinder faceted with n segments: n/2 sin(2 pi/n) R^2 L) + the
    # slabs beyond the base: arm i alternates the upper (0.2 x 2) and lower (0.3 x 2) halves
    n, w = 96, 0.1
    m = revolve_arms([SECTION], axis="x", cut=1.0, base_side=-1, arms=arms, width=w, sections=n)
    base = 0.5 * n * np.sin(2 * np.pi / n) * 1.0**2 * 1.0
    slabs = sum((0.2 if i % 2 == 0 else 0.3) * 2.0 * w for i in range(arms))
    assert m.is_watertight and m.volume == pytest.approx(base + slabs, rel=1e-5)


def test_two_arms_are_the_sections_own_arms_in_its_plane():
    m = revolve_arms([SECTION + [0.0, 0.5]], axis="x", offset=0.5, cut=1.0, base_side=-1, arms=2, width=0.1)
    V = m.vertices[m.vertices[:, 0] > 1.5]  # the arms' vertices
    assert set(np.unique(V[:, 1].round(6))) == {-0.5, -0.2, 1.3, 1.5}  # (manifold3d stores float32)
    assert np.allclose(np.abs(V[:, 2]), 0.05, atol=1e-7)
    # the same section about a "y" axis: coordinates swapped, same solid
    m2 = revolve_arms([SECTION[:, ::-1]], axis="y", cut=1.0, base_side=-1, arms=2, width=0.1)
    assert m2.is_watertight and m2.volume == pytest.approx(
        revolve_arms([SECTION], axis="x", cut=1.0, base_side=-1, arms=2, width=0.1).volume, rel=1e-9)


def test_full_turn_of_a_section_is_a_closed_solid_of_revolution():
    # Pappus: a rectangle r in [1, 2], z in [0, 1] revolved a full turn: V = 2 pi r_c A, faceted
    from simfab.design.synthesis import revolve_outline

    n = 96
    m = revolve_outline(np.array([[0.0, 1.0], [1.0, 1.0], [1.0, 2.0], [0.0, 2.0]]), axis="x", sections=n)
    ring = 0.5 * n * np.sin(2 * np.pi / n) * (2.0**2 - 1.0**2) * 1.0  # faceted annulus times height
    assert m.is_watertight and m.volume == pytest.approx(ring, rel=1e-9)


def test_bad_synthesis_inputs_are_named():
    from simfab.errors import InputError

    with pytest.raises(InputError, match="arms"):
        revolve_arms([SECTION], axis="x", cut=1.0, arms=1, width=0.1)
    with pytest.raises(InputError, match="not inside the section"):
        revolve_arms([SECTION], axis="x", cut=5.0, arms=4, width=0.1)


def test_block_section_becomes_a_3d_scene_with_its_object_path_and_support(tmp_path):
    """The building block's section (its base kept) as a 3D scene: 10-node tets, the ball starting
    outside the part, the fixed box widened to hold the revolved base all around the axis."""
    import shutil

    from simfab.coupling.scene import scene_paths
    from simfab.design.scene import load_design_scene
    from simfab.design.synthesis import revolved_scene

    ds = load_design_scene("block2d_tight")
    cm = ds.cm
    xml, toml = scene_paths("block2d_tight")
    for p in (xml, toml):
        shutil.copy(p, tmp_path / p.name)
    shutil.copy(toml.parent / "block2d_tight_outline.csv", tmp_path)
    paths = revolved_scene(cm.fem.rest, cm.fem, kept=np.concatenate(ds.kept_regions), object_start=cm.pose(0.0)[1],
                           scene_xml=tmp_path / xml.name, scene_toml=tmp_path / toml.name, out=tmp_path / "o",
                           stem="block", axis="x", offset=0.0, arms=4, target_tets=600)
    assert all(p.is_file() for p in paths.values())
    # the same section gives the same tet mesh again (fTetWild's differed run to run: 2046 vs 2188
    # tets; it is the fallback where Gmsh's library cannot load, and then this check is left out)
    from simfab.fem.meshing import load_gmsh

    try:
        load_gmsh()
    except RuntimeError:
        return check_scene(paths, cm)
    again = revolved_scene(cm.fem.rest, cm.fem, kept=np.concatenate(ds.kept_regions), object_start=cm.pose(0.0)[1],
                           scene_xml=tmp_path / xml.name, scene_toml=tmp_path / toml.name, out=tmp_path / "o2",
                           stem="block", axis="x", offset=0.0, arms=4, target_tets=600)
    first, second = np.load(paths["mesh"]), np.load(again["mesh"])
    assert all(np.array_equal(first[k], second[k]) for k in first.files)
    check_scene(paths, cm)


def check_scene(paths, cm):
    """The revolved scene has 10-node tets, the ball starts outside the part, the fixed box holds
    the base all around the axis, and the object, path and material are the 2D scene's."""
    from simfab.coupling.scene import load_coupling_scene
    from simfab.coupling.simulate import check_start
    from simfab.fem.p2 import P2Model

    cm3 = load_coupling_scene(paths["scene_xml"])
    assert cm3.dim == 3 and isinstance(cm3.fem, P2Model)
    check_start(cm3)  # the ball starts outside the part
    # its tets are stored beside the printable STL they were meshed from, so a convergence study takes the
    # scene (run_levels checks the part's table before its first level: none asked here)
    from simfab.coupling.converge import run_levels
    from simfab.coupling.scene import read_scene_toml

    comp = read_scene_toml(paths["scene_toml"])["compliant"]
    assert comp["mesh"] == Path(paths["stl"]).name and comp["target_elements"] == cm3.fem.n_elements
    assert run_levels(paths["scene_xml"], ()) == []
    X = cm3.fem.rest[np.asarray(cm3.fixed_vertices)]
    assert X.shape[0] > 10 and np.ptp(X[:, 0]) < 2e-3  # the base's back face only
    r = np.hypot(X[:, 1], X[:, 2])
    ang = np.arctan2(X[:, 2], X[:, 1])
    assert r.max() > 0.009 and np.histogram(ang, bins=8, range=(-np.pi, np.pi))[0].min() > 0  # all around the axis
    # the object, its path and the material are the 2D scene's
    assert np.allclose(cm3.pose(0.0)[1], cm.pose(0.0)[1]) and cm3.fem.material.name == cm.fem.material.name


def test_arms_without_a_keep_site_are_refused_before_optimizing(tmp_path):
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "simfab", "couple", "optimize", "standside2d", "--revolve-axis", "x",
                        "--revolve-arms", "4", "--out", str(tmp_path / "o")], capture_output=True, text=True)
    assert r.returncode == 2 and "--revolve-arms" in r.stderr and "keep" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())
