"""Two-level p-multigrid for quadratic (P2) element systems: the linear (P1) field on the same
vertices as the coarse space.

A P2 field's restriction to the vertices, interpolated linearly along every edge, is the P1 field
of the corner mesh: the prolongation P (:func:`corner_prolongation`) copies a vertex's unknowns to
itself and gives each edge node the mean of its edge's two vertices, per component, so it
reproduces every linear field (rigid motions included) exactly. :class:`TwoLevelP2` is the
symmetric two-level cycle on the free block A of a P2 Hessian (plus an optional low-rank term
mu U U^T): a smoother on A (Chebyshev on point Jacobi, or symmetric Gauss-Seidel), the coarse
correction P (P^T A P)^-1 P^T by a sparse Cholesky factorization of the Galerkin coarse matrix
(:class:`simfab.solve.linear.SPDSolver`, its analysis reused while the pattern stays), the same
smoother again. It serves as the preconditioner of conjugate gradients
(:func:`simfab.solve.linear.conjugate_gradients`).

    pre = TwoLevelP2(corner_prolongation(model.n_corners, model.edges, model.dim, free))
    pre.setup(A_ff)
    res = conjugate_gradients(lambda v: A_ff @ v, pre, b, max_iter=200,
                              converged=lambda r, rn: rn <= 1e-8 * np.linalg.norm(b))
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from simfab.solve.linear import (
    ABORT_AFTER,
    LagConfig,
    NotPositiveDefinite,
    SPDSolver,
    canonical_csr,
    conjugate_gradients,
)

#: Diagonal shifts of the coarse matrix tried, relative to the pin's stiffness mu, when P^T A P does
#: not factorize (A indefinite along the pinned rigid motions): 0, then these.
COARSE_SHIFTS = (1e-6, 1e-4, 1e-2)


def corner_prolongation(n_corners: int, edges: np.ndarray, dim: int, free: np.ndarray | None = None) -> sp.csr_matrix:
    """The P1 -> P2 prolongation of a P2 mesh whose first ``n_corners`` nodes are the vertices and
    whose node ``n_corners + i`` is the midpoint of ``edges[i]`` (:class:`simfab.fem.p2.P2Model`).

    Args:
        n_corners: vertices of the corner mesh.
        edges: (e, 2) int vertex pairs of the edge nodes.
        dim: unknowns per node (node-major: unknown ``node * dim + k``).
        free: None (every unknown), or (m,) sorted int indices of the unknowns kept (the fine rows);
            the coarse columns kept are the free vertex unknowns (a fixed vertex is zero).

    Returns:
        (m, m_c) CSR: fine values = P @ coarse (vertex) values.
    """
    edges = np.asarray(edges, dtype=np.int64)
    ne = len(edges)
    k = np.arange(dim)
    # vertices: identity; edge node n_corners + i: 1/2 of each of its edge's vertices
    rows = np.concatenate([np.arange(n_corners * dim),
                           ((n_corners + np.arange(ne))[:, None, None] * dim + k).repeat(2, axis=1).ravel()])
    cols = np.concatenate([np.arange(n_corners * dim), (edges[:, :, None] * dim + k).ravel()])
    vals = np.concatenate([np.ones(n_corners * dim), np.full(2 * ne * dim, 0.5)])
    n = (n_corners + ne) * dim
    P = sp.csr_matrix((vals, (rows, cols)), shape=(n, n_corners * dim))
    if free is None:
        return P
    free = np.asarray(free, dtype=np.int64)
    coarse = free[free < n_corners * dim]  # the free vertex unknowns
    return P[free][:, coarse].tocsr()


@dataclass(frozen=True, kw_only=True)
class SmootherConfig:
    """The smoother of :class:`TwoLevelP2`.

    Args:
        kind: "chebyshev" (Chebyshev polynomial of point-Jacobi-preconditioned A, of degree ``sweeps``,
            on the upper part [lambda_max / ``ratio``, ``1.1 lambda_max``] of the spectrum of D^-1 A) or
            "sgs" (``sweeps`` symmetric Gauss-Seidel sweeps; needs ``pyamg``).
        sweeps: matrix products (Chebyshev) or symmetric sweeps (Gauss-Seidel) before and after the
            coarse correction.
        ratio: Chebyshev's eigenvalue interval, lambda_max over its lower end.
        power_iterations: iterations of the power method estimating lambda_max of D^-1 A at setup.
    """

    kind: str = "chebyshev"
    sweeps: int = 2
    ratio: float = 8.0
    power_iterations: int = 10

    def __post_init__(self):
        ok = {"kind": self.kind in ("chebyshev", "sgs"), "sweeps": self.sweeps >= 1, "ratio": self.ratio > 1.0,
              "power_iterations": self.power_iterations >= 1}
        bad = [k for k, v in ok.items() if not v]
        if bad:
            raise ValueError(f"invalid SmootherConfig: {', '.join(f'{k}={getattr(self, k)!r}' for k in bad)}")
        if self.kind == "sgs" and importlib.util.find_spec("pyamg") is None:
            raise ValueError("SmootherConfig(kind='sgs') needs pyamg (pip install pyamg, or simfab's [bench] extra)")


class TwoLevelP2:
    """Symmetric two-level preconditioner r -> M^-1 r for K = A + mu U U^T on a P2 system (see the
    module docstring). Call :meth:`setup` with each new matrix, then the object itself on residuals.

    Args:
        P: (m, m_c) prolongation (:func:`corner_prolongation`, restricted to the free unknowns).
        smoother: :class:`SmootherConfig`.

    Attributes ``coarse_unknowns``; ``coarse``: the :class:`SPDSolver` of the coarse matrix (its
    ``factorizations`` count).
    """

    def __init__(self, P: sp.csr_matrix, smoother: SmootherConfig | None = None):
        self.P = sp.csr_matrix(P)
        self.PT = self.P.T.tocsr()
        self.smoother = smoother or SmootherConfig()
        self.coarse = SPDSolver("cholmod")
        self.coarse_unknowns = self.P.shape[1]
        self._all = np.arange(self.coarse_unknowns)  # the coarse solve's free set: every coarse unknown
        self._A = None
        self._U = None
        self._mu = 0.0
        self._Uc = None
        self._Ac = None
        self._inv_diag = None
        self._lmax = None
        self._eigvec = None
        self._AP = None

    def setup(self, A: sp.spmatrix, U: np.ndarray | None = None, mu: float = 0.0, shift: float = 0.0) -> None:
        """Prepare the cycle for K = A + mu U U^T (A (m, m) symmetric, U (m, r) dense or None, mu >= 0 [units of
        A]): the Galerkin coarse matrix P^T (A + shift I) P, its factorization (with P^T U's Woodbury update)
        and the smoother's diagonal and eigenvalue bound. ``shift`` >= 0 [units of A] (in the coarse matrix
        only) makes it factorizable where A is indefinite along the motions U holds (a preconditioner
        need only be positive definite). Raises :class:`simfab.solve.linear.NotPositiveDefinite` when the
        coarse matrix does not factorize."""
        A = canonical_csr(A)
        self._A, self._mu = A, float(mu)
        self._U = None if U is None or mu == 0.0 else np.asarray(U, dtype=np.float64)
        self._AP = A @ self.P  # the coarse correction's residual update, and the Galerkin product
        Ac = self.PT @ self._AP
        if shift:
            Ac = Ac + shift * (self.PT @ self.P)
        Ac = canonical_csr(Ac)
        self._Ac = Ac
        self._Uc = None if self._U is None else self.PT @ self._U
        d = A.diagonal()
        if self._U is not None:
            d = d + self._mu * np.einsum("ij,ij->i", self._U, self._U)
        self._inv_diag = 1.0 / d
        # one numeric factorization of the coarse matrix (a solve with a zero right-hand side)
        self._coarse_solve(np.zeros(self.coarse_unknowns))
        if self.smoother.kind == "chebyshev":
            self._lmax = self._power_lambda_max()

    def apply(self, v: np.ndarray) -> np.ndarray:
        """K v."""
        y = self._A @ v
        if self._U is not None:
            y += self._mu * (self._U @ (self._U.T @ v))
        return y

    def __call__(self, r: np.ndarray) -> np.ndarray:
        """M^-1 r: smooth from zero, coarse correction, smooth (the adjoint sweep)."""
        x = self._smooth(np.zeros_like(r), r, forward=True)
        res = r - self.apply(x)
        e = self._coarse_solve(self.PT @ res)
        x += self.P @ e
        res -= self._AP @ e  # K P e, with K = A + mu U U^T
        if self._U is not None:
            res -= self._mu * (self._U @ (self._U.T @ (self.P @ e)))
        return self._smooth(x, r, forward=False, residual=res)

    def _coarse_solve(self, rc: np.ndarray) -> np.ndarray:
        if self._Uc is None:
            return self.coarse.solve(self._Ac, rc)
        return self.coarse.solve_free_update(self._Ac, self._all, rc, self._Uc, self._mu)

    def _power_lambda_max(self) -> float:
        """lambda_max of D^-1 K by the power method (enlarged by 1.1 in the smoother): from a fixed start,
        or, on a later setup of the same size, from the last estimate's vector (the Newton Hessians of
        one run change little between solves) with a third of the iterations."""
        n = self._A.shape[0]
        v, its = self._eigvec, max(1, self.smoother.power_iterations // 3)
        if v is None or v.shape != (n,):
            v, its = np.random.default_rng(0).standard_normal(n), self.smoother.power_iterations
        lam = 1.0
        for _ in range(its):
            w = self._inv_diag * self.apply(v)
            lam = float(np.linalg.norm(w) / np.linalg.norm(v))
            v = w / np.linalg.norm(w)
        self._eigvec = v
        return lam

    def _smooth(self, x: np.ndarray, b: np.ndarray, *, forward: bool, residual: np.ndarray | None = None) -> np.ndarray:
        """``sweeps`` smoothing steps on K x = b from x (``residual``: b - K x when known)."""
        s = self.smoother
        if s.kind == "sgs":
            from pyamg.relaxation.relaxation import gauss_seidel

            if self._U is not None:
                raise ValueError("the Gauss-Seidel smoother takes no low-rank term")
            for _ in range(s.sweeps):
                gauss_seidel(self._A, x, b, iterations=1, sweep="forward" if forward else "backward")
            return x
        # Chebyshev iteration on D^-1 K x = D^-1 b over [a, c] (Saad, Iterative Methods, alg. 12.1)
        c = 1.1 * self._lmax
        a = self._lmax / s.ratio
        theta, delta = 0.5 * (c + a), 0.5 * (c - a)
        sigma = theta / delta
        rho = 1.0 / sigma
        r = residual if residual is not None else (b - self.apply(x) if np.any(x) else b.copy())
        d = self._inv_diag * r / theta
        for k in range(s.sweeps):
            x = x + d
            if k == s.sweeps - 1:
                break
            r = r - self.apply(d)
            rho_new = 1.0 / (2.0 * sigma - rho)
            d = rho_new * rho * d + (2.0 * rho_new / delta) * (self._inv_diag * r)
            rho = rho_new
        return x


@dataclass(frozen=True, kw_only=True)
class MultigridConfig:
    """When :class:`MultigridSolver` solves by p-multigrid conjugate gradients instead of a factorization.

    For one-column solves of at least ``min_unknowns`` unknowns, CG preconditioned by
    :class:`TwoLevelP2` (a fresh setup per matrix: no earlier factorization needed) runs until the
    residual's 2-norm is at most ``rtol`` times the right-hand side's (the caller's rtol instead when
    it gives one, e.g. an inexact-Newton forcing term far from Newton's target; or the caller's
    absolute bound is met); a solve that does not converge within ``max_iter`` iterations (or would not, at the
    rate of the first :data:`simfab.solve.linear.ABORT_AFTER`) falls back to the factorization path.
    Negative curvature raises :class:`simfab.solve.linear.NotPositiveDefinite`, as a failed
    factorization does.

    Args:
        min_unknowns: the size from which the multigrid solve is tried first.
        rtol: relative residual (2-norm) of a converged solve.
        max_iter: CG iterations at most.
        smoother: :class:`SmootherConfig` (Chebyshev: it takes the pin's low-rank term).
    """

    min_unknowns: int = 75_000
    rtol: float = 1e-6
    max_iter: int = 60
    smoother: SmootherConfig = SmootherConfig(kind="chebyshev", sweeps=2)

    def __post_init__(self):
        ok = {"min_unknowns": self.min_unknowns >= 0, "rtol": 0.0 < self.rtol < 1.0, "max_iter": self.max_iter >= 1,
              "smoother": self.smoother.kind == "chebyshev"}
        bad = [k for k, v in ok.items() if not v]
        if bad:
            raise ValueError(f"invalid MultigridConfig: {', '.join(f'{k}={getattr(self, k)!r}' for k in bad)}")


class MultigridSolver(SPDSolver):
    """:class:`simfab.solve.linear.SPDSolver` (CHOLMOD) that solves large P2 systems by CG with the
    two-level p-multigrid preconditioner (:class:`MultigridConfig`) before lagging or factorizing.

    Args:
        prolongation: (n, n_c) the P1 -> P2 prolongation on all unknowns (:func:`corner_prolongation`
            without ``free``); its rows and columns are restricted to each free set.
        multigrid: :class:`MultigridConfig`.
        lag: as :class:`SPDSolver`'s (the fallback when the multigrid solve does not converge).

    Attributes ``multigrid_solves`` (converged), ``multigrid_iterations`` (every attempt's),
    ``coarse_factorizations``, besides SPDSolver's counters.
    """

    def __init__(self, prolongation: sp.csr_matrix, *, multigrid: MultigridConfig | None = None,
                 lag: LagConfig | None = None):
        super().__init__("cholmod", lag=lag)
        self.prolongation = sp.csr_matrix(prolongation)
        self.multigrid = multigrid or MultigridConfig()
        self.multigrid_solves = 0
        self.multigrid_iterations = 0
        self._mg = None  # (free, value map A.data -> A_ff.data, A_ff, TwoLevelP2, the pattern's index arrays)
        self._direct = False  # within SPDSolver.solve_free's own path
        self._coarse_done = 0  # factorizations of the coarse solvers of earlier free sets

    @property
    def coarse_factorizations(self) -> int:
        """Numeric factorizations of coarse matrices so far (attempts included)."""
        return self._coarse_done + (0 if self._mg is None else self._mg[3].coarse.factorizations)

    def solve_free(self, A, free, b, *, atol=None, rtol=None):
        x = self.solve_free_lagged(A, free, b, None, 0.0, atol, rtol)
        if x is not None:
            return x
        self._direct = True  # SPDSolver.solve_free asks solve_free_lagged again: tried already
        try:
            return super().solve_free(A, free, b)
        finally:
            self._direct = False

    def solve_free_lagged(self, A, free, b, U=None, mu=0.0, atol=None, rtol=None):
        """As :meth:`SPDSolver.solve_free_lagged` (the same arguments), with the p-multigrid solve in
        the order of their cost: a lagged solve on the current factorization first (a triangular
        solve per iteration), unless the factorization is stale (:attr:`SPDSolver.stale`); then
        p-multigrid CG; None when neither converged (the caller then factorizes)."""
        if self._direct:
            return None
        x = super().solve_free_lagged(A, free, b, U, mu, atol, rtol)  # (None on a stale factorization)
        if x is not None:
            return x
        return self._multigrid(A, free, b, U, mu, atol, rtol)

    def _refactor_after(self, n: int) -> int:
        # where p-multigrid would take over from a slow lagged solve (not a factorization), only a
        # failed one makes the factorization stale
        return self.lag.max_iter if n >= self.multigrid.min_unknowns else self.lag.refactor_after

    def _multigrid(self, A, free, b, U, mu, atol, rtol):
        """x of (A[free][:, free] + mu U U^T) x = b by p-multigrid CG, or None (not tried or not converged)."""
        cfg = self.multigrid
        free = np.asarray(free)
        b = np.asarray(b, dtype=np.float64)
        if b.ndim != 1 or len(free) < cfg.min_unknowns:
            return None
        A = canonical_csr(A)
        Aff, pre = self._restricted(A, free)
        try:
            self._setup(pre, Aff, U, mu)
        except NotPositiveDefinite:
            return None  # the direct path decides (its own shifts and exact-first fallback)
        bn = float(np.linalg.norm(b))
        if bn == 0.0:
            return np.zeros_like(b)
        tol = (cfg.rtol if rtol is None else rtol) * bn
        reach = max(tol, atol or 0.0)

        def converged(r, rn):
            return rn <= tol or (atol is not None and np.abs(r).max() <= atol)

        def give_up(k, rn):  # at this rate the iterations would not converge within max_iter
            return k >= 2 * ABORT_AFTER and k * np.log(reach / bn) / np.log(min(rn / bn, 1.0 - 1e-12)) > cfg.max_iter

        try:
            res = conjugate_gradients(pre.apply, pre, b, max_iter=cfg.max_iter, converged=converged, give_up=give_up)
        except NotPositiveDefinite:
            self.multigrid_iterations += 1
            raise
        self.multigrid_iterations += res.iterations
        if not res.converged:
            return None
        self.multigrid_solves += 1
        return res.x

    def _restricted(self, A: sp.csr_matrix, free: np.ndarray):
        """(A[free][:, free] with A's values, the TwoLevelP2 of this free set), the index maps cached
        per pattern and free set."""
        mg = self._mg
        if mg is None or not (mg[0].shape == free.shape and np.array_equal(mg[0], free) and mg[4] is not None
                              and mg[4][0].shape == A.indptr.shape and mg[4][1].shape == A.indices.shape
                              and np.array_equal(mg[4][0], A.indptr) and np.array_equal(mg[4][1], A.indices)):
            pos = sp.csr_matrix((np.arange(1.0, A.nnz + 1.0), A.indices, A.indptr), shape=A.shape)[free][:, free]
            pos = canonical_csr(pos)
            vmap = pos.data.astype(np.int64) - 1
            P = self.prolongation[free][:, free[free < self.prolongation.shape[1]]].tocsr()
            old = None if mg is None else mg[3]
            pre = TwoLevelP2(P, self.multigrid.smoother)
            if old is not None and old.P.shape == P.shape:
                pre.coarse = old.coarse  # its analysis is kept while the coarse pattern stays
            elif old is not None:
                self._coarse_done += old.coarse.factorizations
            Aff = sp.csr_matrix((A.data[vmap], pos.indices, pos.indptr), shape=pos.shape)
            mg = self._mg = (free.copy(), vmap, Aff, pre, (A.indptr.copy(), A.indices.copy()))
            return Aff, pre
        Aff = mg[2]
        Aff.data = A.data[mg[1]]
        return Aff, mg[3]

    def _setup(self, pre: TwoLevelP2, Aff, U, mu) -> None:
        """pre.setup with the smallest coarse shift of 0, COARSE_SHIFTS * mu that factorizes."""
        shifts = (0.0,) + (tuple(c * mu for c in COARSE_SHIFTS) if U is not None and mu > 0 else ())
        for shift in shifts:
            try:
                pre.setup(Aff, U, mu, shift)
                return
            except NotPositiveDefinite:
                if shift == shifts[-1]:
                    raise


def insertion_solver(model, *, lag: LagConfig | None = None, multigrid: MultigridConfig | None = None) -> SPDSolver:
    """The sparse solver of a simulation on ``model``: a :class:`MultigridSolver` for a quadratic
    model (one with ``n_corners`` and ``edges``, :class:`simfab.fem.p2.P2Model`), else an
    :class:`simfab.solve.linear.SPDSolver`; both with ``lag``.

    Args:
        model: the FEM model whose Hessians the solver receives (unknown ``node * dim + k``).
        lag: :class:`simfab.solve.linear.LagConfig` or None.
        multigrid: :class:`MultigridConfig` (None: its defaults).

    Returns:
        The solver.
    """
    if getattr(model, "n_corners", None) is None or getattr(model, "edges", None) is None:
        return SPDSolver(lag=lag)
    P = corner_prolongation(int(model.n_corners), np.asarray(model.edges), int(model.dim))
    return MultigridSolver(P, multigrid=multigrid, lag=lag)
