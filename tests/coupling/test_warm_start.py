"""Warm start and boundary conditions of the insertion: the contact gaps restored on the
extrapolated warm start, and the ``fixed_axes`` option."""

import numpy as np
import pytest

import simfab.coupling.config as C
from simfab.coupling import predictor
from simfab.coupling.config import InsertionConfig
from simfab.coupling.layout import point_dhat
from simfab.coupling.objective import make_objective
from simfab.coupling.points import ContactPoints, vertex_points
from simfab.coupling.profile import analyze_run
from simfab.coupling.scene import load_coupling_scene
from simfab.coupling.simulate import simulate_insertion
from simfab.coupling.state import PastStep, StepState
from simfab.coupling.stepper import Stepper
from simfab.errors import InputError
from simfab.verification.snapfit import snapfit_model


def _warm_starts(cm):
    """Drive the insertion of ``cm`` over its planned steps with a :class:`Stepper`; before every
    step after the first, the warm start it is about to use (as ``predictor.warm_start`` computes
    it from the state the step starts from). Yields (state, objective, WarmStart, s)."""
    stepper = Stepper(cm)
    for s in cm.s_steps:
        s = float(s)
        if stepper.steps:
            obj = make_objective(cm, stepper.state, s, stepper.ctx)
            yield stepper.state, obj, predictor.warm_start(cm, stepper.state, s, obj, stepper.ctx), s
        stepper.keep(stepper.step(s).record)


def test_snapped_warm_start_puts_contact_vertices_back_at_their_last_gap():
    # On every step with contact, the vertices that ended the last step within d_hat of O must
    # start the next one near their last distance. The move is one projection along the IMLS
    # normal, exact to first order: the remaining error is the field's curvature times the squared
    # move, far below 5% of d_hat here (moves are a few d_hat at most).
    cm = load_coupling_scene("cclamp2d")
    calls = 0
    for state, _, ws, s in _warm_starts(cm):
        if ws.snapped is None:
            continue
        calls += 1
        pts, d_prev = state.points, state.current_evaluation().distances
        dh = point_dhat(cm, pts)
        act = (pts.weights[:, 0] == 1.0) & (d_prev < dh)
        R, p = cm.pose(s)
        d_new = -cm.field.evaluate(pts.positions(ws.snapped)[act], (R, p), hessian=False).psi
        assert np.all(d_new > 0)
        # what matters: they stay in the barrier's range (0, d_hat), near their last gap (a vertex
        # shared with refined facets whose points were in contact too takes the largest of their
        # moves, which lands it within half of d_hat of its own gap)
        assert np.all(d_new < dh[act])
        assert np.all(np.abs(d_new - d_prev[act]) <= 0.5 * dh[act])
    assert calls > 10  # the clamp is in contact for most of the insertion


def test_a_warm_start_keeps_the_contact_where_restoring_its_gaps_pushed_new_points_into_O():
    # alligator2d's jaws slide over O with their contact spreading: restoring the last gaps on the best
    # extrapolation carried neighbours new to the contact into O, and 11 of its steps started with the
    # contact lost (Newton then found it again a capped step at a time: 217 iterations). Every step
    # after one with contact now starts from a restored, feasible candidate.
    cm = load_coupling_scene("alligator2d")
    lost = kept = 0
    for state, obj, ws, _ in _warm_starts(cm):
        if not np.any(state.current_evaluation().distances < point_dhat(cm, state.points)):
            continue
        if ws.snapped is None:
            lost += 1
        else:
            kept += 1
            assert np.isfinite(obj.value(ws.x))
    assert lost == 0 and kept > 15, (lost, kept)


def test_a_moved_vertex_takes_the_largest_move_its_points_ask_for():
    # Vertex 0 carries its own point (wants 12 um toward O, i.e. -12 um) and, with weights 0.9 and
    # 0.5, two points of its edge to vertex 1 (want -20 um and -18 um). The mean of the wanted
    # moves would carry vertex 0 by ~-17 um, 5 um past where its own point stops (inside O when its
    # gap was under 5 um); the largest signed move, -12 um, carries no point closer than it asks.
    # Vertex 1 carries the edge points only, with weights 0.1 and 0.5: it takes -18 um. Directions
    # are the weighted means of the points' normals (here all +y).
    from types import SimpleNamespace

    pts = ContactPoints(verts=np.array([[0, 0], [0, 1], [0, 1]]),
                        weights=np.array([[1.0, 0.0], [0.9, 0.1], [0.5, 0.5]]), facet=np.array([-1, 0, 0]))
    cm = SimpleNamespace(fem=SimpleNamespace(n_vertices=3))
    x = np.zeros((3, 2))
    sel = np.array([True, True, True])
    dist = np.array([-12e-6, -20e-6, -18e-6])
    direction = np.tile([0.0, 2.0], (3, 1))  # normalized inside
    x1 = predictor.move_points(cm, pts, x, sel, dist, direction)
    np.testing.assert_allclose(x1[0], [0.0, -12e-6], atol=1e-18)
    np.testing.assert_allclose(x1[1], [0.0, -18e-6], atol=1e-18)
    np.testing.assert_array_equal(x1[2], [0.0, 0.0])  # no point on it: unmoved
    # a move away from O (positive) wins over one toward it on the same vertex
    x2 = predictor.move_points(cm, pts, x, sel, np.array([3e-6, -20e-6, -18e-6]), direction)
    np.testing.assert_allclose(x2[0], [0.0, 3e-6], atol=1e-18)


def test_warm_starts_keep_the_contact_the_last_step_ended_with():
    # A warm start with every contact point pushed out of the barrier's range (d >= d_hat) lets
    # Newton's first step, which then does not see O there, release the part's deformation into O
    # (the step cap cuts it to a few percent, and the step takes many iterations). On the stand
    # side the contact predictor's pushes (steps where no extrapolation is feasible) and snapped
    # vertices that overshoot into O could do that.
    lost, seen = [], []
    for state, obj, ws, s in _warm_starts(load_coupling_scene("standside2d")):
        ev = state.current_evaluation()
        if ev is not None and np.any(ev.distances < obj.dhat):
            d, _, _ = obj.distances(ws.x, False)
            seen.append(s)
            if not np.any(d < obj.dhat):
                lost.append(s)
    assert len(seen) > 25 and lost == []


def test_a_part_out_of_contact_starts_each_step_at_its_rest_shape_and_is_reported_untouched():
    # paddleside2d's channel matches the blade: O never comes within d_hat. Out of contact A's only
    # equilibrium is its rest shape, a warm-start candidate then: every step starts there, converged
    # (an extrapolation of the last steps instead carries Newton's residual deformation on and costs
    # iterations: 5 at the first step). The profile is category "none" (its energies are round-off:
    # tight or ejects as they fell), its steady state the path's end.
    cm = load_coupling_scene("paddleside2d", overrides={"compliant": {"target_elements": 300},
                                                        "simulation": {"steps": 8}})
    res = simulate_insertion(cm)
    assert sum(r.iterations for r in res.steps) == 0
    for r in res.steps:
        np.testing.assert_array_equal(r.x, cm.fem.rest)
    prof = analyze_run(res)
    assert prof.category == "none" and prof.coupling_ratio == 100.0 and prof.F_grip == 0.0
    assert prof.index_ss == len(cm.s_steps) - 1


@pytest.mark.parametrize("axes, message", [("xq", "axis letters"), ("xx", "axis letters"), ("", "axis letters")])
def test_fixed_axes_must_be_distinct_axis_letters(axes, message):
    with pytest.raises(InputError, match=message):
        InsertionConfig(fixed_axes=axes)


def test_fixed_axes_cannot_be_combined_with_fix_all_axes():
    with pytest.raises(InputError, match="fix_all_axes"):
        InsertionConfig(fixed_axes="xz", fix_all_axes=True)


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


def test_warm_starts_keep_new_points_off_the_object():
    # A point starting almost on O costs a Newton iteration per doubling of its gap; every warm
    # start must have the points that were not that close at the last step at least
    # WARM_START_FLOOR * d_hat away (half of it allowed for the one-projection lift's curvature error)
    assert C.WARM_START_FLOOR >= 0.05  # the floor is on by default
    # 3,600 linear tets: the warm start acts on the contact points, whatever the elements
    cm = load_coupling_scene("clip3d", overrides={"compliant": {"target_elements": 3600},
                                                  "simulation": {"element_order": 1}})
    seen = []
    for state, _, ws, s in _warm_starts(cm):
        ev = state.current_evaluation()
        if ev is not None:
            R, p = cm.pose(s)
            d = -cm.field.evaluate(state.points.positions(ws.x), (R, p), hessian=False).psi
            dh = point_dhat(cm, state.points)  # (each point's own d_hat: its boundary's edge length)
            new = ev.distances > C.WARM_START_FLOOR * dh
            seen.append(float((d[new] / dh[new]).min()))
    assert len(seen) > 30 and min(seen) >= 0.5 * C.WARM_START_FLOOR


def test_a_field_steeper_than_the_lipschitz_bound_is_reported(monkeypatch):
    # The facet check and the lazy distance bounds certify points outside O with |grad psi| <= L.
    # The bundled clamp's field has |grad psi| ~ 1.0 at its evaluated points: with L just below
    # that the run must say that its certificates are not rigorous; with the default L = 2, not.
    res = simulate_insertion(load_coupling_scene("cclamp2d"))
    assert not any("gradient reached" in w for w in res.warnings)
    monkeypatch.setattr(C, "PSI_LIPSCHITZ", 0.99)
    res = simulate_insertion(load_coupling_scene("cclamp2d"))
    assert any("gradient reached" in w and "above the Lipschitz bound 0.99" in w for w in res.warnings)


def test_a_bisection_trial_starts_from_the_interpolation_of_the_steps_around_it():
    """The rest search goes back and forth along the path: a trial between two of the last three
    steps is offered their interpolations (linear between the nearest on either side, quadratic
    through all three), exact for positions linear / quadratic in s; extrapolations keep to the
    traversal's direction, and a trial outside the three steps gets no candidate."""
    pts = vertex_points(np.arange(5), 2)
    rng = np.random.default_rng(3)
    a, b, c = (rng.standard_normal((5, 2)) for _ in range(3))

    def state(x_of, s_now, s_prev, s_prev2):
        return StepState(x=x_of(s_now), s=s_now, points=pts, refined=set(), order=1,
                         prev=PastStep(x_of(s_prev), s_prev), prev2=PastStep(x_of(s_prev2), s_prev2))

    def lin(s):
        return a + b * s

    def quad(s):
        return a + b * s + c * s * s

    # bisection: from the overshoot at 1.0 back to 0.5, now forward again to 0.75 (lower end 0.0)
    st = state(lin, 0.5, 1.0, 0.0)
    cands = predictor.extrapolations(st, 0.75)
    assert len(cands) == 2
    np.testing.assert_allclose(cands[0], lin(0.75), rtol=0, atol=1e-14)
    st = state(quad, 0.5, 1.0, 0.0)
    np.testing.assert_allclose(predictor.extrapolations(st, 0.75)[1], quad(0.75), rtol=0, atol=1e-13)
    # the linear one takes the nearest steps on either side (0.5 and 1.0), not the older 0.0
    lin_guess = predictor.extrapolations(st, 0.75)[0]
    np.testing.assert_allclose(lin_guess, quad(0.5) + (quad(1.0) - quad(0.5)) * 0.5, rtol=0, atol=1e-14)
    assert predictor.extrapolations(state(lin, 0.5, 1.0, 0.0), 1.5) == []
    # going forward: the extrapolations of the last steps, as before
    np.testing.assert_allclose(predictor.extrapolations(state(quad, 1.0, 0.5, 0.0), 1.5)[1], quad(1.5), atol=1e-13)


@pytest.mark.parametrize("mu", [0.0, 0.3])
def test_steps_out_of_reach_keep_the_rest_shape_without_a_warm_start(mu, monkeypatch):
    # the snap-fit's box travels a gap before it touches the beam: over those steps A rests at its
    # rest shape (bit for bit, no Newton iteration) and no warm-start candidate is evaluated; the
    # first step that reaches A takes the general warm start again, and the profile is the one the
    # general path gives (the verification's contact law: the force rises after the first touch)
    from simfab.verification.snapfit import snapfit_model

    calls = []
    general = predictor.warm_start
    monkeypatch.setattr(predictor, "warm_start",
                        lambda cm, state, s, *a: calls.append(s * (state.direction > 0)) or general(cm, state, s, *a))
    cm = snapfit_model(30.0, mu)
    res = simulate_insertion(cm)
    rest = np.asarray(cm.fem.rest)
    resting = [k for k, r in enumerate(res.steps) if np.array_equal(r.x, rest)]
    assert len(resting) >= 3 and resting == list(range(len(resting)))  # the approach, then contact
    assert all(res.steps[k].iterations == 0 and res.steps[k].barrier_energy == 0.0 for k in resting)
    # the insertion's warm starts (the removal's count as 0) only from the last resting step on
    inserting = [s for s in calls if s > 0]
    assert inserting and min(inserting) > res.steps[resting[-1]].s
    assert len(inserting) <= len(res.steps) - len(resting)
    assert res.steps[len(resting)].iterations > 0 and abs(res.steps[-1].force) > 0


def test_the_contact_predictor_pushes_a_point_by_what_o_takes_out_of_its_gap():
    # Where O arrives within a step, pushing every point O can reach by O's whole normal displacement
    # over-deforms A (Newton then starts far off: cclamp2d's first contact started at 7x the step's
    # energy); the predictor pushes each point by what O's approach takes out of its gap (the whole
    # push only after a dent). The contact onset's two steps, over four step sizes of the P2 clamp:
    # 11, 11, 9, 6 Newton iterations, 37 (the whole push alone: 11, 14, 12, 10; 47 in all).
    onset = []
    for steps in (12, 20, 35, 60):
        res = simulate_insertion(load_coupling_scene("cclamp2d", overrides={
            "compliant": {"target_elements": 450}, "simulation": {"element_order": 2, "steps": steps}}))
        first = next(i for i, r in enumerate(res.steps) if abs(r.path_force) > 0)
        onset.append(sum(r.iterations for r in res.steps[first:first + 2]))
    assert sum(onset) <= 40, onset


def test_a_step_continuing_equal_steps_takes_the_quadratic_extrapolation_after_one_evaluation():
    # Along cclamp2d's smooth profile the quadratic extrapolation wins the contest of the warm-start
    # candidates step after step; a step of the last one's length that started from it takes it
    # again, its contact gaps restored, after one objective evaluation (the contest: three). The
    # shortcut must pick what the contest picks (it did at 28 of 29 steps); where the restored
    # extrapolation is infeasible (the seat engaging at the last planned step) and at a step of another
    # length (the rest search, a bisection) the contest is held.
    cm = load_coupling_scene("cclamp2d")
    stepper = Stepper(cm)
    taken = differ = held = 0
    evaluations = []

    def counted(obj):
        value = obj.value
        obj.value = lambda x: evaluations.append(1) or value(x)
        return obj

    for s in map(float, cm.s_steps):
        state, ctx = stepper.state, stepper.ctx
        if stepper.steps and state.start == "quadratic":
            quadratic = predictor.snap_contacts(cm, state, predictor.extrapolations(state, s)[1], s, ctx)
            evaluations[:] = []
            ws = predictor.warm_start(cm, state, s, counted(make_objective(cm, state, s, ctx)), ctx)
            if not np.isfinite(make_objective(cm, state, s, ctx).value(quadratic)):
                assert len(evaluations) >= 3
                held += 1
                stepper.keep(stepper.step(s).record)
                continue
            assert len(evaluations) == 1 and ws.source == "quadratic"
            np.testing.assert_array_equal(ws.snapped, quadratic)
            state.start, evaluations[:] = "", []  # the contest, for comparison
            contest = predictor.warm_start(cm, state, s, counted(make_objective(cm, state, s, ctx)), ctx)
            assert len(evaluations) >= 3
            differ += contest.source != "quadratic"
            taken += 1
            state.start, evaluations[:] = "quadratic", []  # a step of another length holds the contest
            h = s - state.s
            predictor.warm_start(cm, state, s - 0.5 * h, counted(make_objective(cm, state, s - 0.5 * h, ctx)), ctx)
            assert len(evaluations) >= 3
        stepper.keep(stepper.step(s).record)
    assert taken >= 25 and differ <= 1 and held == 1, (taken, differ, held)


def test_a_point_contact_just_begun_is_pushed_by_the_contact_predictor():
    # Where no extrapolation is feasible the contact predictor pushes the points by their gaps; the
    # extrapolations with their gaps restored are not tried first: the snap-fit's step after its
    # first contact (one point in contact) takes 3 Newton iterations from the predictor's push, 6
    # from the restored quadratic extrapolation (docs/decisions.md, "restored extrapolations before
    # the contact predictor": measured, not kept).
    res = simulate_insertion(snapfit_model(30.0, 0.0))
    first = next(i for i, r in enumerate(res.steps) if abs(r.path_force) > 0)
    assert res.steps[first + 1].iterations <= 4, [r.iterations for r in res.steps[first:first + 3]]
