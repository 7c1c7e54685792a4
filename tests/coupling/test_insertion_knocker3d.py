"""Insertion along a rotating path: the bundled door knocker (its own module so that the test
runner can place it on another worker)."""

import numpy as np
from _coupling_checks import check_every_step

from simfab.coupling.scene import load_coupling_scene
from simfab.coupling.simulate import simulate_insertion


def test_knocker_every_step_feasible_through_the_rotation():
    # linear tets on the bundled mesh (the scene runs P2: ~20x the time); the rotating path, the
    # feasibility of every step and the end-of-path warning do not depend on the elements
    cm = load_coupling_scene("knocker3d", overrides={"simulation": {"element_order": 1}})
    res = simulate_insertion(cm)
    # the path ends in the prescribed rotation, which a run cannot continue: when the ring is still
    # drawn in at its last step the run says so (the sign of that small last force, ~5% of the
    # peak, is not robust), and it never says so otherwise
    from simfab.coupling.settle import still_drawn_in

    check_every_step(res, allow=("the path ends in a rotation",))
    assert any("the path ends in a rotation" in w for w in res.warnings) == still_drawn_in(res.steps)
    # the ring really turned: its last orientation is 90 degrees about its bar from the first
    q0, q1 = res.steps[0].quat, res.steps[-1].quat
    angle = 2.0 * np.degrees(np.arccos(min(1.0, abs(float(np.dot(q0, q1))))))
    assert abs(angle - 90.0) < 1.0
    assert max(r.energy for r in res.steps) > 0  # the clip was deformed on the way
