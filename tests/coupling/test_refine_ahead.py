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


def _true_check(cm, x, s, state):
    """Per boundary facet, the largest psi over its check points at (x, s), every point evaluated."""
    refined = np.zeros(len(cm.contact_facets), dtype=bool)
    refined[sorted(state.refined)] = True
    out = np.empty(len(cm.contact_facets))
    for flag in (False, True):
        f = np.flatnonzero(refined == flag)
        if len(f):
            w, _ = refine.check_lattice(cm.dim, state.order, flag)
            y = np.einsum("pv,fvd->fpd", w, x[cm.contact_facets[f]])
            out[f] = cm.field.evaluate(y.reshape(-1, cm.dim), cm.pose(s), hessian=False).psi.reshape(len(f), -1).max(1)
    return out


@pytest.mark.parametrize("scene", ["standside2d", "snapfit"])
def test_a_check_carried_to_nearby_positions_bounds_every_facet(scene):
    """A facet check stands for the check at other positions of the same step when A's boundary moved
    little (the warm start's check for Newton's solution): moved by delta, its bounds become psi_max +
    L delta, and they bound every listed facet's largest psi while every facet it leaves out is outside O
    (psi evaluated at every check point). Moved toward O past the gaps, nothing is carried: the check
    finds the crossing."""
    from simfab.coupling import config as C
    from simfab.verification.snapfit import snapfit_model

    cm = load_design_scene("standside2d").cm if scene == "standside2d" else snapfit_model(30.0, 0.0)
    st = stepper.Stepper(cm)
    rng = np.random.default_rng(0)
    carried = crossed = 0
    for s in cm.s_steps:
        st.keep(st.step(float(s)).record)
        state = st.state
        memo = refine.facet_check(cm, state.x, state.s, state)
        if len(memo.ids) == 0 or memo.psi_max.max() >= 0:
            continue
        # a displacement within what the check certifies: the largest allowed, a third of it per vertex
        allowed = min(memo.margin / (C.PSI_LIPSCHITZ * (1 + 2 * refine.COVER[cm.dim])),
                      -memo.psi_max.max() / C.PSI_LIPSCHITZ)
        u = rng.normal(size=state.x.shape)
        x1 = state.x + u * (allowed / 3 / np.linalg.norm(u, axis=1).max())
        check = refine.facet_check(cm, x1, state.s, state)
        delta = np.linalg.norm((x1 - state.x)[cm.fem.boundary_vertices], axis=1).max()
        assert check.x is x1 and np.array_equal(check.ids, memo.ids)
        np.testing.assert_allclose(check.psi_max, memo.psi_max + C.PSI_LIPSCHITZ * delta, rtol=0, atol=1e-15)
        true = _true_check(cm, x1, state.s, state)
        assert np.all(true[check.ids] <= check.psi_max)
        assert np.all(np.delete(true, check.ids) < 0)
        carried += 1
        # A moved toward O by its nearest vertex's gap and half the longest boundary edge: not carried
        bv = cm.fem.boundary_vertices
        ev = cm.field.evaluate(state.x[bv], cm.pose(state.s), hessian=False)
        j = int(np.argmax(ev.psi))
        edge = np.linalg.norm(np.diff(state.x[cm.contact_facets], axis=1), axis=2).max()
        x2 = state.x + ev.grad[j] * (-ev.psi[j] + 0.5 * edge)
        if _true_check(cm, x2, state.s, state).max() > 0:
            check = refine.facet_check(cm, x2, state.s, state)
            assert check.x is x2 and check.psi_max.max() > 0
            crossed += 1
        state.check = memo  # (the state as the run left it)
    assert carried >= 5 and crossed >= 5
