"""Sensitivities of an insertion step's record to A's rest shape X, by the adjoint method.

A converged step's state x(X) is an equilibrium of W(x; X) = E(x; X) + B(x; X) over the free dofs
(E: Neo-Hookean energy, B = kappa sum_j b(d_j(x), dhat_j): the barrier; both depend on X, E through
the rest edges, B through the per-point activation distances dhat_j, which are fractions of the
rest edge lengths at the point, and in 3D through kappa, proportional to the mean edge length).
The fixed dofs sit at their rest positions, x_fixed = X_fixed. For a figure q(x, X) of the step,
implicit differentiation of grad_free W = 0 gives

    dq/dX = dq/dX|_x - lambda^T d2W/dx dX + [fixed dofs] (dq/dx - H lambda)_fixed,
    H_ff lambda = (dq/dx)_free                                            (one back-substitution)

with H the exact Hessian d2W/dx2 at the converged x (lambda extended by zeros to the fixed dofs).
The mixed term is never formed: ``lambda^T d2W/dx dX`` is the derivative of lambda . grad_x W
with respect to X at fixed x, :func:`simfab.fem.shape_derivative.mixed_product` for E and, for B,
kappa sum_j (db'/d dhat)_j (grad d_j . lambda_j) d dhat_j/dX (+ its kappa part in 3D).

Figures per step (:class:`StepSensitivity`): the elastic energy E (q = E), the insertion force
F = u . sum over the fixed dofs of grad W (the support's reaction along O's translation u: dq/dx =
H v, dq/dX|_x = (d2W/dx dX)^T v with v = u on the fixed dofs) and the grip force
G = |a|, a_d = 1/2 sum_v |grad_v B|_d (dq/dx = H_B w, w_vd = 1/2 sign(grad_v B)_d a_d / G); with a
:class:`StressMeasure` also the averaged von Mises stress's maximum.

One sparse factorization of H_ff per step (CHOLMOD through :class:`simfab.solve.linear.SPDSolver`,
the insertion's solver class, its symbolic analysis reused over a run) and one back-substitution
with a right-hand side per figure (3, or 4 with the stress). The exact
Hessian is used (not Newton's PSD-projected one): at a stable equilibrium H_ff is positive
definite; where it is not, the step is marked ``stable = False`` and solved with SuperLU.

Scope: frictionless contact (mu = 0) and no pinned rigid motions (both make a step depend on the
one before: lagged friction anchors, the pin's anchor at the step's start); a step with either is
marked ``supported = False`` and its derivatives are those at a fixed previous state (the pin
enters as Newton solves with it: Woodbury on the regularized Hessian). Derivatives are at fixed
path positions s_k: the planned steps' positions follow A's farthest point along the path when
``L_max`` is unset (in jumps of 1/2000 of the path, :func:`simfab.coupling.model.
default_insertion_length`), and the rest search places its records anew for every design; neither
is differentiated. Non-smooth events: a constraint point entering or leaving the barrier's range
(b is C2 at d = dhat, so derivatives stay continuous), refinement points added (a new, discrete
constraint set: the profile jumps by the discretization error), kappa doubling (a jump in B's
scale); none is differentiated, the figures' derivatives are those of the branch the run took.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from simfab.contact.barrier import barrier_terms, point_barrier
from simfab.coupling import rigid
from simfab.coupling.layout import EDGE_PAIRS, add_point_blocks, point_dhat, regularize
from simfab.coupling.model import CouplingModel
from simfab.coupling.points import ContactPoints
from simfab.coupling.state import StepState
from simfab.fem import shape_derivative
from simfab.fem.elastic import energy_gradient_hessian
from simfab.solve.linear import NotPositiveDefinite, SPDSolver


@dataclass(frozen=True, kw_only=True, eq=False)
class StepSensitivity:
    """Derivatives of one step's figures with respect to the rest positions X (n, dim).

    s [m], phase: the record's; energy [J/m]: dE/dX; force [N/m]: dF/dX (insertion force,
    :class:`simfab.coupling.record.StepResult` ``force``); grip [N/m]: dG/dX; stress [Pa/m] and
    stress_value [Pa]: the averaged von Mises stress's maximum and its (smoothed) derivative, None
    / NaN without a :class:`StressMeasure`; stable: H_ff was
    positive definite; supported: no friction and no pinned rigid motion at this step."""

    s: float
    phase: str
    energy: np.ndarray
    force: np.ndarray
    grip: np.ndarray
    stress: np.ndarray | None = None
    stress_value: float = float("nan")
    stable: bool = True
    supported: bool = True


def edge_rest_derivative(X: np.ndarray, a: np.ndarray, c: np.ndarray, coef: np.ndarray) -> np.ndarray:
    """sum_e coef_e d|X_a - X_c|/dX (n, dim) over edges (a_e, c_e)."""
    e = X[a] - X[c]
    L = np.linalg.norm(e, axis=1)
    g = (coef / L)[:, None] * e
    out = np.zeros_like(X)
    np.add.at(out, a, g)
    np.add.at(out, c, -g)
    return out


def dhat_jacobian(cm: CouplingModel, pts: ContactPoints) -> sp.csr_matrix:
    """(k, n * dim) d dhat_j/dX of the per-point activation distances of
    :func:`simfab.coupling.layout.point_dhat` (dhat_j = dhat_rel sum_a w_ja h_a, h_a the shortest
    boundary edge at vertex a: its derivative is that edge's, the minimum being a selection)."""
    X = np.asarray(cm.fem.rest, float)
    n, dim = X.shape
    facets = cm.contact_facets
    ia, ic = EDGE_PAIRS[cm.dim]
    e = np.vstack([facets[:, [i, j]] for i, j in zip(ia, ic)])
    L = np.linalg.norm(X[e[:, 0]] - X[e[:, 1]], axis=1)
    ends = e.ravel()
    edge_of = np.repeat(np.arange(len(e)), 2)
    order = np.lexsort((L[edge_of], ends))  # per vertex, its edges by length: the first is the shortest
    first = np.r_[True, ends[order][1:] != ends[order][:-1]]
    shortest = np.full(n, -1)
    shortest[ends[order][first]] = edge_of[order][first]
    k, nv = pts.verts.shape
    rows = np.repeat(np.arange(k), nv)
    v = pts.verts.ravel()
    coef = cm.options.dhat_rel * pts.weights.ravel()
    keep = (coef != 0) & (shortest[v] >= 0)
    rows, v, coef = rows[keep], v[keep], coef[keep]
    ed = e[shortest[v]]
    other = np.where(ed[:, 0] == v, ed[:, 1], ed[:, 0])
    g = (coef / L[shortest[v]])[:, None] * (X[v] - X[other])  # d|X_v - X_u|/dX_v, scaled
    r = np.repeat(rows, 2 * dim)
    c = np.concatenate([v[:, None] * dim + np.arange(dim), other[:, None] * dim + np.arange(dim)], axis=1).ravel()
    val = np.concatenate([g, -g], axis=1).ravel()
    return sp.csr_matrix((val, (r, c)), shape=(k, n * dim))


def mean_edge_gradient(cm: CouplingModel) -> np.ndarray:
    """d h_A/dX (n, dim) of A's mean element edge length (:meth:`MeshModel.mean_edge_length`: over the
    corner mesh, so a P2 model's edge nodes get zero)."""
    X = np.asarray(cm.fem.rest, float)
    el = np.asarray(cm.fem.corner_elements)
    i, j = np.triu_indices(el.shape[1], 1)
    a, c = el[:, i].ravel(), el[:, j].ravel()
    return edge_rest_derivative(X, a, c, np.full(len(a), 1.0 / len(a)))


class _Barrier:
    """The barrier of a converged state: exact per-point terms over the points within range."""

    def __init__(self, cm: CouplingModel, state: StepState):
        x, pts = state.x, state.points
        self.cm, self.pts, self.kappa = cm, pts, float(state.kappa_step)
        self.dhat = point_dhat(cm, pts)
        y = pts.positions(x)
        ev = cm.field.evaluate(y, cm.pose(state.s), hessian=True, hessian_band=float(self.dhat.max()))
        d, gd, hd = -ev.psi, -ev.grad[:, : cm.dim], -ev.hess[:, : cm.dim, : cm.dim]
        self.act = np.flatnonzero(d < self.dhat)
        a = self.act
        self.d, self.gd = d[a], gd[a]
        _, self.gy, self.Hy = point_barrier(d[a], gd[a], hd[a], self.dhat[a], self.kappa, psd=False)
        self.energy = self.kappa * float(barrier_terms(self.d, self.dhat[a])[0].sum()) if len(a) else 0.0
        self.gradient = pts.scatter(self.gy, cm.fem.n_vertices, rows=a)  # (n, dim) dB/dx
        self.dhat_jac = dhat_jacobian(cm, _rows(pts, a))  # (a, n dim)

    def db_ddhat(self) -> tuple[np.ndarray, np.ndarray]:
        """(db/d dhat, db'/d dhat) (a,) at the active points: b = -r^2 log(d/dhat), r = d - dhat."""
        d, dh = self.d, self.dhat[self.act]
        r, log = d - dh, np.log(d / dh)
        return 2.0 * r * log + r * r / dh, 2.0 * log + 2.0 * r / dh + 2.0 * r / d

    def rest_gradient(self, kappa_grad: np.ndarray | None) -> np.ndarray:
        """dB/dX at fixed x (n, dim)."""
        db, _ = self.db_ddhat()
        out = ((self.kappa * db) @ self.dhat_jac).reshape(-1, self.cm.dim)
        if kappa_grad is not None:
            out += self.energy / self.kappa * kappa_grad
        return out

    def mixed_product(self, w: np.ndarray, kappa_grad: np.ndarray | None) -> np.ndarray:
        """d/dX (w . dB/dx) at fixed x (n, dim) for w (n, dim); a stack (b, n, dim) gives (b, n, dim)."""
        _, dbp = self.db_ddhat()
        w = np.asarray(w, float)
        W = w.reshape(-1, *w.shape[-2:])
        wy = np.stack([self.pts.positions(wb)[self.act] for wb in W])  # (b, a, dim)
        coef = self.kappa * dbp * np.einsum("kd,bkd->bk", self.gd, wy)
        out = np.asarray(coef @ self.dhat_jac).reshape(W.shape)
        if kappa_grad is not None:
            out += (np.einsum("bnd,nd->b", W, self.gradient) / self.kappa)[:, None, None] * kappa_grad
        return out.reshape(w.shape)


def _rows(pts: ContactPoints, rows: np.ndarray) -> ContactPoints:
    return ContactPoints(verts=pts.verts[rows], weights=pts.weights[rows], facet=pts.facet[rows])


@dataclass(frozen=True, kw_only=True, eq=False)
class StressMeasure:
    """The stress figure of a step: max_e (A sigma_vm)_e with A (m, m) the row-stochastic averaging
    over a critical distance (:func:`simfab.design.stress.averaging_matrix`, held fixed: its
    dependence on X, through element volumes and which centroids lie within the radius, is not
    differentiated). Its gradient is that of the log-sum-exp T log sum_e exp((A sigma)_e / T) at
    T = ``temperature_rel`` * max (the softmax-weighted element gradients; -> the max's gradient
    where one element dominates); the value reported is the exact maximum."""

    averaging: object
    temperature_rel: float = 0.02


def smooth_max_weights(values: np.ndarray, temperature: float) -> np.ndarray:
    """Softmax weights exp((v_i - max) / T) / sum (k,): the gradient of T log sum_i exp(v_i / T)."""
    v = np.asarray(values, float)
    if not temperature > 0:
        w = (v == v.max()).astype(float)
        return w / w.sum()
    e = np.exp((v - v.max()) / temperature)
    return e / e.sum()


def step_sensitivity(cm: CouplingModel, state: StepState, phase: str = "insert",
                     stress: StressMeasure | None = None, solver: SPDSolver | None = None) -> StepSensitivity:
    """:class:`StepSensitivity` of the converged ``state`` (see the module docstring); with
    ``stress`` also that of the averaged von Mises stress's maximum (:class:`StressMeasure`);
    ``solver``: the sparse solver to factorize with (one per run reuses its symbolic analysis)."""
    solver = SPDSolver() if solver is None else solver
    fem, x = cm.fem, np.asarray(state.x, float)
    n, dim = fem.n_vertices, cm.dim
    bar = _Barrier(cm, state)
    _, gE, HE = energy_gradient_hessian(fem, x, project_psd=False)
    HB = HE.copy()
    HB.data[:] = 0.0
    add_point_blocks(cm, state.points, HB, bar.act, bar.Hy)
    H = HE.copy()  # in HE's fixed pattern (the Hessian slots, regularization and solver maps expect it)
    add_point_blocks(cm, state.points, H, bar.act, bar.Hy)
    kappa_grad = cm.kappa / cm.h * mean_edge_gradient(cm) if dim == 3 else None

    free = cm.free.reshape(n, dim)
    u = cm.direction(state.s)
    v = np.where(free, 0.0, u[None, :])  # F = v . grad W
    gc = bar.gradient
    a = 0.5 * np.abs(gc).sum(axis=0)
    G = float(np.linalg.norm(a))
    wg = 0.5 * np.sign(gc) * (a / G)[None, :] if G > 0 else np.zeros_like(gc)
    # per figure: (dq/dx (n, dim), dq/dX at fixed x (n, dim))
    figures = [(gE.reshape(n, dim), shape_derivative.rest_gradient(fem, x)),
               ((H @ v.ravel()).reshape(n, dim), None),  # direct term: mixed(v), folded into the stack below
               ((HB @ wg.ravel()).reshape(n, dim), None)]  # direct term: the barrier's mixed(wg), likewise
    stress_value = float("nan")
    if stress is not None:
        avg = stress.averaging @ shape_derivative.von_mises(fem, x)
        stress_value = float(avg.max())
        c = stress.averaging.T @ smooth_max_weights(avg, stress.temperature_rel * abs(stress_value))
        figures.append(shape_derivative.von_mises_derivatives(fem, x, c))
    k = len(figures)
    gx = np.stack([f[0] for f in figures])
    idx = np.flatnonzero(cm.free)
    rhs = gx.reshape(k, -1)[:, idx].T
    pinned = state.pin_basis is not None and state.pin_basis.shape[1] > 0
    stable = True
    try:
        if pinned:  # as Newton solved it: Woodbury pin on the regularized Hessian (anchor held fixed)
            Hr = H.copy()
            regularize(cm, Hr)
            pinned_solver = rigid.PinnedSolver(solver, rigid.pin_for(cm, state.pin_basis, rigid.motion_basis(cm)[1],
                                                                     state.x))
            lam_f = np.column_stack([pinned_solver.solve_free(Hr, idx, rhs[:, q]) for q in range(k)])
        else:
            lam_f = solver.solve_free(H, idx, rhs)
    except NotPositiveDefinite:
        stable = False
        lam_f = splu(sp.csc_matrix(H[idx][:, idx])).solve(rhs)
    lam = np.zeros((k, n * dim))
    lam[:, idx] = lam_f.T
    lam = lam.reshape(k, n, dim)
    fixed = ~free
    # dq/dX = direct - mixed(lambda): force's direct term is mixed(v) and grip's the barrier part of
    # mixed(wg), so one stacked mixed product over (lambda_0, lambda_1 - v, lambda_2 (- wg for B), ...)
    We = lam.copy()
    We[1] -= v
    Wb = We.copy()
    Wb[2] -= wg
    mixed_all = shape_derivative.mixed_product(fem, x, We) + bar.mixed_product(Wb, kappa_grad)
    direct = [figures[0][1], np.zeros((n, dim)), np.zeros((n, dim))] + [f[1] for f in figures[3:]]
    out = []
    for q in range(k):
        dq = direct[q] - mixed_all[q]
        resid = gx[q] - (H @ lam[q].ravel()).reshape(n, dim)
        dq[fixed] += resid[fixed]  # the fixed dofs sit at the rest positions: dx_fixed/dX_fixed = I
        out.append(dq)
    supported = state.friction is None and not pinned
    return StepSensitivity(s=float(state.s), phase=phase, energy=out[0], force=out[1], grip=out[2],
                           stress=out[3] if stress is not None else None, stress_value=stress_value, stable=stable,
                           supported=supported)


class SensitivityRecorder:
    """Collects a :class:`StepSensitivity` per kept step of a run: pass as ``simulate(...,
    recorder=...)`` (it receives each kept record with the converged state it was recorded at).
    ``insert`` and ``remove``: the sensitivities of the run's insertion and removal records, in order."""

    def __init__(self, cm: CouplingModel, stress: StressMeasure | None = None):
        self.cm, self.stress = cm, stress
        self.solver = SPDSolver()  # one symbolic analysis for the run's (fixed-pattern) Hessians
        self.insert: list[StepSensitivity] = []
        self.remove: list[StepSensitivity] = []

    def __call__(self, record, state: StepState) -> None:
        sens = step_sensitivity(self.cm, state, record.phase, self.stress, self.solver)
        (self.remove if record.phase == "remove" else self.insert).append(sens)
