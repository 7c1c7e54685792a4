"""Facets a step's warm start pushes into O are refined before the step is solved
(:func:`simfab.coupling.refine.warm_crossings`), not after Newton converged with them crossing."""

import numpy as np
import pytest

from simfab.coupling import predictor, refine, stepper
from simfab.coupling.objective import make_objective
from simfab.coupling.points import facet_weights
from simfab.coupling.simulate import simulate_insertion
from simfab.design.problem import profile_figures
from simfab.design.scene import load_design_scene


def test_warm_crossings_are_the_unrefined_facets_inside_O_at_the_warm_start():
    cm = load_design_scene("standside2d").cm
    st = stepper.Stepper(cm)
    w = facet_weights(cm.dim, st.state.order)
    found = 0
    for s in cm.s_steps:
        s = float(s)
        if st.steps:
            state = st.state
            obj = make_objective(cm, state, s, st.ctx)
            x0 = predictor.warm_start(cm, state, s, obj, st.ctx).x
            ids = set(refine.warm_crossings(cm, x0, s, state))
            # psi > 0 inside O, evaluated directly at every unrefined facet's refinement points
            unrefined = np.setdiff1d(np.arange(len(cm.contact_facets)), sorted(state.refined))
            y = np.einsum("pv,fvd->fpd", w, x0[cm.contact_facets[unrefined]])
            psi = cm.field.evaluate(y.reshape(-1, cm.dim), cm.pose(s), hessian=False).psi.reshape(len(unrefined), -1)
            inside = {int(f) for f in unrefined[psi.max(axis=1) > 0]}
            assert ids == inside, s
            found += len(ids)
        st.keep(st.step(s).record)
    assert found > 0  # the scene's warm starts do push facets into O


def test_refining_ahead_saves_second_solves_and_keeps_the_profile(monkeypatch):
    cm = load_design_scene("standside2d").cm
    ahead = simulate_insertion(cm)
    monkeypatch.setattr(stepper, "warm_crossings", lambda *a, **k: [])  # refine after the solve only
    after = simulate_insertion(cm)
    it_ahead = sum(s.iterations for s in ahead.steps)
    it_after = sum(s.iterations for s in after.steps)
    assert it_ahead < 0.95 * it_after
    # the refined facets differ where a facet crossed at a warm start but not at the solution (or the
    # reverse); on this scene the figures still agree to Newton's force tolerance (measured: within
    # 1e-6 relative; the grip 1.1e-4, read between the rest search's bracket ends, whose records may
    # differ)
    f0, f1 = profile_figures(after), profile_figures(ahead)
    for k, rel in (("E_max", 1e-5), ("E_ss", 1e-5), ("removal_force", 1e-5), ("insertion_force", 1e-5),
                   ("grip_force", 1e-3)):
        assert f1[k] == pytest.approx(f0[k], rel=rel), k
