"""Assertions shared by the coupling tests (imported as a sibling module)."""

import numpy as np


def check_every_step(res, allow=()):
    """Every insertion step ends feasible: penetration <= the model's tolerance, no inverted
    element, finite state and figures, steps in increasing order along the path (the planned ones,
    then any taken past the path's end until the object came to rest); and the run raised no
    warning about itself (e.g. a rigid motion of the part that nothing resists, which would make
    the equilibrium non-unique, steps too coarse, an unfinished insertion). A part stressed beyond
    its material's yield stress is a statement about the design, not the run, and is allowed, as
    are warnings containing one of the strings ``allow``."""
    run_warnings = [w for w in res.warnings if not any(a in w for a in ("yield stress", *allow))]
    assert not run_warnings, run_warnings
    tol = res.model.tol
    s = res.column("s")
    assert len(res.steps) >= len(res.model.s_steps) and np.allclose(s[: len(res.model.s_steps)], res.model.s_steps)
    assert np.all(np.diff(s) > 0)
    for r in res.steps:
        assert r.penetration <= tol, f"s={r.s}: penetration {r.penetration} > {tol}"
        assert r.min_det_F > 0, f"s={r.s}: inverted element"
        assert np.all(np.isfinite(r.x)) and np.isfinite(r.energy) and np.isfinite(r.force)
