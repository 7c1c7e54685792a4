"""Insertion simulation in 3D: the bundled clip on a cylinder (its own module so that the test
runner can place it on another worker than the 2D scenes)."""

from _coupling_checks import check_every_step

from simfab.coupling.outputs import summarize
from simfab.coupling.scene import load_coupling_scene
from simfab.coupling.simulate import simulate_insertion


def test_3d_clip_every_step_feasible_and_tight():
    res = simulate_insertion(load_coupling_scene("clip3d"))
    check_every_step(res)
    prof, _ = summarize(res)
    assert prof.category == "tight" and prof.F_grip > 0
    # the clip's stress stays finite and the part was really deformed by the cylinder
    assert 1e6 < max(r.max_von_mises for r in res.steps) < 1e9
