"""Unit cell: an insert larger than the gap deploys a dome, a smaller one a saddle (thesis, Ch. 5)."""

import pytest

from simfab.deploy import unitcell


@pytest.fixture(scope="module")
def scene():
    return unitcell.load_cell_scene(unitcell.default_scene_path())


def test_larger_insert_dome_smaller_insert_saddle(scene):
    cfg, inserts = scene
    large, small = inserts["insert_large"], inserts["insert_small"]
    assert large.r > cfg.gap > small.r
    dome = unitcell.deploy_cell(cfg, large)
    saddle = unitcell.deploy_cell(cfg, small)
    assert dome.curvature["gaussian_curvature"] > 0 and dome.curvature["kind"] == "dome"
    assert saddle.curvature["gaussian_curvature"] < 0 and saddle.curvature["kind"] == "saddle"
    # the shapes are genuinely 3D: the dome lifts the insert, the saddle bends the ring (> 10% of the cell)
    assert abs(dome.curvature["insert_rise"]) > 0.1 * cfg.size
    assert saddle.curvature["saddle_amplitude"] > 0.1 * cfg.size
    # unloaded equilibria (perturbation removed) that are stable
    assert dome.stable and saddle.stable
    assert len(dome.states) == cfg.increments + 1
    assert dome.curvature_history[0] == pytest.approx(0.0, abs=1e-9)  # flat start
    assert dome.curvature_history[-1] == pytest.approx(dome.curvature["gaussian_curvature"])


@pytest.mark.parametrize("plane, half", [("xy", "width"), ("xz", "thickness")])
def test_bending_strain_of_a_circular_arc(plane, half):
    """A straight strip (sheet normal +z) bent into an arc of radius R: fibre strain c / R at interior
    nodes (c: half the width for bending in the sheet plane xy, half the thickness out of it), 0 at
    the rod ends. Per node the discrete curvature 2 tan(phi/2) over the rest Voronoi length R phi
    (phi: turning angle) is (1 + phi^2/12 + O(phi^4)) / R, the tolerance below."""
    import numpy as np

    from simfab.deploy.export import bending_strain
    from simfab.rods.model import NetworkBuilder, RodMaterial, Section

    R, n, L = 0.05, 20, 0.04
    phi = np.linspace(0.0, L / R, n + 1)
    a, b = R * np.sin(phi), R * (1.0 - np.cos(phi))
    arc = np.stack([a, b, 0 * a] if plane == "xy" else [a, 0 * a, b], axis=1)
    straight = np.stack([np.linspace(0.0, L, n + 1), 0 * a, 0 * a], axis=1)
    sec = Section(width=4e-3, thickness=1e-3)
    nb = NetworkBuilder()
    nb.add_rod("strip", arc, rest_points=straight, section=sec, material=RodMaterial(young=1e9),
               director=(0.0, 0.0, 1.0))
    model, state = nb.build()
    eps = bending_strain(model, state)
    c = 0.5 * (sec.width if half == "width" else sec.thickness)
    assert eps[[0, n]] == pytest.approx([0.0, 0.0], abs=0)
    np.testing.assert_allclose(eps[1:n], c / R, rtol=1.01 * (L / R / n) ** 2 / 12)


@pytest.mark.parametrize("field, value, match", [
    ("segments", 10.5, "whole number in \\[2, 200\\]"), ("segments", 1, "\\[2, 200\\]"), ("segments", 10**5, "200"),
    ("increments", 0, "\\[1, 1000\\]"), ("increments", 2.0, "whole number"), ("segments", True, "whole number"),
    ("gap", 0.05, "no room for the spokes"), ("corner_gap", 0.05, "half the cell size"), ("size", -1.0, "positive"),
])
def test_every_cell_field_is_checked_naming_it(field, value, match):
    from simfab.errors import InputError

    with pytest.raises(InputError, match=match) as e:
        unitcell.CellConfig(**{field: value})
    assert e.value.where == f"cell_{field}"
