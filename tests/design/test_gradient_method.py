"""The gradient design method's treatment of the brief's non-smooth figures (simfab.design.gradient):
the grip read at a seat the rest search brackets, the target-profile error whose run ends at a rest
point that moves with the design, the loose grip's square-root surrogate, the gap of a start that
touches nothing, and the coupling ratio continued past an ejecting end pose."""

import math

import numpy as np
import pytest

from simfab.coupling.scene import load_coupling_scene
from simfab.coupling.simulate import simulate_insertion
from simfab.design import figure_gradients as FG
from simfab.design import gradient as G
from simfab.design.brief import DesignConfig, TargetProfile
from simfab.design.problem import evaluate, make_problem

#: an ejecting run's CR = 100 E_ss / E_max with E_ss = E_max: a product and a quotient, each rounded
#: (100.00000000000001 on some machines), so 100 to a couple of ulps
CR_ROUND = 2 * np.finfo(float).eps


def test_grip_gradient_follows_the_rest_point():
    # block2d_tight's ball seats against the socket's bottom: the force jumps from +5 N to -2 N within
    # 3 um there, and the grip is read at the rest point the rest search brackets anew for every design.
    # The seat is a kink, so no derivative is exact there: the test asks for the secant's sign and size,
    # which the grip's derivative at the record's fixed position misses by an order of magnitude.
    cm = load_coupling_scene("block2d_tight")
    P = make_problem(cm, DesignConfig(grip="tight", handles=3, placement="spatial")).with_settings(hold_steps=True)
    Jh = G.handle_jacobian(P.handles)
    h0 = P.handles.identity()
    dh = np.random.default_rng(0).standard_normal(len(h0)) * P.sigma0
    ev = evaluate(P, h0, keep_result=True, recorder=lambda cm: G.SensitivityRecorder(cm, G.stress_measure(P, cm)))
    fg = G.figure_gradients(P, ev, Jh)
    assert fg.steady_index >= len(ev.result.model.s_steps)  # read at a record of the rest search
    eps = 0.1  # the seat is a kink: a secant over whole re-simulations, not an infinitesimal difference
    ep, em = evaluate(P, h0 + eps * dh), evaluate(P, h0 - eps * dh)
    assert ep.figures["category"] == em.figures["category"] == "tight"
    fd = (ep.figures["grip_force"] - em.figures["grip_force"]) / (2 * eps)
    assert float(fg.gradients["grip_force"] @ dh) == pytest.approx(fd, rel=0.6)
    fixed = float(np.asarray(ev.recorder.insert[fg.steady_index].grip).ravel() @ Jh @ dh)
    assert abs(fixed - fd) > 3 * abs(fd)  # (-196 against -14)


def test_target_model_follows_the_rest_point():
    # A run whose forces are linear in h, F(h) = F0 + P h, ending in the rest search's bracket (F_a > 0 >= F_b,
    # the overshoot -30 N): rms^2 is then a smooth function of h through the forces and the rest point
    # s*(h) between the last two records. The model's gradient must match central differences of
    # rms_error itself.
    rng = np.random.default_rng(0)
    ts = np.linspace(0.0, 0.01, 21)
    target = TargetProfile(s=ts, force=8.0 * np.sin(600.0 * ts))
    s = np.r_[np.linspace(0.0, 0.0095, 20), 0.00952]
    F0 = 8.0 * np.sin(600.0 * s) + 0.5
    F0[-2:] = 4.0, -30.0
    P = rng.standard_normal((len(s), 4)) * np.r_[np.ones(len(s) - 1), 50.0][:, None]
    h0 = 0.01 * rng.standard_normal(4)

    def rms2(h):
        return target.rms_error(s, F0 + P @ h) ** 2

    m = G.target_model(target, s, F0 + P @ h0, P)
    assert m.value == pytest.approx(rms2(h0), rel=1e-12)
    fd = np.array([(rms2(h0 + 1e-6 * e) - rms2(h0 - 1e-6 * e)) / 2e-6 for e in np.eye(4)])
    assert np.allclose(m.gradient, fd, rtol=1e-6, atol=1e-8 * np.abs(fd).max())
    assert np.linalg.eigvalsh(m.hessian).min() >= -1e-9 * np.abs(m.hessian).max()  # Gauss-Newton: PSD


def test_loose_bound_square_root_surrogate():
    row = G.ConstraintRow(name="coupling_ratio", sign=-1.0, bound=1e-3, scale=1.0, root=True)
    assert row.value(1e-3) == pytest.approx(0.0, abs=1e-15)
    assert row.value(0.0) == pytest.approx(math.sqrt(1e-3))  # satisfied: c >= 0
    assert row.value(4e-3) < 0
    g = np.array([2.0, -1.0])  # dCR/dh
    v, eps = 4e-3, 1e-9
    fd = (row.value(v + eps) - row.value(v - eps)) / (2 * eps)
    assert np.allclose(row.gradient(v, g), fd * g, rtol=1e-6)
    assert not np.any(row.gradient(0.0, g))  # CR = 0 (no contact at the seat): the bound is inactive
    plain = G.ConstraintRow(name="grip_force", sign=1.0, bound=3.0, scale=1.0)
    assert plain.value(5.0) == 2.0 and np.allclose(plain.gradient(5.0, g), g)


def test_flat_start_closes_the_gap():
    # paddleside2d's U-channel matches the blade exactly: no contact, every figure's gradient is zero; the
    # gap to the blade is not, and the SQP closes it (the clearance bound linearized) before the grip's
    cm = load_coupling_scene("paddleside2d", overrides={"compliant": {"target_elements": 500},
                                                        "simulation": {"steps": 15}})
    P = make_problem(cm, DesignConfig(grip="tight", grip_force=(5.0, math.inf), handles=3, placement="spatial"))
    Jh = G.handle_jacobian(P.handles)
    Ph = P.with_settings(hold_steps=True)
    ev = evaluate(Ph, P.handles.identity(), keep_result=True,
                  recorder=lambda cm: G.SensitivityRecorder(cm, G.stress_measure(P, cm)))
    assert ev.figures["category"] == "none" and ev.figures["seat_clearance"] > 0
    fg = G.figure_gradients(P, ev, Jh)
    assert G.flat_start(G.constraint_rows(P), fg, {})
    # the gap's gradient (at a vanishing temperature: the nearest vertex's) against a central difference of
    # whole evaluations (the part is undeformed: exact while the nearest vertex stays the nearest)
    g = G.gap_gradient(ev.result, fg.steady_index, Jh, temperature_rel=1e-9)
    dh = np.random.default_rng(0).standard_normal(len(g)) * P.sigma0
    eps = 1e-3
    ep, em = evaluate(Ph, P.handles.identity() + eps * dh), evaluate(Ph, P.handles.identity() - eps * dh)
    fd = (ep.figures["seat_clearance"] - em.figures["seat_clearance"]) / (2 * eps)
    assert float(g @ dh) == pytest.approx(fd, rel=1e-6)
    res = G.optimize_gradient(P, iterations=4, seed=0)
    assert not res.message.startswith("annealing pre-phase")
    # no annealing: every insertion but the final plain re-run gave gradients
    assert res.simulations == res.gradient_evaluations + 1
    assert res.best.status == "ok" and res.best.figures["category"] != "none"
    assert res.best.objective < res.initial.objective


def test_gap_gradient_on_p2_candidates():
    # a P2 scene's candidates (--element-order 2) put edge nodes at the linear mesh's midpoints: the gap's
    # derivative on every node is chained to the corners before dX/dh, so it matches whole evaluations too
    cm = load_coupling_scene("paddleside2d", overrides={"compliant": {"target_elements": 300},
                                                        "simulation": {"steps": 8, "element_order": 2}})
    P = make_problem(cm, DesignConfig(grip="tight", grip_force=(5.0, math.inf), handles=3, placement="spatial"))
    Jh = G.handle_jacobian(P.handles)
    ev = evaluate(P, P.handles.identity(), keep_result=True)
    assert ev.result.model.fem.element_order == 2 and ev.figures["category"] == "none"
    g = G.gap_gradient(ev.result, len(ev.result.steps) - 1, Jh, temperature_rel=1e-9)
    dh = np.random.default_rng(1).standard_normal(len(g)) * P.sigma0
    eps = 1e-3
    ep, em = evaluate(P, P.handles.identity() + eps * dh), evaluate(P, P.handles.identity() - eps * dh)
    fd = (ep.figures["seat_clearance"] - em.figures["seat_clearance"]) / (2 * eps)
    # the nearest node is an edge node (its derivative goes half to each corner; a wrong chain is off by O(1));
    # measured 7e-10 at eps 3e-3, 1e-3 and 1e-4. The gradient assumes the undeformed part: a step out of
    # contact starts at the rest shape (when extrapolated warm starts carried Newton's residual
    # deformation, 3-4e-8 m, on from step to step, this was 8.3e-3), and carries d_hat's dependence on the
    # mesh (without it 1.1e-3)
    assert float(g @ dh) == pytest.approx(fd, rel=1e-6)


def test_an_ejecting_start_with_a_coupling_ratio_bound_is_a_flat_start():
    # clip2d_eject's profile has no dip after its peak: CR = 100 % for every shape nearby (gradient
    # zero), which no SQP step can linearize towards a loose or tight brief's bound
    cm = load_coupling_scene("clip2d_eject", overrides={"simulation": {"steps": 10}})
    P = make_problem(cm, DesignConfig(grip="loose", handles=3, placement="spatial"))
    Jh = G.handle_jacobian(P.handles)
    ev = evaluate(P.with_settings(hold_steps=True), P.handles.identity(), keep_result=True,
                  recorder=lambda cm: G.DeferredRecorder(cm, G.stress_measure(P, cm)))
    fg = G.figure_gradients(P, ev, Jh)
    assert ev.figures["category"] == "ejects" and ev.figures["coupling_ratio"] == pytest.approx(100.0, rel=CR_ROUND)
    assert np.abs(fg.gradients["coupling_ratio"]).max() <= 1e-9 * np.abs(fg.gradients["E_max"]).max()
    assert G.flat_start(G.constraint_rows(P), fg, {})
    # without a coupling-ratio bound ("any" grip) the forces' gradients give the SQP its direction
    P_any = make_problem(cm, DesignConfig(grip="any", insertion_force=(0.0, 0.1), handles=3, placement="spatial"))
    assert not G.flat_start(G.constraint_rows(P_any), fg, {})


def test_a_correction_round_resumes_from_the_previous_best():
    # A correction round starts from the previous run's best design with other correction factors: the
    # simulation is the same (held steps, seeded refinement), only its scoring changes, so the round reuses
    # it (one insertion fewer) and takes the same steps as a round that simulates its start again
    cm = load_coupling_scene("block2d_tight", overrides={"compliant": {"target_elements": 250},
                                                         "simulation": {"steps": 10}})
    P = make_problem(cm, DesignConfig(grip="tight", grip_force=(3.0, 5.0), handles=3, placement="spatial"))
    res = G.optimize_gradient(P, iterations=3, seed=0)
    assert res.resume is not None
    P2 = res.problem.with_settings(corrections={"grip_force": 0.7, "insertion_force": 0.7, "removal_force": 0.7})
    resumed = G.optimize_gradient(P2, start=res.best.h, resume=res.resume, iterations=3, seed=1)
    again = G.optimize_gradient(P2, start=res.best.h, iterations=3, seed=1)
    assert resumed.simulations == again.simulations - 1
    assert [h["value"] for h in resumed.history] == [h["value"] for h in again.history]
    assert resumed.best.objective == again.best.objective


def _ellipse_turned_twice():
    """clip2d_loose's clamp with an elliptical object (semi-axes 11.2 x 8 mm, long axis along the path, clear
    of the clamp) turned 90 deg (its long axis presses the arc: the snap), 180 deg (clear again: the valley),
    then 270 deg while its centre moves 0.3 mm away from the clamp's bottom: the end pose presses the arc
    harder than the snap did, so the profile ejects at its end pose."""
    from simfab.contact.imls import build_imls, curve_normals
    from simfab.coupling.config import InsertionConfig
    from simfab.coupling.simulate import make_coupling_model
    from simfab.io.mjcf import Trajectory

    base = load_coupling_scene("clip2d_loose")
    t = np.linspace(0, 2 * np.pi, 120, endpoint=False)
    v = np.c_[11.2e-3 * np.cos(t), 8.0e-3 * np.sin(t)]
    q = [[math.cos(a), 0, 0, math.sin(a)] for a in np.radians([0, 0, 90, 180, 270]) / 2]
    path = Trajectory(np.array([[1.0e-3, 0, 0], [0.9e-3, 0, 0], [0.9e-3, 0, 0], [0.9e-3, 0, 0], [1.2e-3, 0, 0]]),
                      np.array(q), rot_length_scale=0.01)
    return make_coupling_model(name="ellipse", fem=base.fem, field=build_imls(v, curve_normals(v)), path=path,
                               fixed_vertices=base.fixed_vertices, object_vertices=v,
                               options=InsertionConfig(steps=16, fix_all_axes=True))


def test_ejecting_end_pose_continues_the_coupling_ratio(monkeypatch):
    # an end pose pressing harder than the snap before it: CR = 100 % with a zero gradient; the ratio
    # continued past the category, 100 E_end / E_pk, has a gradient (against central differences of whole
    # evaluations; exact maxima, equilibria solved far below the simulation's tolerance), so the SQP
    # starts without the annealing pre-phase
    from simfab.coupling import config as C

    monkeypatch.setattr(FG, "TEMPERATURE_REL", 0.0)  # the smooth maxima: simfab.design.figure_gradients
    monkeypatch.setattr(C, "NEWTON_GRAD_TOL_REL", 1e-10)
    monkeypatch.setattr(C, "NEWTON_GRAD_TOL_START", 1e-10)
    monkeypatch.setattr(C, "NEWTON_STEP_TOL_REL", 1e-12)
    P = make_problem(_ellipse_turned_twice(), DesignConfig(grip="loose", handles=3, placement="spatial"))
    Ph = P.with_settings(hold_steps=True)
    Jh = G.handle_jacobian(P.handles)
    h0 = P.handles.identity()
    ev = evaluate(Ph, h0, keep_result=True, recorder=lambda cm: G.DeferredRecorder(cm, G.stress_measure(P, cm)))
    fg = G.figure_gradients(P, ev, Jh)
    assert ev.figures["category"] == "ejects" and ev.figures["coupling_ratio"] == pytest.approx(100.0, rel=CR_ROUND)
    assert fg.ratio_continued and fg.values["coupling_ratio"] == G.ejecting_ratio(ev.result) > 100.0
    assert not G.flat_start(G.constraint_rows(P), fg, {})
    dh = np.random.default_rng(0).standard_normal(len(h0)) * P.sigma0
    eps = 1e-3  # (at 1e-2 the snap's refinement points differ between the two runs: a non-smooth event)
    ep, em = evaluate(Ph, h0 + eps * dh, keep_result=True), evaluate(Ph, h0 - eps * dh, keep_result=True)
    fd = (G.ejecting_ratio(ep.result) - G.ejecting_ratio(em.result)) / (2 * eps)
    assert abs(fd) > 0
    assert float(fg.gradients["coupling_ratio"] @ dh) == pytest.approx(fd, rel=1e-4)
    # a translation's end (clip2d_eject) is not an end pose: no continued ratio
    res = simulate_insertion(load_coupling_scene("clip2d_eject", overrides={"simulation": {"steps": 10}}))
    assert G.analyze_run(res).category == "ejects" and G.ejecting_ratio(res) is None
