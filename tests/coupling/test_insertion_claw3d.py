"""Insertion of the largest bundled model: the four-finger claw on a sphere (5,130 tets, the ball
an exact sphere; its own module so that the test runner can place it on another worker)."""

from _coupling_checks import check_every_step

from simfab.coupling.outputs import summarize
from simfab.coupling.scene import load_coupling_scene
from simfab.coupling.simulate import simulate_insertion


def test_claw_every_step_feasible_and_tight():
    # linear tets on the bundled mesh (the scene runs P2: ~10x the time); feasibility of every
    # step and the tight grip do not depend on the elements
    res = simulate_insertion(load_coupling_scene("claw3d", overrides={"simulation": {"element_order": 1}}))
    check_every_step(res)
    prof, _ = summarize(res)
    assert prof.category == "tight" and prof.F_grip > 0
