"""Assertions shared by the coupling tests (imported as a sibling module)."""

import numpy as np


def check_every_step(res):
    """Every insertion step ends feasible: penetration <= the model's tolerance, no inverted
    element, finite state and figures; and the run raised no warning (e.g. a rigid motion of the
    part that nothing resists, which would make the equilibrium non-unique)."""
    assert not res.warnings, res.warnings
    tol = res.model.tol
    assert len(res.steps) == len(res.model.s_steps)
    for r in res.steps:
        assert r.penetration <= tol, f"s={r.s}: penetration {r.penetration} > {tol}"
        assert r.min_det_F > 0, f"s={r.s}: inverted element"
        assert np.all(np.isfinite(r.x)) and np.isfinite(r.energy) and np.isfinite(r.force)
