"""Insertion simulation in 3D: the bundled clip on a cylinder (its own module so that the test
runner can place it on another worker than the 2D scenes)."""

import numpy as np

from simfab.coupling.outputs import summarize
from simfab.coupling.scene import load_coupling_scene
from simfab.coupling.simulate import simulate


def _check_every_step(res):
    tol = res.model.tol
    assert len(res.steps) == len(res.model.s_steps)
    for r in res.steps:
        assert r.penetration <= tol, f"s={r.s}: penetration {r.penetration} > {tol}"
        assert r.min_det_F > 0, f"s={r.s}: inverted element"
        assert np.all(np.isfinite(r.x)) and np.isfinite(r.energy) and np.isfinite(r.force)


def test_3d_clip_every_step_feasible_and_tight():
    res = simulate(load_coupling_scene("clip3d"))
    _check_every_step(res)
    prof, _ = summarize(res)
    assert prof.category == "tight" and prof.F_grip > 0
    # the clip's stress stays finite and the part was really deformed by the cylinder
    assert 1e6 < max(r.max_von_mises for r in res.steps) < 1e9
