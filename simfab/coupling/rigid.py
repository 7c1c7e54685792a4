"""Rigid motions of the compliant part A that neither the supports nor the contact resist.

The fixed region holds A only along some axes, and frictionless contact pushes only along O's
normals. A rigid motion of A that moves no held dof and no contact point along its normal costs
no energy: the equilibrium is then not unique along it (a clip on a frictionless cylinder can
slide along the cylinder's axis, a claw on a sphere can turn about the axis through the sphere's
centre), and where A ends up along it, and with it the forces, depends on solver details. This
module finds such motions and pins them (:class:`Pin`): the next step's objective carries
mu/2 |U^T (x - x_start)|^2, U (N, r) the unresisted motions' displacement fields over the free
dofs (orthonormal), x_start the state the step starts from, mu = PIN_REL times the mean
diagonal stiffness of A. Along a motion nothing resists the energy is flat, so the pin changes no
energy and no force (its gradient vanishes at the equilibrium) and only removes the
non-uniqueness: A stays where the step began along it. U is dense (r <= 6 columns), so the
Newton solve with H + mu U U^T is a Woodbury update of the sparse factorization
(:class:`PinnedSolver`). Before any contact every free motion is pinned (nothing acts on A).

A rigid motion is q = (t, w): translation t and rotation w (about A's rest centroid c), moving a
point y by u(y) = t + w x (y - c) (2D: w is a scalar, w x r = w (-r_y, r_x)).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dsygvd as _sygvd

from simfab.fem.elastic import energy_gradient_hessian
from simfab.solve.linear import NotPositiveDefinite, conjugate_gradients

#: A rigid motion whose contact stiffness is below this fraction of the stiffness it would have if
#: every contact normal were aligned with the motion counts as unresisted.
UNRESISTED_REL = 1e-2
#: Pin weight relative to the mean diagonal stiffness of A at rest (see the module docstring).
PIN_REL = 1.0


def mean_stiffness(cm) -> float:
    """Mean |diagonal| of A's stiffness at rest [N/m] (memoized)."""
    k = cm._cache.get("mean_stiffness")
    if k is None:

        _, _, H = energy_gradient_hessian(cm.fem, cm.fem.rest, project_psd=False)
        k = cm._cache["mean_stiffness"] = float(np.abs(H.diagonal()).mean())
    return k


class Pin:
    """mu/2 |U^T (x - anchor)|^2 over the free dofs: U (N, r) orthonormal displacement fields of
    rigid motions (zero on held dofs), anchor (N,) positions [m], mu [N/m]."""

    def __init__(self, U: np.ndarray, mu: float, anchor: np.ndarray):
        self.U, self.mu, self.anchor = U, float(mu), np.asarray(anchor, float).ravel().copy()

    def energy(self, xf: np.ndarray) -> float:
        q = self.U.T @ (xf - self.anchor)
        return 0.5 * self.mu * float(q @ q)

    def gradient(self, xf: np.ndarray) -> np.ndarray:
        return self.mu * (self.U @ (self.U.T @ (xf - self.anchor)))

    def force(self, xf: np.ndarray) -> np.ndarray:
        """(r,) generalized force the pin exerts along each of its motions at xf [N]."""
        return -self.mu * (self.U.T @ (xf - self.anchor))


def pin_for(cm, Q: np.ndarray, c: np.ndarray, x: np.ndarray) -> Pin | None:
    """Pin of the rigid motions span(Q) (columns, :func:`motion_basis` coordinates) of A at
    positions x (n, dim), anchored at x; None when Q has no column."""
    if Q.shape[1] == 0:
        return None
    memo = cm._cache.get("pin_memo")
    if memo is not None and memo[0] is Q and memo[1] is x:
        return memo[2]
    dim = cm.dim
    U = (point_motions(x - c, dim) @ Q).reshape(-1, Q.shape[1])  # (n*dim, r)
    U[~cm.free] = 0.0
    U, sv, _ = np.linalg.svd(U, full_matrices=False)
    U = U[:, sv > 1e-9 * sv.max()]
    pin = Pin(U, PIN_REL * mean_stiffness(cm), x)
    cm._cache["pin_memo"] = (Q, x, pin)  # the same step's objectives and predictor share it
    return pin


#: PinnedSolver: when A alone does not factorize, A + shift I does with the smallest shift of
#: SHIFT_START * mu * 10^k up to SHIFT_MAX * mu (mu the pin's stiffness, the mean diagonal stiffness)...
SHIFT_START = 1e-7
SHIFT_MAX = 1e-4
#: ... and conjugate gradients on A + mu U U^T, preconditioned by that factorization, solve to this
#: relative residual (inexact-Newton forcing), or to PCG_TOL_NEAR when the caller gives Newton's force
#: target and the right-hand side is within PCG_NEAR times it (Newton's last steps: exact, so that
#: a tight target is reached as with a direct solve), in at most PCG_MAX_ITER iterations (past them
#: the PCG_TOL criterion alone).
PCG_TOL = 1e-2
PCG_NEAR = 100.0
PCG_TOL_NEAR = 1e-8
PCG_MAX_ITER = 25
#: ... or, either way, once the residual's largest entry is within this fraction of Newton's force target
#: (when the caller gives it): the step's own residual then cannot keep Newton from its target.
PCG_ATOL = 0.1
#: A lagged solve (:class:`simfab.solve.linear.LagConfig`) stops once its residual is within this fraction
#: of Newton's force target (when the caller gives it).
LAG_TARGET = 0.1
#: ... and, while its right-hand side is more than PCG_NEAR times that target, at this relative residual
#: (the inexact-Newton forcing of the shifted solves, PCG_TOL; None: the LagConfig's rtol).
LAG_RTOL_FAR = 1e-2


def forcing(b: np.ndarray, target: float | None) -> tuple[float | None, float | None]:
    """The accuracy of an iterative (lagged or multigrid) Newton solve with right-hand side b (m,):
    (atol, rtol) = (LAG_TARGET * target, LAG_RTOL_FAR) while b's largest entry is more than PCG_NEAR
    times Newton's force target [units of b], (LAG_TARGET * target, None: the solver's own rtol) near
    it; (None, None) without a target. A residual within a tenth of the target cannot keep Newton
    from it, and far from it a step solved to two digits costs no Newton iterations (inexact
    Newton's forcing term)."""
    if target is None:
        return None, None
    return LAG_TARGET * target, (None if np.abs(b).max() <= PCG_NEAR * target else LAG_RTOL_FAR)


class ForcedSolver:
    """A solver without the pin whose iterative solves stop at Newton's force target (:func:`forcing`),
    as :class:`PinnedSolver`'s do; a factorization's solve is exact either way.

    Args:
        solver: the SPD solver (:class:`simfab.solve.linear.SPDSolver`; its ``solve_free`` takes
            ``atol`` and ``rtol``).
        target: Newton's force target (inf-norm of the residual) [units of b].
    """

    def __init__(self, solver, target: float):
        self.solver, self.target = solver, target

    def solve_free(self, A, free, b):
        if np.ndim(b) != 1:
            return self.solver.solve_free(A, free, b)
        atol, rtol = forcing(b, self.target)
        return self.solver.solve_free(A, free, b, atol=atol, rtol=rtol)

    def solve(self, A, b):
        return self.solve_free(A, np.arange(A.shape[0]), b)


class PinnedSolver:
    """Solves (A + mu U U^T)[free] x = b with one factorization of A[free] (Woodbury):
    y = A^-1 b, Z = A^-1 U, x = y - Z (I/mu + U^T Z)^-1 U^T y. Wraps a solver with
    ``solve_free(A, free, b)``, or with ``solve_free_update`` (:class:`simfab.solve.linear.SPDSolver`:
    the same update with U through half the triangular solves).

    A loaded part's exact Hessian A can be slightly indefinite along the rigid motions the pin
    holds (their geometric stiffness; docs/decisions.md) while A + mu U U^T is positive definite. When A
    does not factorize, A + shift I (the smallest shift of a ladder, see SHIFT_START) is factorized
    instead and serves as the preconditioner of conjugate gradients on A + mu U U^T itself (the
    shift moves the other modes' eigenvalues by a small fraction: a few iterations), so the solve
    stays exact; the shift is remembered for the run's later solves (``SPDSolver.shift_hint``).
    Negative curvature found by the iterations (A + mu U U^T indefinite) raises NotPositiveDefinite,
    as a failed factorization does. A solver that lags its factorizations
    (:class:`simfab.solve.linear.LagConfig`) is first asked for the lagged solve of A + mu U U^T
    (conjugate gradients preconditioned with its current factorization and the same update; far from
    Newton's target at the shifted solves' forcing, LAG_RTOL_FAR)."""

    def __init__(self, solver, pin: Pin, target: float | None = None):
        self.solver, self.pin = solver, pin
        self.target = target  # Newton's force target (inf-norm of the residual) [units of b], or None
        self.pcg_iterations = 0  # conjugate-gradient iterations of the shifted solves so far
        self._Uf = None

    def solve_free(self, A, free, b):
        if self._Uf is None or self._Uf[0] is not free:
            self._Uf = (free, self.pin.U[free])  # one array per free set: the solver reuses its half solve
        Uf = self._Uf[1]
        if hasattr(self.solver, "solve_free_lagged") and np.ndim(b) == 1:
            atol, rtol = forcing(b, self.target)
            x = self.solver.solve_free_lagged(A, free, b, Uf, self.pin.mu, atol, rtol=rtol)  # None: not lagged
            if x is not None:
                return x
        if not hasattr(self.solver, "solve_free_update"):
            X = self.solver.solve_free(A, free, np.column_stack([b, Uf]))
            y, Z = X[:, 0], X[:, 1:]
            S = np.eye(Uf.shape[1]) / self.pin.mu + Uf.T @ Z
            return y - Z @ np.linalg.solve(S, Uf.T @ y)
        hint = getattr(self.solver, "shift_hint", None)
        if not hint:
            try:
                return self.solver.solve_free_update(A, free, b, Uf, self.pin.mu)
            except NotPositiveDefinite:
                if hint is None:
                    raise
        return self._shifted(A, free, b, Uf)

    def solve(self, A, b):
        return self.solve_free(A, np.arange(A.shape[0]), b)

    def _shifted(self, A, free, b, Uf):
        """(A[free] + mu Uf Uf^T)^-1 b by PCG preconditioned with the shifted factorization."""
        b = np.asarray(b, dtype=np.float64)
        if b.ndim == 2:
            return np.column_stack([self._shifted(A, free, b[:, j], Uf) for j in range(b.shape[1])])
        mu, solver = self.pin.mu, self.solver
        rel = max(solver.shift_hint, SHIFT_START)
        while True:
            try:  # the first preconditioning factorizes
                z = solver.solve_free_update(A, free, b, Uf, mu, rel * mu)
                break
            except NotPositiveDefinite:
                rel *= 10.0
                if rel > SHIFT_MAX:
                    raise
        solver.shift_hint = rel
        return self._pcg(A, free, b, z, Uf, rel * mu)

    def _pcg(self, A, free, b, z, Uf, shift):
        """Conjugate gradients on (A[free] + mu Uf Uf^T) x = b, z the preconditioned b."""
        solver, mu = self.solver, self.pin.mu
        n = A.shape[0]
        z_full = np.zeros(n)

        def K(v):
            z_full[free] = v
            return (A @ z_full)[free] + mu * (Uf @ (Uf.T @ v))

        if hasattr(solver, "solve_factored_update"):
            def M(r):  # the factorization of A + shift I, as it is (no gather, no comparison of values)
                return solver.solve_factored_update(r, Uf, mu)
        else:
            def M(r):  # the factorization of A + shift I is reused (same values)
                return solver.solve_free_update(A, free, r, Uf, mu, shift)

        bn = float(np.linalg.norm(b))
        if bn == 0.0:
            return np.zeros_like(b)
        near = self.target is not None and np.abs(b).max() <= PCG_NEAR * self.target
        tol = PCG_TOL_NEAR if near else PCG_TOL
        atol = np.inf if self.target is None else PCG_ATOL * self.target

        def converged(r, rn):
            return rn <= tol * bn or np.abs(r).max() <= atol

        res = conjugate_gradients(K, M, b, z=z, max_iter=PCG_MAX_ITER, converged=converged)
        self.pcg_iterations += res.iterations
        if res.converged or res.residual <= PCG_TOL * bn:  # past PCG_MAX_ITER the PCG_TOL criterion alone
            return res.x
        raise NotPositiveDefinite(f"conjugate gradients on the pinned Hessian did not converge in {PCG_MAX_ITER} "
                                  "iterations")


def unresisted(Q: np.ndarray, c: np.ndarray, y: np.ndarray, normals: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(k, r') the sub-basis of span(Q) that contact at points y (p, dim) with normals (p, dim) and
    stiffness weights (p,) resists by less than UNRESISTED_REL (see :func:`weakest_motion`); all
    of Q without contact."""
    modes = contact_modes(Q, c, y, normals, weights)
    return Q if modes is None else modes[1][:, modes[0] < UNRESISTED_REL]


def motion_basis(cm) -> tuple[np.ndarray, np.ndarray]:
    """(Q (r, k), c (dim,)): a basis of the rigid motions (columns, r = 3 in 2D, 6 in 3D) that move
    no dof held by the supports, and the centre the rotations are about. k = 0: the supports hold
    every rigid motion. Memoized per model (read-only)."""
    out = getattr(cm, "_cache", {}).get("motion_basis")
    if out is None:
        out = _motion_basis(cm)
        if hasattr(cm, "_cache"):
            cm._cache["motion_basis"] = out
    return out


def _motion_basis(cm) -> tuple[np.ndarray, np.ndarray]:
    fem, dim = cm.fem, cm.dim
    c = fem.rest.mean(axis=0)
    verts, axes = np.nonzero(~cm.free.reshape(-1, dim))  # the held dofs
    r = 3 if dim == 2 else 6
    if not len(verts):
        return np.eye(r), c
    rows = point_motions(fem.rest[verts] - c, dim)[np.arange(len(verts)), axes]  # (held dofs, r)
    _, s, Vt = np.linalg.svd(rows, full_matrices=True)
    rank = int(np.sum(s > 1e-9 * s.max()))
    return Vt[rank:].T, c


def point_motions(rel: np.ndarray, dim: int) -> np.ndarray:
    """(p, dim, r): d u / d q at points with positions ``rel`` (p, dim) relative to the centre."""
    p = len(rel)
    if dim == 2:
        out = np.zeros((p, 2, 3))
        out[:, 0, 0] = out[:, 1, 1] = 1.0
        out[:, 0, 2], out[:, 1, 2] = -rel[:, 1], rel[:, 0]
        return out
    out = np.zeros((p, 3, 6))
    out[:, [0, 1, 2], [0, 1, 2]] = 1.0
    x, y, z = rel[:, 0], rel[:, 1], rel[:, 2]
    # w x r = (w_y z - w_z y, w_z x - w_x z, w_x y - w_y x)
    out[:, 0, 4], out[:, 0, 5] = z, -y
    out[:, 1, 3], out[:, 1, 5] = -z, x
    out[:, 2, 3], out[:, 2, 4] = y, -x
    return out


def weakest_motion(Q: np.ndarray, c: np.ndarray, y: np.ndarray, normals: np.ndarray, weights: np.ndarray):
    """(ratio, q) for the rigid motion in span(Q) that contact resists least.

    y (p, dim) contact points, normals (p, dim) O's unit normals there, weights (p,) >= 0 their
    contact stiffness (e.g. kappa b''(d)). ratio = sum w (n . u)^2 / sum w |u|^2 over the points
    for the minimizing motion (0: unresisted); None when there is no contact or no free motion.
    """
    modes = contact_modes(Q, c, y, normals, weights)
    return None if modes is None else (float(max(modes[0][0], 0.0)), modes[1][:, 0])


def contact_modes(Q: np.ndarray, c: np.ndarray, y: np.ndarray, normals: np.ndarray, weights: np.ndarray):
    """(ratios (r,) ascending, motions (k, r)): the rigid motions in span(Q) ordered by how much
    the contact resists them (ratio as in :func:`weakest_motion`), or None when there is no contact
    or no free motion (:func:`unresisted` and :func:`weakest_motion` read one computation)."""
    if Q.shape[1] == 0 or not np.any(weights > 0):
        return None
    lam, V = _generalized(Q, c, y, normals, weights)
    return lam, Q @ V


def _generalized(Q, c, y, normals, weights):
    """Eigenpairs (ascending) of K v = lam M v: contact stiffness K and motion metric M of the
    motions span(Q) at the contact points (see :func:`weakest_motion`)."""
    J = point_motions(y - c, y.shape[1]) @ Q  # (p, dim, k): point motion per basis motion
    nJ = np.einsum("pd,pdk->pk", normals, J)
    K = np.einsum("p,pk,pl->kl", weights, nJ, nJ)
    M = np.einsum("p,pdk,pdl->kl", weights, J, J)
    # a motion that moves no contact point (M singular along it: few contact points, or all on its
    # axis) is not resisted either: K <= M, so regularizing M gives it the ratio 0
    M = M + (1e-12 * max(float(np.trace(M)), 1e-300) / len(M)) * np.eye(len(M))
    # LAPACK's sygvd, which scipy.linalg.eigh(K, M) calls, without its wrapper's checks (8 against
    # 57 us per call on these 3x3 / 6x6 systems, once per step); the same eigenpairs, bit for bit
    w, V, info = _sygvd(K, M, itype=1, jobz="V", uplo="L")
    if info != 0:
        raise np.linalg.LinAlgError(f"contact modes: sygvd failed (info {info})")
    return w, V


def describe(q: np.ndarray, dim: int, radius: float) -> str:
    """Words for a rigid motion q: its dominant translation axis or rotation axis (the rotation
    compared with the translation by the motion it gives at ``radius`` [m] from the centre)."""
    axes = "xyz"
    t, w = (q[:2], q[2:]) if dim == 2 else (q[:3], q[3:])
    if np.linalg.norm(t) >= radius * np.linalg.norm(w):
        return f"translation along {axes[int(np.argmax(np.abs(t)))]}"
    if dim == 2:
        return "rotation in the plane"
    return f"rotation about {axes[int(np.argmax(np.abs(w)))]}"
