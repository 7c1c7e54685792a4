"""Sparse symmetric positive-definite solves.

CHOLMOD (through ``cvxopt.cholmod``, which bundles SuiteSparse, so it installs with pip)
is the default: it is several times faster than SuperLU on 3D elasticity systems, and as fast
per core as MKL PARDISO on them once its BLAS uses the machine's vector instructions (see
:func:`import_cholmod`; ``tools/bench.py linear_solvers`` compares the libraries). The symbolic
analysis (fill-reducing ordering) and the value map are kept and reused while the sparsity
pattern is unchanged, which is the case across Newton iterations of one simulation; a matrix
whose values equal those of the last factorization is not factorized again. Large systems (and any
once a pinned solve has needed a diagonal shift) can lag the factorization (:class:`LagConfig`): a
new matrix is first solved by conjugate gradients preconditioned with the current factorization,
and factorized only when that does not converge.

    solver = SPDSolver()
    x = solver.solve(A, b)      # A: scipy.sparse (n, n) SPD, b: (n,) or (n, k)
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from simfab._sparse import csr_matvec
from simfab.errors import ConvergenceError


def import_cholmod():
    """``cvxopt.cholmod``, imported so that its BLAS uses the machine's vector instructions.

    cvxopt's wheel bundles OpenBLAS 0.3.15 (single-threaded, runtime kernel choice), which does
    not recognize CPUs newer than itself and then falls back to its oldest x86-64 kernels
    ("Prescott", SSE3), which doubles CHOLMOD's factorization time on recent Xeons
    (docs/decisions.md, "Sparse factorization"). When the CPU has AVX2 and FMA and the
    user has not chosen a kernel set (OPENBLAS_CORETYPE), the Haswell kernels are selected for
    that library: OpenBLAS reads the variable once, when cvxopt loads it, so it is set only
    around the first import and the process environment is left as it was."""
    global _CHOLMOD
    if _CHOLMOD is not None:
        return _CHOLMOD
    import sys

    if "cvxopt" not in sys.modules and "OPENBLAS_CORETYPE" not in os.environ and has_avx2_fma():
        os.environ["OPENBLAS_CORETYPE"] = "Haswell"
        try:
            import cvxopt.cholmod
        finally:
            del os.environ["OPENBLAS_CORETYPE"]
    import cvxopt.cholmod

    _CHOLMOD = cvxopt.cholmod
    return _CHOLMOD


_CHOLMOD = None  # cvxopt.cholmod once imported (import_cholmod runs on every factorization and solve)


def has_avx2_fma() -> bool:
    """Whether this CPU has AVX2 and FMA (the Haswell kernels of OpenBLAS run on it).

    Returns:
        True on Linux when /proc/cpuinfo lists both flags; False otherwise (and off Linux).
    """
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("flags"):
                    flags = set(line.split(":", 1)[1].split())
                    return {"avx2", "fma"} <= flags
    except OSError:  # not Linux: leave OpenBLAS's own choice
        pass
    return False


class NotPositiveDefinite(ConvergenceError):
    """The matrix handed to :class:`SPDSolver` is not numerically positive definite."""


#: A lagged solve whose residual has not fallen fast enough to reach its tolerance within
#: ``LagConfig.max_iter`` iterations (at the mean rate so far) is given up after this many.
ABORT_AFTER = 3


@dataclass(frozen=True, kw_only=True)
class LagConfig:
    """Lagged factorization of :class:`SPDSolver` (inexact Newton with a reused preconditioner).

    For systems of at least ``min_unknowns`` unknowns, a one-column solve of a matrix of the analysed
    pattern whose values differ from the current factorization's is first done by conjugate
    gradients on that matrix, preconditioned with the current factorization (the Newton Hessians of
    one simulation change little from one solve to the next), until the residual's 2-norm is at most
    ``rtol`` times the right-hand side's (or a caller's absolute bound is met); only when that takes
    more than ``max_iter`` iterations (or would, at the rate of the first :data:`ABORT_AFTER`) is
    the matrix factorized (and solved directly). A solve that converged in more than
    ``refactor_after`` iterations leaves the factorization stale: the next new matrix is factorized
    instead of iterated on (each solve on a drifting preconditioner takes more iterations, and a
    factorization costs about 2 x refactor_after iterations' triangular solves and products on the
    insertion's P2 systems, 2D and 3D: docs/decisions.md, "Refactorizing a slow preconditioner").
    A curvature p^T A p <= 0 met by the iterations proves the matrix indefinite and raises
    :class:`NotPositiveDefinite`, as a failed factorization does. Below ``min_unknowns`` (where a
    factorization costs few triangular solves) every new matrix is factorized, unless ``when_shifted``
    and the solver's ``shift_hint`` is set: a pinned solve (:class:`simfab.coupling.rigid.PinnedSolver`)
    has needed a diagonal shift, so every solve is already conjugate gradients preconditioned by a
    factorization that is not the matrix's own, and an older one serves nearly as well."""

    min_unknowns: int = 50_000
    rtol: float = 1e-6
    max_iter: int = 12
    refactor_after: int = 5
    when_shifted: bool = True

    def __post_init__(self):
        bad = [k for k, ok in {"min_unknowns": self.min_unknowns >= 0, "rtol": 0.0 < self.rtol < 1.0,
                               "max_iter": self.max_iter >= 1,
                               "refactor_after": self.refactor_after >= 1}.items() if not ok]
        if bad:
            raise ValueError(f"invalid LagConfig: {', '.join(f'{k}={getattr(self, k)!r}' for k in bad)}")


@dataclass(frozen=True)
class CGResult:
    """What :func:`conjugate_gradients` ended with: the iterate x, its residual's 2-norm, the
    iterations taken and whether the caller's convergence test was met."""

    x: np.ndarray
    residual: float
    iterations: int
    converged: bool


def conjugate_gradients(apply, precondition, b: np.ndarray, *, max_iter: int, converged, give_up=None,
                        z: np.ndarray | None = None) -> CGResult:
    """Preconditioned conjugate gradients on K x = b from x = 0, for a K known only by its products.

    Hand-written rather than scipy's ``cg`` for the curvature test: p^T K p <= 0 proves K not
    positive definite, which the callers treat as a failed factorization.

    Args:
        apply: v -> K v.
        precondition: r -> M^-1 r (M an approximation of K).
        b: (n,) right-hand side.
        max_iter: iterations at most.
        converged: (r, |r|_2) -> bool, tested after every iteration.
        give_up: None, or (iteration k, |r|_2) -> bool: stop unconverged (e.g. too slow a rate).
        z: M^-1 b when the caller has it already.

    Returns:
        :class:`CGResult`. Raises :class:`NotPositiveDefinite` on a non-positive curvature.
    """
    x = np.zeros_like(b)
    r = b.copy()
    z = precondition(r) if z is None else z
    p = z.copy()
    rz = float(r @ z)
    rn = float(np.linalg.norm(b))
    for k in range(1, max_iter + 1):
        Kp = apply(p)
        pKp = float(p @ Kp)
        if not pKp > 0.0:
            raise NotPositiveDefinite("the matrix is not positive definite (negative curvature in conjugate gradients)")
        a = rz / pKp
        x += a * p
        r -= a * Kp
        rn = float(np.linalg.norm(r))
        if converged(r, rn):
            return CGResult(x, rn, k, True)
        if give_up is not None and give_up(k, rn):
            return CGResult(x, rn, k, False)
        z = precondition(r)
        rz, rz_old = float(r @ z), rz
        p = z + (rz / rz_old) * p
    return CGResult(x, rn, max_iter, False)


def canonical_csr(A) -> sp.csr_matrix:
    """``A`` as CSR with sorted, unique entries (a copy only when needed; the caller's matrix is
    never mutated). Value maps that gather ``A.data`` by position rely on this."""
    A = A if isinstance(A, sp.csr_matrix) else sp.csr_matrix(A)
    if not A.has_canonical_format:
        A = A.copy()
        A.sum_duplicates()
    return A


def free_block_map(A: sp.csr_matrix, free: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the block ``A[free][:, free]`` of a CSR matrix A (n, n) takes its entries from, without
    building it, for unique ``free`` (m,) indices.

    Renumbering rows and columns by an ascending subset keeps the order of A's entries, so for
    ascending ``free`` the block's entries are A's entries with both indices free, in A's order (row by
    row; within a row in A's column order, sorted when A's are); in any other order they are sorted by
    block row, then block column.

    Returns:
        (sel (k,) int64 positions of the block's entries in ``A.data``, the block's indptr (m + 1,)
        and indices (k,), both int32).
    """
    new = np.full(A.shape[0], -1, dtype=np.int32)
    new[free] = np.arange(len(free), dtype=np.int32)
    rows = np.repeat(new, np.diff(A.indptr))  # each entry's block row (-1: not free)
    cols = new[A.indices]
    sel = np.flatnonzero((rows >= 0) & (cols >= 0))
    if len(free) > 1 and not (free[1:] > free[:-1]).all():
        sel = sel[np.lexsort((cols[sel], rows[sel]))]
    counts = np.bincount(rows[sel], minlength=len(free))
    indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
    return sel, indptr, cols[sel]


def same_pattern(key, A: sp.csr_matrix) -> bool:
    """Whether CSR ``A`` has the pattern ``key = (indptr, indices)`` (None: no pattern yet)."""
    if key is None:
        return False
    indptr, indices = key
    return (indptr.shape == A.indptr.shape and indices.shape == A.indices.shape
            and np.array_equal(indptr, A.indptr) and np.array_equal(indices, A.indices))


class SPDSolver:
    """Cholesky solver for sparse SPD matrices, specialised for repeated solves with one pattern.

    With CHOLMOD, the map from the CSR values to CHOLMOD's lower-triangle CSC order and the
    symbolic analysis are computed once per sparsity pattern; each later solve only gathers
    the values, refactorizes numerically (skipped when the values are those of the last
    factorization: Newton's predictor can hand the same Hessian twice) and solves, so the
    per-call overhead of small systems stays below the factorization itself. A new pattern
    triggers a new analysis.

    Args:
        backend: "cholmod" | "splu" | "auto"
            "auto" uses CHOLMOD when cvxopt is importable, else SciPy's SuperLU.
        lag: None (every new matrix is factorized), or the :class:`LagConfig` of lagged
            factorizations in :meth:`solve_free` and :meth:`solve_free_lagged` (CHOLMOD only).

    Attribute ``timer``: None, or an object with ``timed(key)`` returning a context manager (e.g.
    :class:`simfab.coupling.timing.Timer`); each numeric factorization is then timed under
    "factorization". Attribute ``factorizations``: the numeric factorizations attempted so far;
    ``lagged_solves`` / ``pcg_iterations``: the solves done by lagged conjugate gradients (converged)
    and the iterations of every lagged attempt (converged or not).

    CHOLMOD's input is the lower triangle in column-major order, which for a symmetric matrix is
    the upper triangle of its CSR in row-major order: the value map takes the CSR entries on and
    above the diagonal, in their storage order, so each gather reads ``A.data`` front to back (several
    times faster than a random-order gather: docs/decisions.md, "Sparse factorization").
    """

    def __init__(self, backend: str = "auto", lag: LagConfig | None = None):
        if backend == "auto":
            try:
                import_cholmod()
                backend = "cholmod"
            except ImportError:  # pragma: no cover - cvxopt is a dependency
                backend = "splu"
        if backend not in ("cholmod", "splu"):
            raise ValueError(f"unknown linear-solver backend {backend!r}")
        self.backend = backend
        self.lag = lag if backend == "cholmod" else None
        self._key = None  # (indptr, indices) of the analysed CSR pattern
        self._perm = None  # CSR value index of each CHOLMOD (lower, column-major) entry
        self._inv_d = None  # D^-1 of the current factorization (n, 1)
        self._lu = None  # splu backend: the last factorization
        self._A = None  # cvxopt spmatrix holding the lower triangle
        self._F = None  # CHOLMOD symbolic (then numeric) factor
        self._factored = None  # the values of the current numeric factorization (None: none)
        self._spare = None  # an array of _factored's size, reused for the next gather (see _values)
        self._stale = False  # a lagged solve on the current factorization was slow or failed (see LagConfig)
        # solve_free: (full pattern key, free indices, value map full -> factor input, the index
        # arrays (indptr, indices) last seen with that key)
        self._full = None
        self._diag = None  # positions of the diagonal entries in the factor's input (values) order
        self._update = None  # solve_free_update: (factor values, U, mu, L^-1 P U, D^-1 L^-1 P U, capacitance)
        self.timer = None
        self.factorizations = 0
        self.lagged_solves = 0
        self.pcg_iterations = 0
        #: the diagonal shift (relative to the pin's stiffness) a :class:`simfab.coupling.rigid.PinnedSolver`
        #: last needed to factorize with this solver (0: none); its later solves start from it
        self.shift_hint = 0.0

    def solve(self, A: sp.spmatrix, b: np.ndarray) -> np.ndarray:
        """Solve ``A x = b`` for SPD ``A`` (n, n) and ``b`` (n,) or (n, k); returns x shaped like b.

        Raises :class:`NotPositiveDefinite` when the factorization fails.
        """
        b = np.asarray(b, dtype=np.float64)
        if self.backend == "splu":
            from scipy.sparse.linalg import splu

            lu = splu(sp.csc_matrix(A), permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})
            return lu.solve(b)
        return self._solve_cholmod(A, b)

    def solve_free(self, A: sp.spmatrix, free: np.ndarray, b: np.ndarray, *, atol: float | None = None,
                   rtol: float | None = None) -> np.ndarray:
        """Solve ``A[free][:, free] x = b`` without forming the submatrix: ``free`` (m,) int indices
        of the unknowns, ``b`` (m,) or (m, k). With CHOLMOD, the map from ``A``'s values straight to
        the factor's input order is computed once per (pattern, free set), so each later call is
        one gather and a numeric factorization (Newton on the free dofs of a fixed FEM pattern).
        ``atol`` and ``rtol`` bound a lagged solve's residual as in :meth:`solve_free_lagged` (a
        factorization's solve is exact).
        Raises :class:`NotPositiveDefinite` when the factorization fails (or, lagging, when the
        iterations meet negative curvature)."""
        if self.lag is not None:
            x = self.solve_free_lagged(A, free, b, atol=atol, rtol=rtol)
            if x is not None:
                return x
        self._factor_free(A, free)
        if self.backend == "splu":
            return self._lu.solve(np.asarray(b, dtype=np.float64))
        return self._solve_factored(np.asarray(b, dtype=np.float64))

    def solve_free_update(self, A: sp.spmatrix, free: np.ndarray, b: np.ndarray, U: np.ndarray,
                          mu: float, shift: float = 0.0) -> np.ndarray:
        """Solve ``(A[free][:, free] + shift I + mu U U^T) x = b`` (U (m, r) dense, mu > 0 [units of
        A], shift >= 0 [units of A], b (m,) or (m, k)) with one sparse factorization of ``A``'s block
        plus the shift (Woodbury).

        With CHOLMOD's factor P A P^T = L D L^T (D = I for a supernodal L L^T) and the half solves
        f(v) = L^-1 P v, g(v) = P^T L^-T v (so A^-1 = g D^-1 f): V = f(U), v = f(b),
        c = (I/mu + V^T D^-1 V)^-1 V^T D^-1 v and x = g(D^-1 (v - V c)). The r columns of U pass
        through the forward half only, so the update costs r/2 solves instead of r.
        Raises :class:`NotPositiveDefinite` when the factorization fails."""
        b = np.asarray(b, dtype=np.float64)
        U = np.asarray(U, dtype=np.float64)
        self._factor_free(A, free, shift)
        k = 1 if b.ndim == 1 else b.shape[1]
        if self.backend == "splu":
            X = self._lu.solve(np.column_stack([b.reshape(len(b), k), U]))
            y, Z = X[:, :k], X[:, k:]
            return (y - Z @ np.linalg.solve(np.eye(U.shape[1]) / mu + U.T @ Z, U.T @ y)).reshape(b.shape)
        return self._woodbury(b, U, mu)

    def solve_factored_update(self, b: np.ndarray, U: np.ndarray, mu: float) -> np.ndarray:
        """Solve ``(F + mu U U^T) x = b`` with F the matrix of the current factorization (the last
        :meth:`solve_free_update`'s block with its shift, or :meth:`solve_free`'s): no gather of values,
        no comparison with the factorized ones (an iterative solve's preconditioner, applied many times
        per factorization). With CHOLMOD the half solve of U is reused while U and the factor are the same.

        Args:
            b: (m,) or (m, k) right-hand side.
            U: (m, r) dense update columns.
            mu: the update's weight > 0 [units of F].

        Returns:
            x shaped like b. Raises RuntimeError when nothing has been factorized yet.
        """
        b = np.asarray(b, dtype=np.float64)
        if self.backend == "splu":
            if self._lu is None:
                raise RuntimeError("solve_factored_update: no factorization yet")
            k = 1 if b.ndim == 1 else b.shape[1]
            X = self._lu.solve(np.column_stack([b.reshape(len(b), k), U]))
            y, Z = X[:, :k], X[:, k:]
            return (y - Z @ np.linalg.solve(np.eye(U.shape[1]) / mu + U.T @ Z, U.T @ y)).reshape(b.shape)
        if self._factored is None:
            raise RuntimeError("solve_factored_update: no factorization yet")
        return self._woodbury(b, np.asarray(U, dtype=np.float64), mu)

    def solve_free_lagged(self, A: sp.spmatrix, free: np.ndarray, b: np.ndarray, U: np.ndarray | None = None,
                          mu: float = 0.0, atol: float | None = None, rtol: float | None = None) -> np.ndarray | None:
        """The lagged solve of ``(A[free][:, free] + mu U U^T) x = b`` (see :class:`LagConfig`; U (m, r)
        dense or None, mu [units of A], b (m,)): conjugate gradients preconditioned with the current
        factorization (with U's Woodbury update when U is given), to ``rtol`` (None: ``LagConfig.rtol``;
        e.g. an inexact-Newton forcing term far from the target) or until the residual's largest entry
        is at most ``atol`` [units of b] (None: rtol only; e.g. a fraction of Newton's force target,
        below which the residual cannot matter). Returns x, or None when the solve is not lagged (no lag
        configured, too few unknowns and no shift, no factorization of this pattern and free set yet, b
        with several columns), the factorization is stale (:attr:`stale`) or the iterations did not
        converge: the caller then factorizes. A matrix equal to the factorized one is solved directly.
        Raises :class:`NotPositiveDefinite` when the iterations meet negative curvature."""
        lag = self.lag
        free = np.asarray(free)
        b = np.asarray(b, dtype=np.float64)
        if lag is None or b.ndim != 1 or self._factored is None:
            return None
        if len(free) < lag.min_unknowns and not (lag.when_shifted and self.shift_hint):
            return None
        A, known = self._analysed(A, free)
        if not known:
            return None
        values = self._values(A)
        if U is None:
            def precondition(r):
                return self._solve_factored(r)
        else:
            U = np.asarray(U, dtype=np.float64)

            def precondition(r):
                return self._woodbury(r, U, mu)
        if np.array_equal(values, self._factored):
            return precondition(b)
        if self._stale:
            return None
        x = self._pcg(A, free, b, precondition, U, mu, atol, lag.rtol if rtol is None else rtol)
        if x is not None:
            self.lagged_solves += 1
        return x

    @property
    def stale(self) -> bool:
        """A lagged solve on the current factorization took more than ``LagConfig.refactor_after``
        iterations or did not converge: later lagged solves are not tried on it (reset by the next
        factorization)."""
        return self._stale

    def _pcg(self, A: sp.csr_matrix, free: np.ndarray, b: np.ndarray, precondition, U: np.ndarray | None,
             mu: float, atol: float | None, rtol: float):
        """Conjugate gradients on (A[free][:, free] + mu U U^T) x = b (A the whole CSR: its product with
        a vector zero off ``free``, no submatrix or transpose built); None when not converged in
        ``lag.max_iter`` iterations."""
        n = len(b)
        v_full = np.zeros(A.shape[0])

        def apply(v):
            v_full[free] = v
            y = csr_matvec(A, v_full)[free]
            if U is not None:
                y += mu * (U @ (U.T @ v))
            return y

        bn = float(np.linalg.norm(b))
        if bn == 0.0:
            return np.zeros(n)
        tol = rtol * bn
        reach = max(tol, atol or 0.0)  # a 2-norm that meets either criterion

        def converged(r, rn):
            return rn <= tol or (atol is not None and np.abs(r).max() <= atol)

        def give_up(k, rn):  # at this rate the iterations would not converge within max_iter
            return k >= ABORT_AFTER and k * np.log(reach / bn) / np.log(min(rn / bn, 1.0 - 1e-12)) > self.lag.max_iter

        try:
            res = conjugate_gradients(apply, precondition, b, max_iter=self.lag.max_iter, converged=converged,
                                      give_up=give_up)
        except NotPositiveDefinite:
            self.pcg_iterations += 1
            raise
        self.pcg_iterations += res.iterations
        self._stale = not res.converged or res.iterations > self._refactor_after(n)
        return res.x if res.converged else None

    def _refactor_after(self, n: int) -> int:
        """Lagged iterations after which an n-unknown system's factorization is stale (see :class:`LagConfig`)."""
        return self.lag.refactor_after

    def _analysed(self, A, free: np.ndarray):
        """(A as canonical CSR, whether its pattern and the free set are those of the analysis)."""
        full = self._full
        # a model's Hessians share its pattern's index arrays (never modified in place): the same
        # arrays as last time need no comparison
        same = full is not None and getattr(A, "indices", None) is full[3][1] and A.indptr is full[3][0]
        if not same:
            A = canonical_csr(A)
        known = full is not None and full[1].shape == free.shape and np.array_equal(full[1], free) and (
            same or same_pattern(full[0], A))
        return A, known

    def _woodbury(self, b: np.ndarray, U: np.ndarray, mu: float) -> np.ndarray:
        """(F + mu U U^T)^-1 b, F the current factorization's matrix (see :meth:`solve_free_update`)."""
        k = 1 if b.ndim == 1 else b.shape[1]
        upd = self._update
        if upd is not None and upd[0] is self._factored and upd[1] is U and upd[2] == mu:
            V, DV, S = upd[3:]  # the same factorization and U: their half solve is reused
            v = self._half(b.reshape(len(b), k), forward=True)
        else:
            F = self._half(np.column_stack([b.reshape(len(b), k), U]), forward=True)
            v, V = F[:, :k], F[:, k:]
            DV = self._inv_d * V
            S = np.eye(U.shape[1]) / mu + V.T @ DV
            self._update = (self._factored, U, mu, V, DV, S)
        Dv = self._inv_d * v
        c = np.linalg.solve(S, V.T @ Dv)
        return self._half(Dv - DV @ c, forward=False).reshape(b.shape)

    def _factor_free(self, A: sp.spmatrix, free: np.ndarray, shift: float = 0.0) -> None:
        """Factorize ``A[free][:, free] + shift I`` numerically (see :meth:`solve_free`)."""
        free = np.asarray(free)
        if self.backend == "splu":
            from scipy.sparse.linalg import splu

            A = canonical_csr(A)
            Af = A[free][:, free] + shift * sp.identity(len(free), format="csr") if shift else A[free][:, free]
            self._lu = splu(sp.csc_matrix(Af), permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})
            return
        A, known = self._analysed(A, free)
        full = self._full
        if not known:
            sel, indptr, indices = free_block_map(A, free)  # (A canonical: so is the block's pattern)
            self._analyse(sp.csr_matrix((A.data[sel], indices, indptr), shape=(len(free),) * 2))
            composed = sel[self._perm]
            full = self._full = ((A.indptr.copy(), A.indices.copy()), free.copy(), composed, (A.indptr, A.indices))
        elif A.indices is not full[3][1] or A.indptr is not full[3][0]:  # the same pattern in new arrays
            full = self._full = full[:3] + ((A.indptr, A.indices),)
        values = self._values(A)
        if shift:
            values[self._diag] += shift
        self._ensure_factor(values)

    def _values(self, A) -> np.ndarray:
        """A's values gathered into the factor's input order (the value map of :meth:`_factor_free`), in
        the solver's spare array: a lagged solve only compares them with the factorized ones, and a
        factorization keeps them and hands back its previous array as the spare (:meth:`_ensure_factor`).
        A new array of a large factor's size costs its page faults at every gather (docs/benchmarks.md, 3m)."""
        idx = self._full[2]
        spare = self._spare
        if spare is None or spare.shape != idx.shape:
            spare = self._spare = np.empty(idx.shape)
        return np.take(A.data, idx, out=spare, mode="clip")  # (valid indices; "raise" would buffer the output)

    def _solve_cholmod(self, A, b):
        A = canonical_csr(A)  # the value map gathers one value per entry
        if not same_pattern(self._key, A):
            self._analyse(A)
        self._ensure_factor(A.data[self._perm])
        return self._solve_factored(b)

    def _ensure_factor(self, values: np.ndarray) -> None:
        """Numeric factorization of the analysed pattern with ``values`` (CHOLMOD's input order; the
        solver keeps the array, which the caller must not modify afterwards), unless they are those of
        the current factorization."""
        if self._factored is None or not np.array_equal(values, self._factored):
            old, self._factored, self._update = self._factored, None, None
            if self.timer is None:
                self._factor(values)
            else:
                with self.timer.timed("factorization"):
                    self._factor(values)
            self._factored = values
            if values is self._spare:  # the previous values are the next gather's array
                self._spare = old if old is not None and old.shape == values.shape else None

    def _solve_factored(self, b: np.ndarray) -> np.ndarray:
        """x = A^-1 b with the current factorization, b (n,) or (n, k)."""
        import cvxopt

        cholmod = import_cholmod()
        x = cvxopt.matrix(np.ascontiguousarray(b.reshape(self._A.size[0], -1)))
        cholmod.solve(self._F, x)
        return np.array(x).reshape(b.shape)

    def _half(self, B: np.ndarray, *, forward: bool) -> np.ndarray:
        """f(B) = L^-1 P B (``forward``) or g(B) = P^T L^-T B with the current factor, B (n, k)."""
        import cvxopt

        cholmod = import_cholmod()
        x = cvxopt.matrix(np.ascontiguousarray(B))
        for sys in ((7, 4) if forward else (5, 8)):  # CHOLMOD_P, CHOLMOD_L / CHOLMOD_Lt, CHOLMOD_Pt
            cholmod.solve(self._F, x, sys=sys)
        return np.array(x)

    def _factor(self, values: np.ndarray) -> None:
        """Numeric Cholesky factorization; NotPositiveDefinite when a pivot is not positive."""
        import cvxopt

        self.factorizations += 1
        self._stale = False
        cholmod = import_cholmod()
        self._A.V = cvxopt.matrix(values)
        try:
            cholmod.numeric(self._A, self._F)
        except ArithmeticError as e:
            raise NotPositiveDefinite("Cholesky factorization failed: matrix is not positive definite") from e
        # a simplicial factor is L D L^T, which succeeds on indefinite matrices too: positive
        # definite only when every pivot of D is positive (a supernodal L L^T has a positive
        # diagonal whenever it succeeds)
        inv_d = cvxopt.matrix(1.0, (self._A.size[0], 1))
        cholmod.solve(self._F, inv_d, sys=6)  # D^-1 1 (D = I for L L^T)
        inv_d = np.array(inv_d)
        if not (np.count_nonzero(np.isfinite(inv_d)) == inv_d.size and inv_d.min(initial=np.inf) > 0.0):
            raise NotPositiveDefinite("Cholesky factorization failed: matrix is not positive definite")
        self._inv_d = inv_d  # (n, 1) D^-1 of the factor (ones for L L^T), for solve_free_update

    def _analyse(self, A: sp.csr_matrix) -> None:
        self._full = None  # a value map built on the previous analysis no longer applies
        self._factored = None
        n = A.shape[0]
        rows = np.repeat(np.arange(n), np.diff(A.indptr))
        cols = A.indices
        # CHOLMOD reads the lower triangle column by column (rows ascending within a column); its
        # entry (i, j), i >= j, is A[j, i] of the symmetric A, the upper triangle's entry in CSR row j:
        # the upper triangle in CSR storage order (rows j, columns i ascending) is CHOLMOD's order
        self._perm = np.flatnonzero(cols >= rows)
        c, r = rows[self._perm], cols[self._perm]
        self._diag = np.flatnonzero(c == r)  # the diagonal's entries in the factor's input order
        cholmod = import_cholmod()
        import cvxopt

        self._A = cvxopt.spmatrix(cvxopt.matrix(A.data[self._perm]), cvxopt.matrix(r.astype(np.int64)),
                                  cvxopt.matrix(c.astype(np.int64)), (n, n))
        # CHOLMOD's own choice (supernodal when the flops per factor entry are high): simplicial on
        # small 2D systems, supernodal on 3D ones (docs/decisions.md, "Sparse factorization")
        cholmod.options["supernodal"] = 1
        self._F = cholmod.symbolic(self._A)
        self._key = (A.indptr.copy(), A.indices.copy())
