"""Figure gradients: the brief's figures' derivatives with respect to the handle parameters h.

One insertion of the design X(h) records, per step, the adjoint sensitivities of the elastic energy
E_k, the insertion force F_k, the grip G_k and the averaged von Mises maximum sigma_k to the rest
positions (:mod:`simfab.coupling.adjoint`). X = M_LBS T(h) is linear in h (:mod:`simfab.design.handles`),
so dq/dh = (dX/dh)^T dq/dX with

    dX_i/dt_j = w_ij I,    dX_i/ds_j = w_ij diag(X_i - c_j)          (per axis; inactive handles fixed)

Maxima over the steps (E_max, F_in, F_rm, the stress) are differentiated as the log-sum-exp
T log sum_k exp(q_k / T), T = TEMPERATURE_REL times the series' largest magnitude (the reported value
is the exact maximum); E_ss at the held steady-state index; the coupling ratio by the quotient rule;
the grip at the rest point by implicit differentiation (:func:`rest_grip_gradient`); E_L and the
element quality analytically; with friction F_rm and F_hold from the removal's records
(:func:`removal_gradients`). On P2 elements every node's derivative is chained to the linear mesh's
vertices first. The seat clearance is not differentiated, but for a part that touches nothing
(:func:`gap_gradient`). The optimizer that uses them is :mod:`simfab.design.gradient`; the full
derivation is in docs/design-gradients.md.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from simfab.coupling.adjoint import SensitivityRecorder, StressMeasure, smooth_max_weights
from simfab.coupling.profile import SLIDING_REL, analyze_run, rest_bracket
from simfab.design import brief as B
from simfab.design.handles import Handles
from simfab.design.problem import DesignEvaluation, DesignProblem, linear_mesh
from simfab.design.stress import averaging_matrix, quadrature_averaging_matrix
from simfab.errors import ConvergenceError
from simfab.fem.model import mean_edge_length_gradient
from simfab.fem.shape_derivative import linear_rest_derivative, point_von_mises

__all__ = ["DeferredRecorder", "FigureGradients", "TEMPERATURE_REL", "TargetModel", "WEIGHT_FLOOR", "design_recorder",
           "ejecting_ratio", "figure_gradients", "gap_gradient", "handle_jacobian", "modification_gradient",
           "needed_records", "quality_jacobian", "removal_gradients", "rest_grip_gradient", "stress_measure",
           "target_model"]


#: Smooth maxima's temperature, relative to the largest magnitude of the series they take the maximum of.
TEMPERATURE_REL = 0.02


def handle_jacobian(handles: Handles) -> np.ndarray:
    """The rest shape's derivative with respect to the design vector.

    Args:
        handles: the design's handles (packed per active handle as [t_j (d), s_j (d)],
            :func:`simfab.design.handles.pack`).

    Returns:
        dX/dh (n * d, n_vars).
    """
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
    """The brief's figures of one insertion with their gradients with respect to h.

    Args:
        values: {figure: value} (those of :func:`simfab.design.problem.profile_figures`).
        gradients: {figure: (n_vars,) or None (not differentiated)}; with a target profile also
            "force_samples" (K, n_vars), the insertion records' path forces' Jacobian.
        steady_index: the steady-state index the figures were read at.
        supported: every step's dependence on the ones before is followed.
        ratio_continued: the profile ejects at an end pose and ``values["coupling_ratio"]`` is
            :func:`ejecting_ratio` (above 100 %), not the profile's 100 %.
    """

    values: dict
    gradients: dict
    steady_index: int
    supported: bool
    ratio_continued: bool = False


def stress_measure(problem: DesignProblem, cm) -> StressMeasure:
    """The yield constraint's stress (averaged over the brief's radius) on a model's mesh: per element on
    linear elements, over the quadrature points on P2 (as :func:`simfab.design.problem.profile_figures` reads it).

    Args:
        problem: the design problem (its brief's stress radius).
        cm: the coupling model.

    Returns:
        The :class:`~simfab.coupling.adjoint.StressMeasure`.
    """
    return _stress_measure(cm, problem.brief.stress_radius)


def _stress_measure(cm, radius: float) -> StressMeasure:
    A = quadrature_averaging_matrix(cm.fem, radius) if cm.fem.element_order == 2 else averaging_matrix(cm.fem, radius)
    return StressMeasure(averaging=A, temperature_rel=TEMPERATURE_REL)


def design_recorder(cm, brief: B.DesignConfig) -> "DeferredRecorder":
    """The recorder the gradient method runs a model's insertion with: pass the initial shape's insertion
    one (``simulate_insertion(cm, recorder=...)``) as ``make_problem``'s ``initial_recorder`` and the method
    reuses that insertion instead of simulating the initial shape again.

    Args:
        cm: the coupling model.
        brief: the design brief (its stress radius).

    Returns:
        A :class:`DeferredRecorder`.
    """
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
    """A run's recorder (``simulate_insertion(..., recorder=...)``) that keeps each record's converged state
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
        return np.array([float((A @ point_von_mises(self.cm.fem, st.x)).max()) for _, st in self.records])

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


def figure_gradients(problem: DesignProblem, ev: DesignEvaluation, Jh: np.ndarray) -> FigureGradients:
    """The figure gradients of an evaluated design.

    Args:
        problem: the design problem.
        ev: an evaluation run with a :class:`DeferredRecorder` (the sensitivities of
            :func:`needed_records` only) or a :class:`~simfab.coupling.adjoint.SensitivityRecorder`
            (``evaluate(..., recorder=...)``, status "ok", result kept).
        Jh: :func:`handle_jacobian`.

    Returns:
        The :class:`FigureGradients`.
    """
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
    touched = prof.category != "none"
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
    g["grip_force"] = rest_grip_gradient(res, i_ss, dF, dG) if prof.category not in ("ejects", "none") else dG[i_ss]
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

    At a seat (block2d_tight: the ball on the socket's bottom) the force and the grip change steeply
    over the bracket's micrometres and the terms nearly cancel: the derivative at fixed positions
    alone is far off (the seat is a kink: no derivative is exact there; tests/design/test_gradient_method.py;
    the figures: docs/decisions.md, "Figures out of the code's docstrings"). Without such a bracket (a planned record,
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


def gap_gradient(res, index: int, Jh: np.ndarray, temperature_rel: float = 0.1) -> np.ndarray | None:
    """d(seat clearance)/dh (n_vars,) of an insertion whose part touches nothing (category "none"),
    at record ``index``; None when no boundary vertex is within the field's kernel of O.

    The clearance is min_i d(y_i) - d_hat over A's boundary vertices y_i, d = -psi
    (:func:`simfab.design.problem.seat_clearance`). A part that touches nothing is undeformed: every
    free vertex sits at its rest position, y_i = X_i, so dd_i/dX_i = -grad psi(y_i); d_hat is
    dhat_rel times the linear mesh's mean edge length, whose derivative is subtracted. The minimum's
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
    # d_hat = dhat_rel * (the linear mesh's mean edge length) moves with the design too
    lin = linear_mesh(cm.fem)
    g_dhat = cm.options.dhat_rel * mean_edge_length_gradient(lin.rest, lin.elements)
    return (linear_rest_derivative(cm.fem, gX) - g_dhat).ravel() @ Jh  # (P2: edge nodes chained to the corners)


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
