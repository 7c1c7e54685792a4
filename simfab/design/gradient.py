"""Rest-shape design by gradients: the brief's figures and their derivatives with respect to the
handle parameters h, and a gradient-based optimizer over them (a trust-region SQP, :mod:`simfab.design.sqp`).

Derivatives. One insertion of the design X(h) records, per step, the adjoint sensitivities of the
elastic energy E_k, the insertion force F_k, the grip G_k and the averaged von Mises maximum
sigma_k to the rest positions (:mod:`simfab.coupling.adjoint`). X = M_LBS T(h) is linear in h
(:mod:`simfab.design.handles`), so dq/dh = (dX/dh)^T dq/dX with

    dX_i/dt_j = w_ij I,    dX_i/ds_j = w_ij diag(X_i - c_j)          (per axis; inactive handles fixed)

The figures (:func:`simfab.design.problem.profile_figures`) are maxima or values at the steady-state
index of those per-step series; their derivatives (:func:`figure_gradients`):

- E_max, F_in = max(0, -min F), F_rm = max(0, max F) (up to the steady state), the stress maximum over
  the steps: the gradient of the log-sum-exp T log sum_k exp(q_k / T) with T = TEMPERATURE_REL times
  the series' largest magnitude (softmax weights over the steps; the reported value is the exact
  maximum);
- E_ss = E at the steady-state index i_ss (held: a change of the index is a non-smooth event);
  coupling ratio 100 E_ss / E_max by the quotient rule; the grip at the rest point, which moves
  with the design (:func:`rest_grip_gradient`: implicit differentiation of F(s*; X) = 0);
- E_L = |L v|^2 / l^2 (:mod:`simfab.design.modification`): 2 M_L v, exactly;
- the element quality q_e (signed mean ratio) analytically.
- the target-profile error rms^2 (the objective of profile matching) through the force samples at
  fixed step positions and the run's rest point, which moves with the design (:func:`target_model`);
- with friction, F_rm and F_hold from the removal traversal's records (:func:`removal_gradients`),
  whose sensitivities the adjoint's backward pass carries through the friction anchors; the
  insertion runs with lag_tol <= GRADIENT_LAG_TOL (the pipeline tightens the scene's).
On P2 elements every node's derivative is chained to the linear mesh's vertices (the edge nodes
sit at the midpoints; :func:`simfab.fem.shape_derivative.linear_rest_derivative`) before dX/dh.
Not differentiated (gradient None; the optimizer reads it as a constraint without a gradient: it
checks it on every design and reports it): the seat clearance (but for a part that touches nothing,
:func:`gap_gradient`).

Optimizer (:func:`optimize_gradient`): a trust-region SQP (:func:`simfab.design.sqp.trust_region_sqp`)
on z = (h - lower) / (upper - lower) in [0, 1] from the initial shape, one insertion per iteration:
the objective's model needs no simulation - E_L is a quadratic in h with a constant Hessian
(:func:`modification_hessian`), profile matching's rms^2 a function of the force samples and the run's
rest point, whose Gauss-Newton Hessian J^T Q J (:func:`target_model`) comes with their Jacobian J - and only
the brief's constraints are linearized from the insertion: scaled to their SCALES units,
(value - lo) / scale >= 0 and (hi - value) / scale >= 0 (a loose grip's coupling-ratio bound in
sqrt(CR), :class:`ConstraintRow`), aimed AIM_REL inside the bound; the element-quality bound
q_e / q0_e >= QUALITY_REL is imposed exactly in every subproblem (analytic, no simulation), so no
trial is an inverted or degenerate mesh. Target matching restarts the SQP from its best design at the
initial radius when the trust region collapsed (at most RESTARTS times, while that gains): the rest
point's approach (the force between the last planned record and the seat) is not sampled at fixed
positions, and a radius shrunk there stays small after the design has moved on. A start that touches
nothing (every figure's gradient zero) gets the seat clearance's bound, linearized through the gap of
the undeformed part (:func:`gap_gradient`). A start that ejects at an end pose (the pose presses A harder
than the snap before it) has its coupling ratio continued above 100 % (:func:`ejecting_ratio`), which the
SQP linearizes like the ratio itself. Only when neither gives a gradient (no vertex near O; a start that
ejects without an end pose or an earlier peak: :func:`flat_start`), a seeded annealing pre-phase runs
until a design is in the brief's category (:func:`in_category`). The best design is
the feasible one with the lowest objective among all simulated (the lowest penalized objective when
none is feasible). Every candidate runs at the initial shape's planned step positions
(``EvaluationSettings.hold_steps``): the derivatives are taken at fixed positions, and the default
insertion length would move them in jumps.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from simfab.coupling.adjoint import SensitivityRecorder, StressMeasure, smooth_max_weights
from simfab.coupling.profile import SLIDING_REL, analyze_run, rest_bracket
from simfab.design import brief as B
from simfab.design.handles import Handles
from simfab.design.optimize import OptimizationResult, optimize_anneal
from simfab.design.problem import (
    CONTACT_STRAIN_FLOOR,
    QUALITY_REL,
    DesignProblem,
    Evaluation,
    element_quality,
    evaluate,
    initial_evaluation,
    score_figures,
)
from simfab.design.sqp import CheapConstraints, Sample, SQPOptions, trust_region_sqp
from simfab.design.stress import averaging_matrix, quadrature_averaging_matrix
from simfab.errors import ConvergenceError
from simfab.fem.shape_derivative import linear_rest_derivative, von_mises
from simfab.progress import log

#: [contact] lag_tol the gradient method runs frictional insertions with (at most): the adjoint
#: differentiates each step at its converged lag, and at a looser lag the figures jump with the
#: number of lagging iterations (docs/decisions.md, "Design by gradients").
GRADIENT_LAG_TOL = 1e-2
#: Smooth maxima's temperature, relative to the largest magnitude of the series they take the maximum of.
TEMPERATURE_REL = 0.02


def handle_jacobian(handles: Handles) -> np.ndarray:
    """dX/dh (n * d, n_vars): the rest shape's derivative with respect to the design vector (packed
    per active handle as [t_j (d), s_j (d)], :func:`simfab.design.handles.pack`)."""
    X, C, W = handles.rest, handles.centers, handles.weights
    n, d = X.shape
    act = np.flatnonzero(handles.active)
    J = np.zeros((n, d, len(act), 2, d))
    for k, j in enumerate(act):
        for a in range(d):
            J[:, a, k, 0, a] = W[:, j]
            J[:, a, k, 1, a] = W[:, j] * (X[:, a] - C[j, a])
    return J.reshape(n * d, -1)


@dataclass(frozen=True, kw_only=True, eq=False)
class FigureGradients:
    """The brief's figures of one insertion with their gradients with respect to h (n_vars,) each:
    ``values`` {figure: value} (those of :func:`simfab.design.problem.profile_figures`),
    ``gradients`` {figure: (n_vars,) or None (not differentiated)} (with a target profile also
    "force_samples" (K, n_vars), the insertion records' path forces' Jacobian); ``supported``: every
    step's dependence on the ones before is followed (see :mod:`simfab.coupling.adjoint`);
    ``steady_index``: the steady-state index the figures were read at; ``ratio_continued``: the profile
    ejects at an end pose and ``values["coupling_ratio"]`` is :func:`ejecting_ratio` (above 100 %), not the
    profile's 100 %."""

    values: dict
    gradients: dict
    steady_index: int
    supported: bool
    ratio_continued: bool = False


def stress_measure(problem: DesignProblem, cm) -> StressMeasure:
    """The yield constraint's stress (averaged over the brief's radius) on ``cm``'s mesh: per element
    on linear elements, over the quadrature points on P2 (as :func:`simfab.design.problem.profile_figures`
    reads it)."""
    return _stress_measure(cm, problem.brief.stress_radius)


def _stress_measure(cm, radius: float) -> StressMeasure:
    A = quadrature_averaging_matrix(cm.fem, radius) if cm.fem.element_order == 2 else averaging_matrix(cm.fem, radius)
    return StressMeasure(averaging=A, temperature_rel=TEMPERATURE_REL)


def design_recorder(cm, brief: B.DesignBrief) -> "DeferredRecorder":
    """The recorder the gradient method runs ``cm``'s insertion with: pass the initial shape's
    insertion one (``simulate(cm, recorder=...)``) as ``make_problem``'s ``initial_recorder`` and
    the method reuses that insertion instead of simulating the initial shape again."""
    return DeferredRecorder(cm, _stress_measure(cm, brief.stress_radius))


def _smax(values: np.ndarray, grads: np.ndarray) -> np.ndarray:
    """Gradient of the smooth maximum of ``values`` (k,) with per-value gradients (k, p)."""
    scale = float(np.abs(values).max()) if len(values) else 0.0
    return smooth_max_weights(values, TEMPERATURE_REL * scale) @ grads


#: A record whose weight in every figure's smooth maximum is below this gets no sensitivity
#: (:func:`needed_records`): the dropped weights sum to at most (records) x WEIGHT_FLOOR, so the
#: gradient changes by about that fraction (1e-5 on the design scenes' ~40 records; the finite-difference
#: tests ask for 1e-4). At temperature 2 % of the peak that keeps the records within 28 % of it.
WEIGHT_FLOOR = 1e-6


class DeferredRecorder:
    """A run's recorder (``simulate(..., recorder=...)``) that keeps each record's converged state
    and computes the adjoint sensitivities (:class:`simfab.coupling.adjoint.SensitivityRecorder`)
    afterwards, of the records asked for only (:meth:`sensitivities`): the brief's figures read
    a few records each (maxima through softmax weights that vanish away from the peak, the steady
    state, the rest point's bracket), and a record's sensitivity costs an assembly, a factorization
    and its mixed products (about one insertion step). A record whose step depends on its start
    (a pinned rigid motion, friction anchors) brings the record before it (the backward pass
    follows the chain), so the sensitivities are those of recording every record."""

    def __init__(self, cm, stress: StressMeasure | None = None):
        self.cm, self.stress = cm, stress
        self.records: list = []  # (record, converged state without Newton's memo)

    def __call__(self, record, state) -> None:
        self.records.append((record, dataclasses.replace(state, evaluation=None, tangent=None, check=None,
                                                         check_cache={})))

    def stress_values(self) -> np.ndarray:
        """(records,) the stress measure's value max_e (A sigma_vm)_e of every record [Pa]."""
        A = self.stress.averaging
        return np.array([float((A @ von_mises(self.cm.fem, st.x)).max()) for _, st in self.records])

    def sensitivities(self, needed) -> dict:
        """{record index: StepSensitivity} of the records ``needed`` (indices in the run's order,
        insertion then removal) and those their steps depend on."""
        want = set(int(j) for j in needed)
        depends = set()
        for j in range(len(self.records) - 1, 0, -1):  # (descending: a chain pulls in its whole start)
            st = self.records[j][1]
            if st.prev is not None and ((st.pin_basis is not None and st.pin_basis.shape[1] > 0)
                                        or st.friction is not None):
                depends.add(j)
                if j in want:
                    want.add(j - 1)
        order = sorted(want)
        rec = SensitivityRecorder(self.cm, self.stress)
        for j in order:
            rec(*self.records[j])
        # a step that does not depend on its start is exact whether or not the record before it was replayed
        return {j: sn if j in depends else dataclasses.replace(sn, supported=True)
                for j, sn in zip(order, rec.insert + rec.remove)}


def _weights_needed(values: np.ndarray) -> np.ndarray:
    """(k,) bool: the records whose smooth-maximum weight (:func:`_smax`) is at least WEIGHT_FLOOR."""
    v = np.asarray(values, float)
    if not len(v):
        return np.zeros(0, bool)
    scale = float(np.abs(v).max())
    return smooth_max_weights(v, TEMPERATURE_REL * scale) >= WEIGHT_FLOOR


def needed_records(problem: DesignProblem, res, prof, stresses: np.ndarray) -> np.ndarray:
    """(K + R,) bool over the run's insertion and removal records: those :func:`figure_gradients`
    reads a sensitivity of (a weight of at least WEIGHT_FLOOR in a smooth maximum, the steady state,
    the rest point's bracket, every insertion record for a target profile); ``stresses`` (K + R,)
    the stress measure's values [Pa]."""
    K, R = len(res.steps), len(res.removal)
    out = np.zeros(K + R, bool)
    E, F = res.column("energy"), res.column("force")
    out[:K] |= _weights_needed(E)
    i_ss = prof.index_ss
    out[i_ss] = True
    end = K if prof.category == "ejects" else i_ss + 1
    out[:end] |= _weights_needed(-F[:end]) | _weights_needed(F[:end])
    a = rest_bracket(F, i_ss, len(res.model.s_steps) if K > len(res.model.s_steps) else None)
    if a is not None and prof.category != "ejects":
        out[a: a + 2] = True
    v = _ejecting_valley(res, prof)
    if v is not None:  # ejecting_ratio: the end and the peak before the valley
        out[K - 1] = True
        out[: v + 1] |= _weights_needed(E[: v + 1])
    if R:
        Fr = res.column("force", "remove")
        out[K:] |= _weights_needed(Fr)
        slipping = np.array([r.slipping if r.normal_force > 0 else 1.0 for r in res.removal])
        k = np.flatnonzero(slipping >= SLIDING_REL)
        if len(k):  # F_hold: the records up to the onset of sliding
            out[K: K + int(k[0]) + 1] = True
    out |= _weights_needed(stresses)
    if problem.target is not None:
        out[:K] = True
    return out


def figure_gradients(problem: DesignProblem, ev: Evaluation, Jh: np.ndarray) -> FigureGradients:
    """:class:`FigureGradients` of an evaluation run with a :class:`DeferredRecorder` (the
    sensitivities of :func:`needed_records` only) or a :class:`SensitivityRecorder` (every record's)
    (``evaluate(..., recorder=...)``, status "ok", result kept); Jh: :func:`handle_jacobian`."""
    res, rec = ev.result, ev.recorder
    prof = analyze_run(res)
    g, supported = _figure_gradients(problem, res, rec, prof, Jh)
    values = dict(ev.figures)
    continued = _ejecting_valley(res, prof) is not None and g["coupling_ratio"] is not None
    if continued:
        values["coupling_ratio"] = ejecting_ratio(res)
    return FigureGradients(values=values, gradients=g, steady_index=prof.index_ss, supported=supported,
                           ratio_continued=continued)


def _figure_gradients(problem: DesignProblem, res, rec, prof, Jh: np.ndarray) -> tuple:
    """(gradients, supported) of :func:`figure_gradients`."""
    K, R = len(res.steps), len(res.removal)
    fem = res.model.fem
    if isinstance(rec, DeferredRecorder):
        if len(rec.records) != K + R:
            raise ValueError("the recorder does not hold one state per record")
        stresses = rec.stress_values() if rec.stress is not None else np.zeros(K + R)
        try:
            sens = rec.sensitivities(np.flatnonzero(needed_records(problem, res, prof, stresses)))
        except (ConvergenceError, ArithmeticError, np.linalg.LinAlgError, RuntimeError):
            # an equilibrium the adjoint cannot factorize (e.g. a pinned step whose Hessian is not
            # positive definite): the design keeps its values; its gradients are unknown, taken as
            # zero (what the SQP's linearization reads for a figure without a gradient), supported False
            n = Jh.shape[1]
            names = ("E_max", "E_ss", "coupling_ratio", "insertion_force", "removal_force", "hold_force",
                     "grip_force", "von_mises") + (("rms_error_sq",) if problem.target is not None else ())
            out = {**{k: np.zeros(n) for k in names}, "seat_clearance": None}
            if problem.target is not None:
                out["force_samples"] = np.zeros((K, n))
            return out, False
    else:
        if len(rec.insert) != K:
            raise ValueError("the recorder does not hold one sensitivity per insertion record")
        sens = dict(enumerate(rec.insert + rec.remove))
        stresses = np.array([s.stress_value for s in sens.values()])
    zero = np.zeros(Jh.shape[1])

    def pull(j, figure):  # dq/dX on every node -> the linear mesh's vertices (P2: edge nodes at midpoints) -> dq/dh
        sn = sens.get(j)
        if sn is None:  # (a record no figure reads: weight below WEIGHT_FLOOR)
            return zero
        return linear_rest_derivative(fem, np.asarray(getattr(sn, figure), float)).ravel() @ Jh

    dE = np.array([pull(j, "energy") for j in range(K)])
    dF = np.array([pull(j, "force") for j in range(K)])
    dG = np.array([pull(j, "grip") for j in range(K)])
    E, F = res.column("energy"), res.column("force")
    Ey = fem.material.youngs_modulus if fem.material is not None else 3.0 * float(np.mean(fem.mu))
    touched = prof.E_max > 0.5 * Ey * float(np.sum(fem.volume)) * CONTACT_STRAIN_FLOOR**2
    i_ss = prof.index_ss
    g: dict = {}
    g_Emax = _smax(E, dE)
    g["E_max"] = g_Emax
    g["E_ss"] = g_Emax if prof.category == "ejects" else dE[i_ss]
    g["coupling_ratio"] = (100.0 * (g["E_ss"] / prof.E_max - prof.E_ss * g_Emax / prof.E_max**2)
                           if touched else zero)
    v = _ejecting_valley(res, prof)
    if v is not None and touched:  # ejecting_ratio's gradient: 100 (dE_end / E_pk - E_end dE_pk / E_pk^2)
        E_pk = float(E[: v + 1].max())
        g["coupling_ratio"] = 100.0 * (dE[-1] / E_pk - E[-1] * _smax(E[: v + 1], dE[: v + 1]) / E_pk**2)
    end = len(F) if prof.category == "ejects" else i_ss + 1
    g["insertion_force"] = -_smax(-F[:end], dF[:end]) if prof.F_in > 0 else zero
    if R:  # friction: F_rm and F_hold from the removal traversal (simfab.coupling.profile.analyze_run)
        g["removal_force"], g["hold_force"] = removal_gradients(res, prof, np.array([pull(K + j, "force")
                                                                                       for j in range(R)]))
    else:
        g["removal_force"] = _smax(F[:end], dF[:end]) if prof.F_rm > 0 else zero
        g["hold_force"] = g["removal_force"]
    g["grip_force"] = rest_grip_gradient(res, i_ss, dF, dG) if prof.category != "ejects" else dG[i_ss]
    if all(s.stress is not None for s in sens.values()):
        dS = np.array([pull(j, "stress") for j in range(K + R)])
        g["von_mises"] = _smax(stresses, dS)
    else:
        g["von_mises"] = None
    g["seat_clearance"] = None
    if problem.target is not None:
        scale = problem.settings.corrections.get("force_profile", 1.0)
        g["rms_error_sq"] = target_model(problem.target, res.column("s"), scale * F, scale * dF).gradient
        g["force_samples"] = dF  # (K, n_vars): d F_k / dh, the Gauss-Newton model's Jacobian
    return g, all(s.supported for s in sens.values())


def _ejecting_valley(res, prof) -> int | None:
    """The valley index of :func:`ejecting_ratio` when it applies (an ejecting profile at an end pose with
    a peak before its last valley), else None."""
    if prof.category != "ejects" or res.model.end_direction is not None:
        return None
    E = res.column("energy")
    k = len(E) - 1
    while k > 0 and E[k - 1] < E[k]:  # back from the end down the final rise
        k -= 1
    return k if k > 0 and float(E[: k + 1].max()) > E[k] else None


def ejecting_ratio(res) -> float | None:
    """The coupling ratio continued past an ejecting end pose [%]: 100 E_end / E_pk, with E_pk the largest
    energy before the valley the run's final rise starts from; None when the run does not end in a pose
    (a rotation), does not eject, or rises all the way from its start.

    A path that ends in a pose has its steady state there (:func:`simfab.coupling.profile.analyze`); when
    the end pose presses A harder than the snap before it (knocker3d_design's clip squeezing the ring as
    it turns), the end is the energy's maximum and the profile ejects: CR = 100 % for every design
    nearby, its gradient zero, so no linearization of a coupling-ratio bound gives a direction. This
    ratio is the profile's CR = 100 E_end / E_max wherever the end is below the earlier peak (E_max =
    E_pk there, the category tight or loose), and goes on above 100 % with the end's energy, so it is
    continuous across the category change and its gradient (envelope theorem at both records; E_pk a
    smooth maximum, :func:`figure_gradients`) asks for the end pose to press less."""
    if res.model.end_direction is not None:
        return None
    prof = analyze_run(res)
    v = _ejecting_valley(res, prof)
    if v is None:
        return None
    E = res.column("energy")
    E_pk = float(E[: v + 1].max())
    return 100.0 * float(E[-1]) / E_pk if E_pk > 0 else None


def rest_grip_gradient(res, i_ss: int, dF: np.ndarray, dG: np.ndarray) -> np.ndarray:
    """dF_grip/dh (n_vars,) of the grip read at the steady state; dF, dG: (k, n_vars) the records'
    force and grip derivatives at fixed positions.

    The profile reads the grip at the rest point s*, where the force F passes through zero,
    interpolated between the two records a, b = a + 1 that bracket it (F_a > 0 >= F_b;
    :func:`simfab.coupling.profile.rest_bracket`: a = i_ss, or a = i_ss - 1 when both are records of
    the rest search, the steady state the search's last record past the zero crossing). The reading
    G* = G_a + w (G_b - G_a), w = F_a / (F_a - F_b), follows s*(X), F(s*; X) = 0; differentiated with
    the bracket's secant slopes (the implicit function theorem on the linear interpolant):

        dG* = (1 - w) dG_a + w dG_b + (G_b - G_a) dw,    dw = (F_a dF_b - F_b dF_a) / (F_a - F_b)^2

    At a seat (block2d_tight: the ball on the socket's bottom) the force and the grip change by
    ~10^6 N/m over the bracket's micrometres and the terms nearly cancel: the derivative at fixed
    positions alone is off by an order of magnitude or more (the seat is a kink: no derivative is
    exact there; tests/design/test_gradient_method.py). Without such a bracket (a planned record,
    whose position is held; or the rest search's last record with a planned record before it, a
    secant over a whole step: docs/decisions.md): dG at i_ss."""
    F, G = res.column("force"), res.column("grip")
    planned = len(res.model.s_steps)
    a = rest_bracket(F, i_ss, planned if len(F) > planned else None)
    if a is None:
        return dG[i_ss]
    b = a + 1
    w = F[a] / (F[a] - F[b])
    dw = (F[a] * dF[b] - F[b] * dF[a]) / (F[a] - F[b]) ** 2
    return (1 - w) * dG[a] + w * dG[b] + (G[b] - G[a]) * dw


def removal_gradients(res, prof, dF: np.ndarray) -> tuple:
    """(dF_rm/dh, dF_hold/dh) (n_vars,) each of a frictional run's removal figures
    (:func:`simfab.coupling.profile.analyze_run`); dF: (r, n_vars) the removal records' force
    derivatives (the adjoint's backward pass carries each record's dependence on the earlier ones:
    the friction anchors). F_rm = max(0, max F) over the removal records: the smooth maximum's
    gradient. F_hold = max(0, max F over the records before the onset of sliding k, F_at) with
    F_at = F_(k-1) + w (F_k - F_(k-1)) interpolated at the slipping fraction SLIDING_REL
    (:func:`simfab.coupling.profile.hold_force`): the smooth maximum over those values, w held (the
    onset's position between two records is a stick-slip event, not differentiated). A run that
    jams has F_rm = F_hold = 0 (zero gradients); a contact that never slides has F_hold = F_rm."""
    n = dF.shape[1] if dF.ndim == 2 else 0
    zero = np.zeros(n)
    if prof.category == "jams" or not len(dF):
        return zero, zero
    Fr = res.column("force", "remove")
    g_rm = _smax(Fr, dF) if prof.F_rm > 0 else zero
    slipping = np.array([r.slipping if r.normal_force > 0 else 1.0 for r in res.removal])
    k = np.flatnonzero(slipping >= SLIDING_REL)
    if not len(k):
        return g_rm, g_rm
    k = int(k[0])
    at, d_at = float(Fr[k]), dF[k]
    if k > 0 and slipping[k] > slipping[k - 1]:
        w = min(max((SLIDING_REL - slipping[k - 1]) / (slipping[k] - slipping[k - 1]), 0.0), 1.0)
        at, d_at = float(Fr[k - 1] + w * (Fr[k] - Fr[k - 1])), (1 - w) * dF[k - 1] + w * dF[k]
    if prof.F_hold <= 0:
        return g_rm, zero
    return g_rm, _smax(np.r_[Fr[:k], at], np.vstack([dF[:k], d_at[None, :]]))


def modification_gradient(problem: DesignProblem, X: np.ndarray, Jh: np.ndarray) -> np.ndarray:
    """dE_L/dh (n_vars,): E_L = sum_axes v^T M_L v over the boundary displacements v, so dE_L/dX = 2 M_L v."""
    en = problem.energy
    v = np.asarray(X, float)[en.vertices] - en.rest[en.vertices]
    gX = np.zeros_like(np.asarray(X, float))
    gX[en.vertices] = 2.0 * (en.M @ v)
    return gX.ravel() @ Jh


def quality_jacobian(X: np.ndarray, elements: np.ndarray) -> np.ndarray:
    """(m, n * d) d q_e/dX of the signed mean-ratio quality (:func:`simfab.design.problem.element_quality`):
    2D q = 2 sqrt(3) det / l2, 3D q = 12 (det / 2)^(2/3) / l2 (det > 0) with det the edge matrix's
    determinant (d det/dDm = det Dm^-T) and l2 the sum of squared edge lengths."""
    el = np.asarray(elements)
    p = np.asarray(X, float)[el]  # (m, d+1, d)
    m, k, d = p.shape
    D = np.swapaxes(p[:, 1:, :] - p[:, :1, :], 1, 2)
    det = np.linalg.det(D)
    i, j = np.triu_indices(k, 1)
    diff = p[:, i, :] - p[:, j, :]
    l2 = np.sum(diff**2, axis=(1, 2))
    if d == 2:
        q = 2.0 * math.sqrt(3.0) * det / l2
        dq_ddet = 2.0 * math.sqrt(3.0) / l2
    else:
        q = 12.0 * np.cbrt(np.abs(det) / 2.0) ** 2 / l2 * np.sign(det)
        dq_ddet = 4.0 * np.cbrt(np.abs(det) / 2.0) ** -1 / l2
    ddet_dD = det[:, None, None] * np.swapaxes(np.linalg.inv(D), 1, 2)  # (m, d, d): columns = nodes 1..d
    cols = np.swapaxes(ddet_dD, 1, 2)  # (m, d nodes, d comps)
    g = np.concatenate([-cols.sum(axis=1, keepdims=True), cols], axis=1) * dq_ddet[:, None, None]
    dl2 = np.zeros((m, k, d))
    np.add.at(dl2, (slice(None), i), 2.0 * diff)
    np.add.at(dl2, (slice(None), j), -2.0 * diff)
    g -= (q / l2)[:, None, None] * dl2
    rows = np.repeat(np.arange(m), k * d)
    colidx = (el[:, :, None] * d + np.arange(d)).ravel()
    return sp.csr_matrix((g.ravel(), (rows, colidx)), shape=(m, X.size))


@dataclass(kw_only=True)
class _Run:
    """The optimizer's bookkeeping: every design simulated, in order."""

    problem: DesignProblem
    Jh: np.ndarray
    evaluations: list = field(default_factory=list)
    memo: dict = field(default_factory=dict)
    insertions: int = 0
    gradient_evaluations: int = 0
    signatures: list = field(default_factory=list)  # per complete insertion: its discrete features (events)


@dataclass(frozen=True, kw_only=True, eq=False)
class _Evaluated:
    """One simulated design: the evaluation, its :class:`FigureGradients` (None unless complete) and
    (target matching) the records' force derivatives dF_k/dh (k, n_vars) at fixed positions."""

    ev: Evaluation
    fg: FigureGradients | None
    force_jacobian: np.ndarray | None = None


def _key(h: np.ndarray) -> np.ndarray:
    """A design's memo key (z -> h round trips differ in the last bits)."""
    return np.round(np.asarray(h, float), 12)


def _evaluate(run: _Run, h: np.ndarray) -> _Evaluated:
    """Design h simulated with its sensitivities, memoized (a design is never simulated twice)."""
    key = _key(h).tobytes()
    out = run.memo.get(key)
    if out is not None:
        return out
    problem = run.problem
    if (problem.initial_recorder is not None and problem.initial is not None and not problem.settings.refined
            and np.array_equal(h, problem.handles.identity())):
        # the initial shape's insertion, run before the optimization with its recorder (the same run:
        # hold_steps is the initial shape's own steps); scored with this problem's settings
        ev = initial_evaluation(problem)
        ev.recorder = problem.initial_recorder
    else:
        ev = evaluate(problem, h, keep_result=True,
                      recorder=lambda cm: DeferredRecorder(cm, stress_measure(problem, cm)))
    if ev.sim_seconds > 0:
        run.insertions += 1
    fg, dF = None, None
    if ev.status == "ok":
        fg = figure_gradients(problem, ev, run.Jh)
        run.gradient_evaluations += 1
        if problem.target is not None:
            dF = fg.gradients["force_samples"]
    ev.recorder = None  # (memory: the recorder's states; the sensitivities are read into fg)
    if ev.status == "ok":
        r = ev.result
        planned = len(r.model.s_steps)
        run.signatures.append({"steady_state_index": fg.steady_index, "category": ev.figures.get("category"),
                               "refinement": tuple(r.refined_facets), "kappa": max(st.kappa for st in r.steps),
                               "steps": len(r.steps), "rest_positions": tuple(st.s for st in r.steps[planned:])})
    run.evaluations.append(ev)
    out = run.memo[key] = _Evaluated(ev=ev, fg=fg, force_jacobian=dF)
    return out


def nonsmooth_events(signatures: list) -> dict:
    """How often consecutive simulated designs differ in a discrete feature the gradient does not see:
    {feature: count} over ``pairs`` consecutive pairs (steady-state index, category, the set of refined
    facets, the final barrier stiffness kappa, the number of records and the positions of those past
    the planned steps: the rest search's)."""
    out = {k: 0 for k in ("steady_state_index", "category", "refinement", "kappa", "steps", "rest_positions")}
    for a, b in zip(signatures, signatures[1:]):
        for k in out:
            out[k] += int(a[k] != b[k])
    out["pairs"] = max(len(signatures) - 1, 0)
    return out


#: Constraints without a gradient: the SQP would see them as flat (the seat clearance turns positive as
#: a grip is relaxed: a flat constraint stalls a line search); every simulated design is still checked
#: against them (the best design is a feasible one). A start that touches nothing linearizes the
#: clearance through :func:`gap_gradient` instead.
NOT_DIFFERENTIATED = ("seat_clearance",)


#: A coupling-ratio upper bound below this [%] (the loose brief's KAPPA_LOOSE) is linearized in
#: sqrt(CR) (:class:`ConstraintRow`).
ROOT_BELOW = 1.0


@dataclass(frozen=True, kw_only=True)
class ConstraintRow:
    """One finite bound the SQP linearizes: c = sign (v - bound) / scale >= 0 with v = value * correction,
    or with ``root`` c = sign (sqrt(v) - sqrt(bound)) / sqrt(scale).

    The root is the smooth surrogate of a category bound: a loose grip asks CR = 100 E_ss / E_max <=
    1e-3 %, and E_ss vanishes quadratically as the seat's overlap closes (the barrier and the elastic
    energy are quadratic in it), so dCR/dh -> 0 on the way and each linearization asks for a step that
    is too long by a growing factor; sqrt(CR) is about linear in the overlap."""

    name: str
    sign: float
    bound: float
    scale: float
    root: bool = False

    def value(self, v: float) -> float:
        if self.root:
            return self.sign * (math.sqrt(max(v, 0.0)) - math.sqrt(self.bound)) / math.sqrt(self.scale)
        return self.sign * (v - self.bound) / self.scale

    def gradient(self, v: float, g: np.ndarray) -> np.ndarray:
        """dc/dh from dv/dh ``g``."""
        if self.root:
            return self.sign * g / (2.0 * math.sqrt(v * self.scale)) if v > 0 else np.zeros_like(g)
        return self.sign * g / self.scale


def constraint_rows(problem: DesignProblem) -> list:
    """[:class:`ConstraintRow`]: one row per finite bound (a force's lower bound 0 always holds)."""
    rows = []
    for name, (lo, hi) in problem.limits.items():
        if name in NOT_DIFFERENTIATED:  # checked on every design (the best is a feasible one), not linearized
            continue
        lo, hi = B.aimed_bounds(name, lo, hi, problem.settings.margin)
        scale = B.SCALES[name]
        if math.isfinite(lo) and not (name != "coupling_ratio" and lo <= 0):  # a force >= 0 always holds
            rows.append(ConstraintRow(name=name, sign=1.0, bound=lo, scale=scale))
        if math.isfinite(hi):
            rows.append(ConstraintRow(name=name, sign=-1.0, bound=hi, scale=scale,
                                      root=name == "coupling_ratio" and hi < ROOT_BELOW))
    return rows


#: Annealing iterations at most of the pre-phase that runs when the start gives the SQP no direction.
PRE_PHASE_ITERATIONS = 60


def flat_start(rows: list, fg: FigureGradients, corrections: dict) -> bool:
    """The start gives the SQP no direction: some constraint row is violated and every violated row's
    gradient is zero or missing (a part that does not touch the object: no figure depends on its shape),
    or a coupling-ratio row is violated while the profile ejects (no dip after its peak: CR = 100 %
    for every shape nearby, its gradient zero, and no linearization of that row can be satisfied)
    and the ratio could not be continued past the category (:func:`ejecting_ratio`: a path that ends in
    a pose, pressing harder than the snap before it, as knocker3d_design's clip squeezes the ring)."""
    violated = [r for r in rows if r.value(fg.values[r.name] * corrections.get(r.name, 1.0)) < 0]
    flat = all(fg.gradients.get(r.name) is None or not np.any(fg.gradients[r.name]) for r in violated)
    ejects = (fg.values.get("category") == "ejects" and not fg.ratio_continued
              and any(r.name == "coupling_ratio" for r in violated))
    return bool(violated) and (flat or ejects)


def lost_grip(category: str, tight: bool, reached: dict) -> bool:
    """A design the SQP counts as failed: one that touches nothing once a design touched (``reached``
    ["contact"]), or, for a tight brief, one whose category is not tight once a tight one was reached.
    Such a design's figures have no gradient towards the brief (a grip of 0 at a rest point that
    touches nothing), so a step there ends the descent; its violation alone (the l1 merit) may still
    look like progress when the step relieved another constraint (a stress bound traded for the grip)."""
    if category == "none" and reached["contact"]:
        return True
    return tight and category != "tight" and reached["tight"]


def gap_gradient(res, index: int, Jh: np.ndarray, temperature_rel: float = 0.1) -> np.ndarray | None:
    """d(seat clearance)/dh (n_vars,) of an insertion whose part touches nothing (category "none"),
    at record ``index``; None when no boundary vertex is within the field's kernel of O.

    The clearance is min_i d(y_i) - d_hat over A's boundary vertices y_i, d = -psi
    (:func:`simfab.design.problem.seat_clearance`). A part that touches nothing is undeformed: every
    free vertex sits at its rest position, y_i = X_i, so dd_i/dX_i = -grad psi(y_i). The minimum's
    gradient is that of a soft minimum over the near vertices at temperature ``temperature_rel`` d_hat:
    a part shaped after O has many vertices within a fraction of d_hat of the nearest (paddleside2d: 39
    within d_hat / 10), and the soft minimum closes the gap over all of them rather than at one
    (-> the exact minimum's one-sided derivative as the temperature -> 0)."""
    cm = res.model
    r = res.steps[index]
    bv = np.asarray(cm.fem.boundary_vertices)
    ev = cm.field.evaluate(np.asarray(r.x)[bv], cm.pose(r.s), hessian=False)
    near = np.asarray(ev.near, bool)
    if not near.any():
        return None
    d = -np.asarray(ev.psi, float)[near]
    w = np.exp(-(d - d.min()) / (temperature_rel * float(np.max(cm.dhat))))
    gX = np.zeros(np.asarray(r.x).shape)
    gX[bv[near]] = -(w / w.sum())[:, None] * np.asarray(ev.grad, float)[near]
    return linear_rest_derivative(cm.fem, gX).ravel() @ Jh  # (P2: edge nodes chained to the corners)


def in_contact(ev: Evaluation) -> bool:
    """A complete evaluation whose part touched the object (category other than "none")."""
    return ev.status == "ok" and ev.figures.get("category") not in (None, "none")


def in_category(ev: Evaluation) -> bool:
    """In contact and within the brief's coupling-ratio bounds (its category: tight, loose), the
    pre-phase's goal: a design that merely grazes the object (a grip of millinewtons, in the
    barrier's range only) has gradients too small for a linearization of a newton-sized bound."""
    return in_contact(ev) and all(c.satisfied for c in ev.constraints if c.name == "coupling_ratio")


#: Trust-region SQP iterations at most (one insertion each), when the brief's iterations are more.
MAX_ITERATIONS = 30
#: The SQP's initial trust-region radius, in z (a fraction of each design variable's range).
RADIUS = 0.05
#: ... when it starts from a given design (a correction round's: an optimized design, near the kinks of
#: its active constraints, where a step of RADIUS loses the grip).
RADIUS_FROM_DESIGN = 0.01
#: The constraints are aimed this far inside their bounds, relative to the bound (at least AIM_ABS in
#: their SCALES units: 1 mN, 1 kPa, 0.001 %), a design the SQP counts as feasible (each aimed row violated by
#: at most its aim) meets the brief, and a step whose linearization lands on
#: the bound does not end a hair outside it (the figures are piecewise smooth: a correction step of a few
#: micrometres then meets their kinks).
AIM_REL = 1e-2
AIM_ABS = 1e-3
#: The element-quality bound the subproblems impose: this factor above QUALITY_REL (round-off off the
#: rejection threshold).
QUALITY_AIM = 1.001
#: The SQP stops when its trust-region radius falls below this (in z: 1e-4 of a translation's range
#: is ~ 1e-5 of the part's size).
MIN_RADIUS = 1e-4
#: Stop when no step predicts a reduction of the objective above this fraction of it.
RTOL = 1e-2
#: Target matching: restarts of the SQP from its best design at its initial radius after its trust region
#: collapsed or its trials kept failing (the next one only while a restart lowers the objective by more than RTOL).
RESTARTS = 2


def modification_hessian(problem: DesignProblem, Jh: np.ndarray) -> np.ndarray:
    """d2E_L/dh2 (n_vars, n_vars), constant: E_L = sum_axes v_a^T M_L v_a over the boundary vertices'
    displacements v_a (linear in h), so the Hessian is 2 sum_a J_a^T M_L J_a with J_a the rows of dX/dh
    of the boundary vertices' axis a."""
    en = problem.energy
    d = problem.handles.dim
    out = np.zeros((Jh.shape[1], Jh.shape[1]))
    for a in range(d):
        Ja = Jh[en.vertices * d + a]
        out += 2.0 * Ja.T @ (en.M @ Ja)
    return out


@dataclass(frozen=True, kw_only=True, eq=False)
class TargetModel:
    """The target-profile error of one insertion as the SQP models it: ``value`` rms^2 [N^2],
    ``gradient`` (n,) its derivative with respect to the design variables and ``hessian`` (n, n) a
    Gauss-Newton model Hessian (symmetric positive semi-definite), in the units of the force samples'
    Jacobian the model was built with."""

    value: float
    gradient: np.ndarray
    hessian: np.ndarray


#: The rest point's step in the target model's second differences, relative to the target's length:
#: the curvature of rms^2 in the run's end over the distances a design step moves it (tens of
#: micrometres), not at the target's sample kinks.
REST_STEP_REL = 2e-3


def target_model(target, s: np.ndarray, force: np.ndarray, dF: np.ndarray) -> TargetModel:
    """:class:`TargetModel` of the target-profile error rms^2 (:meth:`simfab.design.brief.TargetProfile.
    rms_error`) of a run with records at s (k,) [m], forces (k,) [N] and the forces' Jacobian dF
    (k, n) at fixed positions.

    rms^2 is a function R(y) of y = (F_0 .. F_a, s*): the records' forces up to the run's end and the
    end itself, the rest point s* = s_a + w (s_b - s_a), w = F_a / (F_a - F_b), when the last two records
    bracket a zero crossing (:func:`simfab.design.brief.run_to_rest`; else y = F and R is a quadratic).
    The rest point moves with the design: ds*/dh = (s_b - s_a) (F_a dF_b - F_b dF_a) / (F_a - F_b)^2 (the
    implicit derivative of F(s*) = 0 over the bracket's secant, as for the grip,
    :func:`rest_grip_gradient`), so dy/dh = J_y stacks dF_k/dh and ds*/dh. R is a quadratic in the forces
    at a fixed end (an integral of squared piecewise-linear differences): its derivatives in them are
    differences with a 1 N step, exact up to round-off; in s* it is piecewise smooth (the target's
    samples), differentiated by central differences with a step of 1e-6 L and curved over REST_STEP_REL L.
    Gauss-Newton: value R, gradient J_y^T dR/dy, Hessian J_y^T Q J_y with Q the second differences of R
    in y projected on the positive semi-definite cone (negative eigenvalues, from the rest point's
    terms, set to 0)."""
    s, F = np.asarray(s, float), np.asarray(force, float)
    dF = np.asarray(dF, float)
    k = len(F)
    L = float(target.s[-1] - target.s[0])
    rested = k >= 2 and F[-2] > 0.0 >= F[-1]
    if rested:
        a, b = k - 2, k - 1
        w = F[a] / (F[a] - F[b])
        se = s[a] + w * (s[b] - s[a])
        dse = (s[b] - s[a]) * (F[a] * dF[b] - F[b] * dF[a]) / (F[a] - F[b]) ** 2
        y0, Jy = np.r_[F[:b], se], np.vstack([dF[:b], dse[None, :]])

        def R(y):
            return target.rms_error(np.r_[s[:b], y[-1]], np.r_[y[:-1], 0.0]) ** 2

        room = 0.5 * (se - s[a])  # (the end stays past its last record)
        hg = np.r_[np.ones(b), min(1e-6 * L, room)]
        hh = np.r_[np.ones(b), min(REST_STEP_REL * L, room)]
    else:
        y0, Jy = F, dF

        def R(y):
            return target.rms_error(s, y) ** 2

        hg = hh = np.ones(k)
    n = len(y0)
    # only the samples inside the target's range (and the end) enter R
    first = float(target.s[0]) - (s[1] - s[0] if k > 1 else 0.0)
    where = np.r_[s[:-1], np.inf] if rested else s  # (the entries of y: records, then the end)
    live = np.flatnonzero(where >= first)
    r0 = R(y0)
    gy = np.zeros(n)
    for i in live:
        e = np.zeros(n)
        e[i] = hg[i]
        gy[i] = (R(y0 + e) - R(y0 - e)) / (2.0 * hg[i])
    r1 = {}
    for i in live:
        e = np.zeros(n)
        e[i] = hh[i]
        r1[i] = R(y0 + e)
    Qs = np.zeros((n, n))  # the Hessian in y / hh (unit steps): comparable entries for the projection
    for p, i in enumerate(live):
        for j in live[p:]:
            e = np.zeros(n)
            e[i] += hh[i]
            e[j] += hh[j]
            Qs[i, j] = Qs[j, i] = R(y0 + e) - r1[i] - r1[j] + r0
    lam, V = np.linalg.eigh(Qs)
    Qs = (V * np.maximum(lam, 0.0)) @ V.T
    Js = Jy / hh[:, None]
    return TargetModel(value=r0, gradient=gy @ Jy, hessian=Js.T @ Qs @ Js)


def optimize_gradient(problem: DesignProblem, *, iterations: int | None = None, seed: int = 0, quiet: bool = True,
                      callback=None, start=None, resume=None) -> OptimizationResult:
    """A trust-region SQP on the brief (:func:`simfab.design.sqp.trust_region_sqp`; see the module
    docstring): one insertion per iteration; returns an :class:`OptimizationResult` whose ``simulations``
    counts every insertion (the pre-phase's and the final run as ``couple simulate`` runs the design
    included) and ``gradient_evaluations`` those that gave gradients. ``seed`` seeds the annealing
    pre-phase, which runs only when the start gives no direction (:func:`flat_start`: at most
    PRE_PHASE_ITERATIONS iterations, until a design is in the brief's category; the SQP starts from
    the best one); otherwise the method is deterministic. ``iterations`` caps the SQP's iterations
    (default: the brief's, at most MAX_ITERATIONS). ``start``: the design to start from (a correction
    round's: the trust region then starts at RADIUS_FROM_DESIGN, and a brief's round stops at its first
    design that meets the corrected brief, :class:`simfab.design.sqp.SQPOptions` ``stop_when_feasible``:
    the factors were measured at the start and move with the design by more than the objective's
    further steps would gain; the mesh check decides), default the initial shape. ``resume``: a
    previous result's ``resume`` (its best design's simulation with gradients); when ``start`` is that
    design and the problem a brief, the run starts from it re-scored (the round's corrections change
    the scoring, not the simulation: same held steps and seeded refinement) instead of simulating it
    again. Raises ConvergenceError when the initial shape cannot be simulated."""
    t0 = time.perf_counter()
    problem = problem.with_settings(hold_steps=True)  # derivatives are at fixed step positions
    H = problem.handles
    Jh = handle_jacobian(H)
    run = _Run(problem=problem, Jh=Jh)
    if problem.initial is not None:  # the placement's run of the initial shape: scored, not simulated again
        initial = initial_evaluation(problem)
    else:
        initial = _evaluate(run, H.identity()).ev  # (with its sensitivities: the SQP starts there)
    if initial.status != "ok":
        raise ConvergenceError(f"the initial shape cannot be simulated ({initial.reason}); nothing to optimize from")
    if not problem.settings.refined and initial.result.refined_facets:
        run.problem = problem = problem.with_settings(refined=tuple(int(i) for i in initial.result.refined_facets))
    lo, hi = problem.lower, problem.upper
    span = hi - lo
    rows = constraint_rows(problem)
    corr = problem.settings.corrections
    if (resume is not None and start is not None and problem.target is None and resume.fg is not None
            and np.array_equal(_key(resume.ev.h), _key(start)) and resume.ev.figures.get("category") != "none"):
        # a round from the previous run's best: its simulation, scored with this round's factors
        ev = dataclasses.replace(resume.ev, sim_seconds=0.0)  # (simulated by that run)
        score_figures(problem, ev, ev.result)
        run.memo[_key(start).tobytes()] = dataclasses.replace(resume, ev=ev)
        run.evaluations.append(ev)
    pre = None
    e0 = _evaluate(run, H.identity() if start is None else np.asarray(start, float))
    if e0.fg is not None and flat_start(rows, e0.fg, corr):
        touches_nothing = e0.ev.figures.get("category") == "none"
        g_gap = (gap_gradient(e0.ev.result, e0.fg.steady_index, Jh)
                 if touches_nothing and "seat_clearance" in problem.limits else None)
        if g_gap is not None and np.any(g_gap):
            # no figure depends on the shape, but the gap to O does: close it first (the clearance bound, linearized)
            log(f"couple optimize: {problem.base.name}: the start touches nothing (gap "
                f"{e0.ev.figures['seat_clearance'] * 1e6:.3g} um); the SQP closes the gap first", quiet=quiet)
            rows.append(ConstraintRow(name="seat_clearance", sign=-1.0, bound=0.0, scale=B.SCALES["seat_clearance"]))
        else:
            # no direction at all: anneal (seeded) until a design is in the brief's category, then descend
            why = "no contact" if touches_nothing else "the profile ejects"
            log(f"couple optimize: {problem.base.name}: the start gives no gradient ({why}); annealing "
                f"pre-phase until a design is in the brief's category, at most {PRE_PHASE_ITERATIONS} iterations",
                quiet=quiet)
            pre = optimize_anneal(problem, iterations=PRE_PHASE_ITERATIONS, seed=seed, quiet=True,
                           start=None if start is None else np.asarray(start, float), until=in_category)
            run.insertions += pre.simulations + pre.stopped_simulations + pre.speculative
            if in_contact(pre.best):
                start = pre.best.h
    target = problem.target is not None
    el = problem.mesh.elements
    q0 = problem.q0
    B_EL = None if target else span[:, None] * modification_hessian(problem, Jh) * span[None, :]
    force_scale = corr.get("force_profile", 1.0)

    def h_of(z):
        return lo + np.clip(z, 0.0, 1.0) * span

    tight = problem.brief.grip == "tight"
    reached = {"contact": False, "tight": False}

    def sample(z) -> Sample:
        h = h_of(z)
        e = _evaluate(run, h)
        if e.fg is None or (target and e.ev.rms_error is None):
            return Sample(ok=False)
        category = e.ev.figures.get("category")
        if lost_grip(category, tight, reached):
            return Sample(ok=False)
        reached["contact"] |= category != "none"
        reached["tight"] |= category == "tight"
        fg = e.fg
        if target:
            tm = target_model(problem.target, e.ev.result.column("s"), force_scale * e.ev.result.column("force"),
                              force_scale * e.force_jacobian * span[None, :])
            f, g, Bz = tm.value, tm.gradient, tm.hessian  # (Gauss-Newton: the samples' own curvature left out)
        else:
            X = H.apply(h)
            f, g, Bz = problem.energy(X), modification_gradient(problem, X, Jh) * span, B_EL
        c = np.array([r.value(fg.values[r.name] * corr.get(r.name, 1.0)) for r in rows]) - aim
        A = np.zeros((len(rows), len(z)))
        for i, r in enumerate(rows):
            gr = fg.gradients.get(r.name)
            if r.name == "seat_clearance":  # (a flat start's gap; 0 once in contact, where it holds)
                gr = (gap_gradient(e.ev.result, fg.steady_index, Jh) if e.ev.figures.get("category") == "none"
                      else None)
            if gr is not None:
                k = corr.get(r.name, 1.0)
                A[i] = r.gradient(fg.values[r.name] * k, gr * k) * span
        return Sample(ok=True, f=f, g=g, B=Bz, c=c, A=A)

    aim = np.array([max(AIM_ABS, AIM_REL * abs(r.value(0.0))) for r in rows])
    quality = CheapConstraints(
        fun=lambda z: np.asarray(element_quality(H.apply(h_of(z)), el)) / q0 - QUALITY_AIM * QUALITY_REL,
        jac=lambda z: np.asarray(quality_jacobian(H.apply(h_of(z)), el) @ Jh) / q0[:, None] * span[None, :])
    z0 = np.clip((H.identity() if start is None else np.asarray(start, float)) - lo, 0, None) / span
    cap = min(MAX_ITERATIONS, problem.brief.iterations) if iterations is None else int(iterations)
    history: list = []

    def on_step(st):
        ev = _evaluate(run, h_of(st.z)).ev  # (memoized: the trial's evaluation)
        history.append((ev, st.accepted))
        if callback is not None:
            callback({"k": len(history), "info": ev})
        log(f"couple optimize: {problem.base.name}: SQP iteration {len(history)}: objective {ev.objective:.4g}, "
            f"ratio {st.rho:.3g} (predicted {st.predicted:.3g}), radius {st.radius:.3g}, "
            f"{'accepted' if st.accepted else 'rejected'}, insertions {run.insertions}", quiet=quiet)

    opts = SQPOptions(radius=RADIUS if start is None or pre is not None else RADIUS_FROM_DESIGN,
                      max_evaluations=cap + 1, rtol=RTOL, ctol=aim, min_radius=MIN_RADIUS,
                      stop_when_feasible=start is not None and not target)
    if not sample(z0).ok:  # (memoized: the SQP's first evaluation)
        why = _evaluate(run, h_of(z0)).ev.reason or "status " + _evaluate(run, h_of(z0)).ev.status
        raise ConvergenceError(f"couple optimize: {problem.base.name}: the gradient method's start cannot be "
                               f"simulated with its sensitivities ({why}); --method anneal does not need them")
    res = trust_region_sqp(sample, z0, options=opts, cheap=quality, callback=on_step)
    iterations = len(res.steps)
    for _ in range(RESTARTS if target else 0):
        # target matching: a trust region that collapsed at a kink of the rest point starts again from the
        # best design at the initial radius (its start memoized: no insertion); again while that gains
        if res.converged or iterations >= cap:
            break
        log(f"couple optimize: {problem.base.name}: SQP: {res.message}; restart from the best design at radius "
            f"{opts.radius:g}", quiet=quiet)
        before = res.sample.f
        res = trust_region_sqp(sample, res.z, options=dataclasses.replace(opts, max_evaluations=cap + 1 - iterations),
                               cheap=quality, callback=on_step)
        iterations += len(res.steps)
        if res.sample.f > (1.0 - RTOL) * before:
            break
    if not res.converged and iterations >= cap:
        res.message = f"iteration cap ({cap}) reached"
    log(f"couple optimize: {problem.base.name}: SQP: {res.message} ({iterations} iterations, "
        f"{run.insertions} insertions)", quiet=quiet)
    ok = [ev for ev in run.evaluations if ev.status == "ok"]
    best = min(ok, key=lambda e: (not e.feasible, e.objective))
    resume_next = run.memo.get(_key(best.h).tobytes())
    if best.status == "ok" and best is not initial:  # as `couple simulate` runs it (own steps, no seeded refinement)
        plain = evaluate(problem.with_settings(refined=(), hold_steps=False), best.h, keep_result=True)
        run.insertions += int(plain.sim_seconds > 0)
        if plain.status == "ok":
            best = plain
    for ev in run.evaluations:
        if ev is not best and ev is not initial:
            ev.result = None
    rejected: dict = {}
    for ev in run.evaluations:
        if ev.status == "rejected":
            key = ev.reason.split(":")[0]
            rejected[key] = rejected.get(key, 0) + 1
    hist, current, best_so_far = [], initial.objective, initial.objective
    for k, (ev, acc) in enumerate(history):
        current = ev.objective if acc else current
        best_so_far = min(best_so_far, ev.objective)
        hist.append({"k": k, "accepted": acc, "current": current, "best": best_so_far, "temperature": math.nan,
                     "sigma": math.nan, "value": ev.objective, "evaluation": ev})
    message = f"SQP: {res.message} ({iterations} iterations)"
    if pre is not None:
        message = (f"annealing pre-phase ({pre.iterations} iterations, "
                   f"{pre.simulations + pre.stopped_simulations + pre.speculative} insertions, "
                   f"{'a design in the category' if in_category(pre.best) else 'none in the category'}); "
                   f"{message}")
    if problem.initial is None:  # the initial shape's run, for correction rounds started from this result
        problem = dataclasses.replace(problem, initial=initial.result)
    return OptimizationResult(problem=problem, initial=initial, best=best, history=hist,
                        accepted=[(k, ev.rest, ev.objective) for k, (ev, acc) in enumerate(history) if acc],
                        simulations=run.insertions, stopped_simulations=0, rejected=rejected,
                        seconds=time.perf_counter() - t0, sim_seconds=sum(ev.sim_seconds for ev in run.evaluations),
                        iterations=iterations, stopped_early=bool(res.converged), method="gradient",
                        gradient_evaluations=run.gradient_evaluations, message=message,
                        events=nonsmooth_events(run.signatures), resume=resume_next)
