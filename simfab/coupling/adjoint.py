"""Sensitivities of an insertion step's record to A's rest shape X, by the adjoint method.

A converged step's state x(X) solves R(x; X, x_prev) = 0 over the free dofs, R = grad_x (E + B)
(+ the friction forces, + the rigid-mode pin's gradient), E the Neo-Hookean energy, B the barrier
(whose activation distances dhat_j follow the rest edge lengths). For a figure q(x, X) of the step

    dq/dX = dq/dX|_x - lambda^T dR/dX + [fixed dofs] (dq/dx - J^T lambda)_fixed
            + (-lambda^T dR/dx_prev) dx_prev/dX,
    (J^T)_ff lambda = (dq/dx)_free,   J = dR/dx                          (one back-substitution)

The mixed term lambda^T dR/dX is never formed (:func:`simfab.fem.shape_derivative.mixed_product`
for E, the barrier's per point). The dependence on the step's start (the rigid-mode pin's anchor,
the friction anchors) is followed by a backward pass (:class:`SensitivityRecorder`). With friction
the converged lag is differentiated as a function of x and X (:class:`_Friction`, SuperLU).

Figures per step (:class:`StepSensitivity`): the elastic energy, the insertion force (the
support's reaction along O's translation), the grip force and, with a :class:`StressMeasure`,
the averaged von Mises maximum. One sparse factorization per step (:class:`simfab.solve.linear.SPDSolver`;
SuperLU for a non-symmetric or unstable J) and one back-substitution per figure. Not differentiated:
the path positions s_k and the non-smooth events (contact onset, refinement, kappa doubling,
stick-slip); the derivatives are those of the branch the run took. The full derivation:
docs/methods.md, "simfab.coupling.adjoint".
"""

from __future__ import annotations

import dataclasses
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
from simfab.fem.model import mean_edge_length_gradient
from simfab.solve.linear import NotPositiveDefinite, SPDSolver


@dataclass(frozen=True, kw_only=True, eq=False)
class StepSensitivity:
    """Derivatives of one step's figures with respect to the rest positions X (n, dim) of every node of
    ``cm.fem`` (P2: corners and edge nodes; :func:`simfab.fem.shape_derivative.linear_rest_derivative`
    chains them to the linear mesh's vertices).

    Args:
        s: the record's path length [m].
        phase: the record's phase ("insert" or "remove").
        energy: dE/dX (n, dim) [J/m].
        force: dF/dX (n, dim) [N/m] of the insertion force (:class:`simfab.coupling.record.StepResult` ``force``).
        grip: dG/dX (n, dim) [N/m].
        stress: the averaged von Mises maximum's (smoothed) derivative [Pa/m], None without a :class:`StressMeasure`.
        stress_value: that maximum [Pa] (NaN without one).
        stable: H_ff was positive definite.
        supported: every dependence of the step is followed (False: solved from an unrecorded state, held
            fixed, or, where steps depend on their start, a later record whose chain back reaches such a step
            above PRUNE_REL).
        friction_lag_held: the friction's normal forces and normals were held at their values
            (``SensitivityRecorder(held_lag=True)``, an approximation).
    """

    s: float
    phase: str
    energy: np.ndarray
    force: np.ndarray
    grip: np.ndarray
    stress: np.ndarray | None = None
    stress_value: float = float("nan")
    stable: bool = True
    supported: bool = True
    friction_lag_held: bool = False


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
        if kappa_grad is not None:  # B = kappa sum b, kappa = (kappa / kappa_0) kappa_0(X) (doublings fixed)
            out += self.energy / self.cm.kappa * kappa_grad
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
            out += (np.einsum("bnd,nd->b", W, self.gradient) / self.cm.kappa)[:, None, None] * kappa_grad
        return out.reshape(w.shape)


def _rows(pts: ContactPoints, rows: np.ndarray) -> ContactPoints:
    return ContactPoints(verts=pts.verts[rows], weights=pts.weights[rows], facet=pts.facet[rows])


@dataclass(frozen=True, kw_only=True, eq=False)
class StressMeasure:
    """The stress figure of a step: max_e (A sigma_vm)_e, A the row-stochastic averaging over a critical
    distance of the per-point stresses of :func:`simfab.fem.shape_derivative.point_von_mises`.

    A is held fixed (its dependence on X is not differentiated). The gradient is that of the log-sum-exp
    T log sum_e exp((A sigma)_e / T) at T = ``temperature_rel`` * max; the value reported is the exact maximum.

    Args:
        averaging: A (p, p) (linear: per element, :func:`simfab.design.stress.averaging_matrix`; P2: per
            quadrature point, element-major).
        temperature_rel: the smooth maximum's temperature relative to the maximum.
    """

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


class _Friction:
    """The friction forces of a converged state solved with the lag ``state.friction``
    (:mod:`simfab.coupling.friction`), as functions of the state itself: at a converged lag the
    normal forces and normals are those of the solution,

        f_j = mu lambda_j phi(|w_j|) w_j,   w_j = (I - n_j n_j^T)(y_j(x) - c_j),   phi = f1(y) / y,
        lambda_j = -kappa b'(d_j(x); dhat_j(X)),   n_j = grad d_j / |grad d_j|,
        c_j = M (y_j(x_prev) - p_a) + p_b (the anchors, carried from the step's start),

    and eps_j = (friction_eps_rel / dhat_rel) dhat_j(X). Their Jacobian in y_j is

        df_j/dy = Hf_j + mu phi w_j (x) dlambda_j/dy + B_j Dw_j,   B_j = mu lambda_j (phi'/y w w^T + phi I),
        dlambda_j/dy = -kappa b''(d_j) grad d_j,   Dw_j = -((n . dy) N_j + n_j (x) N_j^T dy),
        N_j = dn_j/dy = (I - n n^T) hess d_j / |grad d_j|,

    Hf_j = B_j (I - n n^T) the friction Hessian at the held lag: the first term is the part
    a lag held fixed keeps; the other two are not symmetric (the lagged step has no potential in its
    normal forces and normals). ``held``: use Hf only (lambda_j and n_j held at their values)."""

    def __init__(self, cm: CouplingModel, state: StepState, held: bool = False):
        lag = state.friction
        x = np.asarray(state.x, float)
        self.cm, self.lag, self.rows = cm, lag, lag.rows
        pts, rows = lag.points, lag.rows
        fe = lag.evaluate(x, hessian=True)
        self.Hy = fe.hessian  # (a, dim, dim) d2D/dy2, exact for the held lag (simfab.contact.friction)
        dim = cm.dim
        dy = pts.positions(x)[rows] - lag.anchors[rows]
        n = lag.normals
        w = dy - np.einsum("kd,kd->k", n, dy)[:, None] * n  # the tangential slip (I - n n^T) dy
        y, eps = fe.slip, lag.eps
        stick = y < eps
        ys = np.where(y > 0, y, 1.0)
        phi = np.where(stick, 2.0 / eps - y / eps**2, 1.0 / ys)
        curv = np.where(y <= 0, 0.0, np.where(stick, -1.0 / (eps**2 * ys), -1.0 / ys**3))
        ml = lag.mu_lambda
        self.force_dir = ml[:, None] * phi[:, None] * w  # f_j
        # mu lambda_j f1 / y differentiated in eps (zero once slipping)
        self.dfy = ml * np.where(stick, -2.0 / eps**2 + 2.0 * y / eps**3, 0.0)
        self.w = w
        scale = cm.contact.friction_eps_rel / cm.options.dhat_rel
        sub = _rows(pts, rows)
        self.dhat_jac = dhat_jacobian(cm, sub)  # (a, n dim)
        self.eps_jac = scale * self.dhat_jac
        self.extra = None
        self.kappa = float(state.kappa_step)
        if held or not len(rows):
            return
        ev = cm.field.evaluate(pts.positions(x)[rows], cm.pose(state.s), hessian=True,
                               hessian_band=float(point_dhat(cm, pts).max()))
        d, gd, hd = -ev.psi, -ev.grad[:, :dim], -ev.hess[:, :dim, :dim]
        dh = point_dhat(cm, pts)[rows]
        r, log = d - dh, np.log(d / dh)
        b2 = -2.0 * log - 4.0 * r / d + r * r / d**2  # b''(d)
        self.dbp_ddhat = 2.0 * log + 2.0 * r / dh + 2.0 * r / d  # d b'(d; dhat) / d dhat
        self.lam = lag.normal_force[rows]
        self.mu = lag.mu_lambda / np.where(self.lam > 0, self.lam, 1.0)
        gl = -self.kappa * b2[:, None] * gd  # d lambda / dy
        gn = np.linalg.norm(gd, axis=1)
        Pt = np.eye(dim) - n[:, :, None] * n[:, None, :]
        N = Pt @ hd / gn[:, None, None]
        ndy = np.einsum("kd,kd->k", n, dy)
        Dw = -(ndy[:, None, None] * N + n[:, :, None] * np.einsum("kji,kj->ki", N, dy)[:, None, :])
        B = ml[:, None, None] * (curv[:, None, None] * w[:, :, None] * w[:, None, :] + phi[:, None, None] * np.eye(dim))
        self.extra = (self.mu * phi)[:, None, None] * w[:, :, None] * gl[:, None, :] + B @ Dw  # (a, dim, dim)

    def mixed_product(self, W: np.ndarray, kappa_grad: np.ndarray | None) -> np.ndarray:
        """d/dX (w . sum_j P_j^T f_j) at fixed x and anchors for a stack W (b, n, dim): through eps_j and,
        unless held, lambda_j (dhat_j, and kappa in 3D)."""
        wy = np.stack([self.lag.points.positions(wb)[self.rows] for wb in W])  # (b, a, dim)
        coef = self.dfy * np.einsum("kd,bkd->bk", self.w, wy)
        out = np.asarray(coef @ self.eps_jac).reshape(W.shape)
        if self.extra is not None:
            fw = np.einsum("kd,bkd->bk", self.force_dir, wy)  # w . f_j: f_j is proportional to lambda_j
            dlam = -self.kappa * self.dbp_ddhat  # d lambda_j / d dhat_j
            out += np.asarray((fw * (dlam / np.where(self.lam > 0, self.lam, 1.0))) @ self.dhat_jac).reshape(W.shape)
            if kappa_grad is not None:  # lambda_j proportional to kappa, kappa to the mean edge length in 3D
                out += (fw.sum(axis=1) / self.cm.kappa)[:, None, None] * kappa_grad
        return out

    def back(self, W: np.ndarray, M: np.ndarray) -> np.ndarray:
        """-(d R / d x_prev)^T w for a stack W (b, n, dim): the anchors c_j = M P_j x_prev + const, so
        dR/dx_prev = -sum_j P_j^T Hf_j M P_j and the result is sum_j P_j^T M^T Hf_j P_j w."""
        dim = self.cm.dim
        Md = np.asarray(M)[:dim, :dim]
        out = np.empty_like(W)
        for b, wb in enumerate(W):
            wy = self.lag.points.positions(wb)[self.rows]
            out[b] = self.lag.points.scatter(np.einsum("kij,kj->ki", self.Hy, wy) @ Md, self.cm.fem.n_vertices,
                                             rows=self.rows)
        return out


@dataclass(frozen=True, kw_only=True, eq=False)
class StepLink:
    """How a step's equilibrium depends on the state it started from, x_prev (the previous record's
    positions, or the rest shape X for the first): through the friction anchors (``friction_motion``:
    O's rotation M (3, 3) over the step, None without friction) and the rigid-motion pin's anchor
    (``pin``: :class:`simfab.coupling.rigid.Pin` anchored at x_prev, None without); ``followed``: the
    dependence is followed to the previous record (False when the step started from a state that was
    not recorded: a bisected step or a step solved again after its pin changed; x_prev then held)."""

    friction_motion: np.ndarray | None
    pin: object
    followed: bool
    from_rest: bool


class StepLinearization:
    """A converged step linearized for the adjoint method: the Jacobian J = dR/dx of its equilibrium
    R = grad_x (E + B) (+ the friction forces, + the pin's gradient) = 0 (without friction the exact
    Hessian H, symmetric), the barrier, friction and pin terms, and the solver.

    :meth:`solve` gives lambda with (J^T lambda)_free = r_free for a stack of right-hand sides;
    :meth:`pull` turns (lambda, dq/dx, direct terms) into dq/dX (the module docstring's formula);
    :meth:`back` gives the right-hand sides the previous step receives. ``held_lag``: the friction's
    normal forces and normals held at their values (the Jacobian then is the symmetric H + Hf)."""

    def __init__(self, cm: CouplingModel, state: StepState, link: StepLink, solver: SPDSolver,
                 held_lag: bool = False):
        self.cm, self.state, self.link, self.solver = cm, state, link, solver
        fem, x = cm.fem, np.asarray(state.x, float)
        self.x = x
        n, dim = fem.n_vertices, cm.dim
        self.bar = _Barrier(cm, state)
        frictional = state.friction is not None and len(state.friction.rows)
        self.fric = _Friction(cm, state, held=held_lag) if frictional else None
        _, self.gE, HE = energy_gradient_hessian(fem, x, project_psd=False)
        self.HB = HE.copy()
        self.HB.data[:] = 0.0
        add_point_blocks(cm, state.points, self.HB, self.bar.act, self.bar.Hy)
        H = HE.copy()  # in HE's fixed pattern (the Hessian slots, regularization and solver maps expect it)
        add_point_blocks(cm, state.points, H, self.bar.act, self.bar.Hy)
        self.JT = None  # J^T where J is not symmetric
        if self.fric is not None:
            add_point_blocks(cm, self.fric.lag.points, H, self.fric.rows, self.fric.Hy)
            if self.fric.extra is not None:
                J = H.copy()
                add_point_blocks(cm, self.fric.lag.points, J, self.fric.rows, self.fric.extra)
                self.JT = sp.csr_matrix(J.T)
        self.H = H
        # 3D: the model's kappa_0 = kappa_rel E h_A follows the mean edge length h_A of the corner mesh (d kappa_0/dX);
        # a step's kappa is kappa_0 times the run's doublings, fixed on the branch the run took
        self.kappa_grad = (cm.kappa / cm.h * mean_edge_length_gradient(cm.fem.rest, cm.fem.corner_elements)
                           if dim == 3 else None)
        self.idx = np.flatnonzero(cm.free)
        self.fixed = ~cm.free.reshape(n, dim)
        self.stable = True

    def transpose_product(self, v: np.ndarray) -> np.ndarray:
        """J^T v (n, dim) for v (n, dim) (without the pin): d(v . R)/dx."""
        A = self.H if self.JT is None else self.JT
        return (A @ np.ravel(v)).reshape(np.shape(v))

    def apply(self, lam: np.ndarray) -> np.ndarray:
        """J^T lambda (+ the pin's mu U U^T lambda) for a stack (k, n, dim)."""
        out = np.stack([self.transpose_product(lb) for lb in lam])
        pin = self.link.pin
        if pin is not None:
            out += (pin.mu * ((lam.reshape(len(lam), -1) @ pin.U) @ pin.U.T)).reshape(lam.shape)
        return out

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """lambda (k, n, dim) with (J^T lambda)_free = rhs_free, lambda_fixed = 0, for rhs (k, n, dim)."""
        k = len(rhs)
        idx = self.idx
        b = rhs.reshape(k, -1)[:, idx].T
        lam = np.zeros((k, rhs[0].size))
        pin = self.link.pin
        if pin is None and self.JT is None:
            try:
                lam_f = self.solver.solve_free(self.H, idx, b)
            except NotPositiveDefinite:
                self.stable = False
                lam_f = splu(sp.csc_matrix(self.H[idx][:, idx])).solve(b)
            lam[:, idx] = np.asarray(lam_f).reshape(len(idx), k).T
            return lam.reshape(rhs.shape)
        # as Newton solved it, a pin by Woodbury on the regularized matrix, then refinement sweeps
        # against the exact J^T + mu U U^T remove the regularization's tiny diagonal term
        Ar = self.H.copy()
        if pin is not None:
            regularize(self.cm, Ar)
        if self.JT is not None:
            lu = splu(sp.csc_matrix((self.JT + (Ar - self.H))[idx][:, idx]))
            base = lu.solve
        else:
            def base(r):
                return self.solver.solve_free(Ar, idx, r)

        def sweeps(base) -> None:
            if pin is None:
                inner = base
            else:
                Uf = pin.U[idx]
                Z = np.asarray(base(Uf)).reshape(len(idx), -1)
                S = np.eye(Uf.shape[1]) / pin.mu + Uf.T @ Z

                def inner(r):
                    y = np.asarray(base(r)).reshape(r.shape)
                    return y - Z @ np.linalg.solve(S, Uf.T @ y)
            lam[:] = 0.0
            for sweep in range(3 if pin is not None else 1):
                r = b if sweep == 0 else b - self.apply(lam.reshape(rhs.shape)).reshape(k, -1)[:, idx].T
                lam[:, idx] += np.asarray(inner(r)).reshape(len(idx), k).T

        try:
            sweeps(base)
        except NotPositiveDefinite:  # (an indefinite equilibrium Hessian: the same solve by LU)
            self.stable = False
            sweeps(splu(sp.csc_matrix(Ar[idx][:, idx])).solve)
        return lam.reshape(rhs.shape)

    def pull(self, lam: np.ndarray, gx: np.ndarray, direct: np.ndarray, elastic_shift: np.ndarray,
             barrier_shift: np.ndarray) -> np.ndarray:
        """dq/dX (k, n, dim) = direct - (lambda - shift)^T dR/dX + (dq/dx - J^T lambda)_fixed for stacks
        (k, n, dim): ``elastic_shift`` is subtracted from lambda in the elastic and friction terms and
        ``barrier_shift`` in the barrier's (the force's and grip's direct terms folded into the stack)."""
        We = lam - elastic_shift
        Wb = lam - barrier_shift
        out = direct - shape_derivative.mixed_product(self.cm.fem, self.x, We) \
            - self.bar.mixed_product(Wb, self.kappa_grad)
        if self.fric is not None:
            out -= self.fric.mixed_product(We, self.kappa_grad)
        resid = gx - self.apply(lam)
        out[:, self.fixed] += resid[:, self.fixed]  # the fixed dofs sit at the rest positions: dx_fixed/dX_fixed = I
        return out

    def back(self, lam: np.ndarray) -> np.ndarray:
        """The right-hand sides (k, n, dim) -(dR/dx_prev)^T lambda that the previous step receives:
        the friction anchors' and the pin anchor's."""
        out = np.zeros_like(lam)
        if self.fric is not None and self.link.friction_motion is not None:
            out += self.fric.back(lam, self.link.friction_motion)
        pin = self.link.pin
        if pin is not None:  # pin energy mu/2 |U^T (x - x_prev)|^2 (U held): d grad / d x_prev = -mu U U^T
            out += (pin.mu * ((lam.reshape(len(lam), -1) @ pin.U) @ pin.U.T)).reshape(lam.shape)
        return out


def step_link(cm: CouplingModel, state: StepState, previous: StepState | None) -> StepLink:
    """:class:`StepLink` of ``state`` given the previous record's state (None: the first record)."""
    prev = state.prev
    if previous is None:
        followed = prev is None
        anchor = np.asarray(cm.fem.rest, float) if prev is None else prev.x
    else:
        followed = prev is not None and prev.x is previous.x
        anchor = prev.x if prev is not None else previous.x
    pinned = state.pin_basis is not None and state.pin_basis.shape[1] > 0
    pin = rigid.pin_for(cm, state.pin_basis, rigid.motion_basis(cm)[1], anchor) if pinned else None
    M = None
    if state.friction is not None and prev is not None:
        M = cm.motion(prev.s, state.s)[0]
    return StepLink(friction_motion=M, pin=pin, followed=followed, from_rest=prev is None)


def _step(cm, state, phase, stress, solver, link, held_lag=False):
    """(linearization, sensitivity at a fixed start, lambda stack (k, n, dim))."""
    lin = StepLinearization(cm, state, link, solver, held_lag)
    fem, x = cm.fem, lin.x
    n, dim = fem.n_vertices, cm.dim
    free = ~lin.fixed
    u = cm.direction(state.s)
    v = np.where(free, 0.0, u[None, :])  # F = v . grad W
    gc = lin.bar.gradient
    a = 0.5 * np.abs(gc).sum(axis=0)
    G = float(np.linalg.norm(a))
    wg = 0.5 * np.sign(gc) * (a / G)[None, :] if G > 0 else np.zeros_like(gc)
    zero = np.zeros((n, dim))
    gE_rest = shape_derivative.rest_gradient(fem, x)
    # per figure: dq/dx (n, dim), dq/dX at fixed x; the force's direct term is mixed(v) and the grip's the
    # barrier part of mixed(wg): folded into the stacked mixed product as shifts of lambda
    gx = [lin.gE.reshape(n, dim), lin.transpose_product(v), (lin.HB @ wg.ravel()).reshape(n, dim)]
    direct = [gE_rest, zero, zero]
    stress_value = float("nan")
    if stress is not None:
        avg = stress.averaging @ shape_derivative.point_von_mises(fem, x)
        stress_value = float(avg.max())
        c = stress.averaging.T @ smooth_max_weights(avg, stress.temperature_rel * abs(stress_value))
        sx, sX = shape_derivative.von_mises_derivatives(fem, x, c)
        gx.append(sx)
        direct.append(sX)
    gx, direct = np.stack(gx), np.stack(direct)
    e_shift, b_shift = np.zeros_like(gx), np.zeros_like(gx)
    e_shift[1] = b_shift[1] = v
    b_shift[2] = wg
    lam = lin.solve(gx)
    out = lin.pull(lam, gx, direct, e_shift, b_shift)
    if link.from_rest and link.pin is not None:  # the first step's pin is anchored at the rest shape itself
        out += lin.back(lam)
    sens = StepSensitivity(s=float(state.s), phase=phase, energy=out[0], force=out[1], grip=out[2],
                           stress=out[3] if stress is not None else None, stress_value=stress_value,
                           stable=lin.stable, supported=link.followed,
                           friction_lag_held=lin.fric is not None and held_lag)
    return lin, sens, lam


#: The backward pass drops a record's right-hand side once its l1 norm [q/m] falls below this fraction of
#: the largest entry of the record's own derivative dq/dX (dx/dX is O(1), so it would change dq/dX by
#: about as little): chains through sliding friction or pinned motions in balance die out within a few steps.
PRUNE_REL = 1e-9


def _depends(link: StepLink, lin: StepLinearization) -> bool:
    """The step's equilibrium depends on the previous record's positions, and that is followed."""
    return link.followed and _on_start(link, lin)


def _on_start(link: StepLink, lin: StepLinearization) -> bool:
    """The step's equilibrium depends on the state it started from (friction anchors, a pin's anchor)."""
    return not link.from_rest and (link.pin is not None or lin.fric is not None)


def _matters(rhs: np.ndarray, sens: StepSensitivity, figure: str) -> bool:
    """Whether a right-hand side of the backward pass for a record's figure is above PRUNE_REL of the
    record's own derivative of it (l1 norm against the largest entry)."""
    return bool(np.abs(rhs).sum() > PRUNE_REL * np.abs(getattr(sens, figure)).max())


class SensitivityRecorder:
    """Collects a :class:`StepSensitivity` per kept step of a run: pass as ``simulate_insertion(..., recorder=...)``.

    ``insert`` and ``remove``: the sensitivities of the run's insertion and removal records, in order.
    Each record's sensitivity is computed when it is kept, at its start held fixed; where steps depend on
    their start (friction anchors, a pin), reading ``insert`` / ``remove`` first runs the backward pass
    (:meth:`finish`): the right-hand sides of every later record are solved at each earlier one in turn.

    Args:
        cm: the coupling model of the run.
        stress: the stress figure to differentiate too, or None.
        held_lag: hold the friction's normal forces and normals fixed (an approximation).
    """

    def __init__(self, cm: CouplingModel, stress: StressMeasure | None = None, *, held_lag: bool = False):
        self.cm, self.stress, self.held_lag = cm, stress, held_lag
        self.solver = SPDSolver()  # one symbolic analysis for the run's (fixed-pattern) Hessians
        self._sens: list[StepSensitivity] = []
        self._states: list[StepState] = []
        self._links: list[StepLink] = []
        self._pending: list = []  # per record: its lambda stack when the step depends on its start, else None
        self._finished = True

    def __call__(self, record, state: StepState) -> None:
        previous = self._states[-1] if self._states else None
        link = step_link(self.cm, state, previous)
        lin, sens, lam = _step(self.cm, state, record.phase, self.stress, self.solver, link, self.held_lag)
        depends = _depends(link, lin)
        self._sens.append(sens)
        # kept for the backward pass without Newton's evaluation, tangent and check memo (Hessians)
        self._states.append(dataclasses.replace(state, evaluation=None, tangent=None, check=None, check_cache={}))
        self._links.append(link)
        self._pending.append(lin.back(lam) if depends else None)
        self._finished = self._finished and not depends

    def finish(self) -> None:
        """The backward pass through the steps that depend on their start (see the class docstring)."""
        if self._finished:
            return
        self._finished = True
        figs = [f for f in ("energy", "force", "grip", "stress") if getattr(self._sens[0], f) is not None]
        add: dict = {}
        cut_off: set = set()  # records whose chain reaches a held start
        incoming = None  # (targets [(record, figure)], right-hand sides (b, n, dim)) to solve at record j
        for j in range(len(self._sens) - 1, -1, -1):
            targets, send = [], []
            if incoming is not None:
                lin = StepLinearization(self.cm, self._states[j], self._links[j], self.solver, self.held_lag)
                lam = lin.solve(incoming[1])
                zero = np.zeros_like(lam)
                dq = lin.pull(lam, incoming[1], zero, zero, zero)
                if self._links[j].from_rest and self._links[j].pin is not None:
                    dq += lin.back(lam)
                for t, d in zip(incoming[0], dq):
                    add[t] = add.get(t, 0.0) + d
                if _depends(self._links[j], lin):
                    targets, send = list(incoming[0]), [lin.back(lam)]
                elif _on_start(self._links[j], lin):
                    # the step started from a state that was not recorded (held): the later records whose
                    # chain still matters here miss the dependence beyond it, so they are not supported
                    cut = lin.back(lam)
                    cut_off |= {k for (k, f), b in zip(incoming[0], cut) if _matters(b, self._sens[k], f)}
            if self._pending[j] is not None:
                targets += [(j, f) for f in figs]
                send.append(self._pending[j])
            if targets:  # drop the right-hand sides too small to matter (a chain that has died out)
                send = np.concatenate(send)
                keep = [i for i, (k, f) in enumerate(targets) if _matters(send[i], self._sens[k], f)]
                targets, send = [targets[i] for i in keep], send[keep]
            incoming = (targets, send) if targets else None
        for (k, f), d in add.items():
            self._sens[k] = dataclasses.replace(self._sens[k], **{f: getattr(self._sens[k], f) + d})
        for k in cut_off:
            self._sens[k] = dataclasses.replace(self._sens[k], supported=False)

    @property
    def insert(self) -> list[StepSensitivity]:
        self.finish()
        return [s for s in self._sens if s.phase != "remove"]

    @property
    def remove(self) -> list[StepSensitivity]:
        self.finish()
        return [s for s in self._sens if s.phase == "remove"]
