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
    dome = unitcell.deploy(cfg, large)
    saddle = unitcell.deploy(cfg, small)
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
