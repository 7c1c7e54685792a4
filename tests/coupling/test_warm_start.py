"""Warm start and boundary conditions of the insertion: the contact gaps restored on the
extrapolated warm start, and the ``fixed_axes`` option."""

import numpy as np
import pytest

import simfab.coupling.predictor as P
import simfab.coupling.simulate as S
from simfab.coupling.config import InsertionOptions
from simfab.coupling.scene import load_coupling_scene
from simfab.errors import InputError


def test_snapped_warm_start_puts_contact_vertices_back_at_their_last_gap(monkeypatch):
    # Wrap the real _snap_contacts: on every step with contact, the vertices that ended the last
    # step within d_hat of O must start the next one near their last distance. The move is one
    # projection along the IMLS normal, exact to first order: the remaining error is the field's
    # curvature times the squared move, far below 5% of d_hat here (moves are a few d_hat at most).
    calls = []
    real = P._snap_contacts

    def spy(cm, state, x, s_new, ctx):
        out = real(cm, state, x, s_new, ctx)
        if out is not None:
            calls.append((cm, state.points, state.final[4].copy(), out, s_new))
        return out

    monkeypatch.setattr(P, "_snap_contacts", spy)
    S.simulate(load_coupling_scene("cclamp2d"))
    assert len(calls) > 10  # the clamp is in contact for most of the insertion
    for cm, pts, d_prev, x, s in calls:
        dh = P._point_dhat(cm, pts)
        act = (pts.weights[:, 0] == 1.0) & (d_prev < dh)
        R, p = cm.pose(s)
        d_new = -cm.field.evaluate(pts.positions(x)[act], (R, p), hessian=False).psi
        assert np.all(d_new > 0)
        # what matters: they stay in the barrier's range (0, d_hat), near their last gap (a vertex
        # shared with refined facets whose points were in contact too takes the mean of their
        # moves, which lands it within half of d_hat of its own gap)
        assert np.all(d_new < dh[act])
        assert np.all(np.abs(d_new - d_prev[act]) <= 0.5 * dh[act])


@pytest.mark.parametrize("axes, message", [("xq", "axis letters"), ("xx", "axis letters"), ("", "axis letters")])
def test_fixed_axes_must_be_distinct_axis_letters(axes, message):
    with pytest.raises(InputError, match=message):
        InsertionOptions(fixed_axes=axes)


def test_fixed_axes_cannot_be_combined_with_fix_all_axes():
    with pytest.raises(InputError, match="fix_all_axes"):
        InsertionOptions(fixed_axes="xz", fix_all_axes=True)


def test_fixed_axes_must_include_the_insertion_axis_and_exist_in_2d():
    with pytest.raises(InputError, match="insertion axis"):
        load_coupling_scene("clip3d", overrides={"simulation": {"fixed_axes": "yz"}})
    with pytest.raises(InputError, match="2D part"):
        load_coupling_scene("cclamp2d", overrides={"simulation": {"fixed_axes": "xz"}})


def test_fixed_axes_hold_exactly_the_named_axes_of_the_fixed_region():
    cm = load_coupling_scene("clip3d", overrides={"simulation": {"fixed_axes": "xz"}})
    free = cm.free.reshape(-1, 3)
    assert not free[cm.fixed_vertices][:, [0, 2]].any() and free[cm.fixed_vertices][:, 1].all()
    others = np.setdiff1d(np.arange(cm.fem.n_vertices), cm.fixed_vertices)
    assert free[others].all()


def test_warm_starts_keep_new_points_off_the_object(monkeypatch):
    # A point starting almost on O costs a Newton iteration per doubling of its gap; every warm
    # start must have the points that were not that close at the last step at least
    # WARM_START_FLOOR * d_hat away (half of it allowed for the one-projection lift's curvature error)
    import simfab.coupling.config as C

    seen = []
    real = P._warm_start

    def spy(cm, state, s_new, obj, ctx):
        x0 = real(cm, state, s_new, obj, ctx)
        fin = state.final
        if fin is not None and len(fin[4]) == len(state.points):
            R, p = cm.pose(s_new)
            d = -cm.field.evaluate(state.points.positions(x0), (R, p), hessian=False).psi
            new = fin[4] > C.WARM_START_FLOOR * cm.dhat
            seen.append(float(d[new].min() / cm.dhat))
        return x0

    assert C.WARM_START_FLOOR >= 0.05  # the floor is on by default
    monkeypatch.setattr(P, "_warm_start", spy)
    # 3,600 linear tets: the warm start acts on the contact points, whatever the elements
    S.simulate(load_coupling_scene("clip3d", overrides={"compliant": {"target_elements": 3600},
                                                        "simulation": {"element_order": 1}}))
    assert len(seen) > 30 and min(seen) >= 0.5 * C.WARM_START_FLOOR


def test_a_field_steeper_than_the_lipschitz_bound_is_reported(monkeypatch):
    # The facet check and the lazy distance bounds certify points outside O with |grad psi| <= L.
    # The bundled clamp's field has |grad psi| ~ 1.0 at its evaluated points: with L just below
    # that the run must say that its certificates are not rigorous; with the default L = 2, not.
    import simfab.coupling.config as C

    res = S.simulate(load_coupling_scene("cclamp2d"))
    assert not any("gradient reached" in w for w in res.warnings)
    monkeypatch.setattr(C, "PSI_LIPSCHITZ", 0.99)
    res = S.simulate(load_coupling_scene("cclamp2d"))
    assert any("gradient reached" in w and "above the Lipschitz bound 0.99" in w for w in res.warnings)
