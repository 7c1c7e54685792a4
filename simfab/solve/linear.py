"""Sparse symmetric positive-definite solves.

Two sparse Cholesky libraries, each where it is fastest (``tools/bench.py linear_solvers``):

- MKL PARDISO (:mod:`simfab.solve.pardiso`, the ``mkl`` wheel) for systems of at least
  :data:`PARDISO_MIN_DOFS` unknowns: its METIS ordering and multithreaded supernodal
  factorization take 1/2 to 1/5 of CHOLMOD's time on 3D elasticity systems (knocker3d with
  quadratic tets: 23,676 dofs, 0.22-0.26 s of CPU per factorization on one core instead of
  0.53 s, and it runs on both cores);
- CHOLMOD (``cvxopt.cholmod``, which bundles SuiteSparse, so it installs with pip) below that,
  where PARDISO's fixed cost per call (about 1 ms) outweighs its faster kernels (2D coupling
  meshes of ~1,000 dofs, solved thousands of times by the rest-shape optimizer), and everywhere
  when MKL is missing (it has wheels for x86-64 only).

Both are several times faster than SuperLU on 3D elasticity systems. The symbolic analysis
(fill-reducing ordering) and the value map are kept and reused while the sparsity pattern is
unchanged, which is the case across Newton iterations of one simulation; a matrix whose values
equal those of the last factorization is not factorized again.

    solver = SPDSolver()
    x = solver.solve(A, b)      # A: scipy.sparse (n, n) SPD, b: (n,) or (n, k)
"""

from __future__ import annotations

import os

import numpy as np
import scipy.sparse as sp

from simfab.errors import ConvergenceError

#: Systems with at least this many unknowns are factorized with MKL PARDISO when it is installed,
#: smaller ones with CHOLMOD (measured crossover: PARDISO is 0.55x CHOLMOD's speed at 1,000 dofs,
#: 1.1x at 3,000-7,000, 1.6-8x from 17,000 on; tools/benchmarks/linear_solvers.py)
PARDISO_MIN_DOFS = 4000


def import_cholmod():
    """``cvxopt.cholmod``, imported so that its BLAS uses the machine's vector instructions.

    cvxopt's wheel bundles OpenBLAS 0.3.15 (single-threaded, runtime kernel choice), which does
    not recognize CPUs newer than itself and then falls back to its oldest x86-64 kernels
    ("Prescott", SSE3): on this project's Xeon machines that doubles CHOLMOD's factorization time
    (knocker3d P2 Hessian: 0.56 s instead of 0.27 s of CPU). When the CPU has AVX2 and FMA and the
    user has not chosen a kernel set (OPENBLAS_CORETYPE), the Haswell kernels are selected for
    that library: OpenBLAS reads the variable once, when cvxopt loads it, so it is set only
    around the first import and the process environment is left as it was."""
    import sys

    if "cvxopt" not in sys.modules and "OPENBLAS_CORETYPE" not in os.environ and _has_avx2_fma():
        os.environ["OPENBLAS_CORETYPE"] = "Haswell"
        try:
            import cvxopt.cholmod
        finally:
            del os.environ["OPENBLAS_CORETYPE"]
    import cvxopt.cholmod

    return cvxopt.cholmod


def _has_avx2_fma() -> bool:
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


def canonical_csr(A) -> sp.csr_matrix:
    """``A`` as CSR with sorted, unique entries (a copy only when needed; the caller's matrix is
    never mutated). Value maps that gather ``A.data`` by position rely on this."""
    A = A if isinstance(A, sp.csr_matrix) else sp.csr_matrix(A)
    if not A.has_canonical_format:
        A = A.copy()
        A.sum_duplicates()
    return A


def same_pattern(key, A: sp.csr_matrix) -> bool:
    """Whether CSR ``A`` has the pattern ``key = (indptr, indices)`` (None: no pattern yet)."""
    if key is None:
        return False
    indptr, indices = key
    return (indptr.shape == A.indptr.shape and indices.shape == A.indices.shape
            and np.array_equal(indptr, A.indptr) and np.array_equal(indices, A.indices))


class SPDSolver:
    """Cholesky solver for sparse SPD matrices, specialised for repeated solves with one pattern.

    The map from the CSR values to the factor's input order (the lower triangle column after
    column, which for a symmetric matrix is also the upper triangle row after row: CHOLMOD's
    and PARDISO's inputs hold the same values in the same order) and the symbolic analysis are
    computed once per sparsity pattern; each later solve only gathers the values, refactorizes
    numerically (skipped when the values are those of the last factorization) and solves, so
    the per-call overhead of small systems stays below the factorization itself. A new
    pattern triggers a new analysis.

    Parameters
    ----------
    backend : "auto" | "cholmod" | "pardiso" | "splu"
        "auto": MKL PARDISO for patterns of at least PARDISO_MIN_DOFS unknowns when MKL is
        installed, CHOLMOD otherwise. The others force one library (tests, benchmarks).
    """

    def __init__(self, backend: str = "auto"):
        if backend not in ("auto", "cholmod", "pardiso", "splu"):
            raise ValueError(f"unknown linear-solver backend {backend!r}")
        if backend == "pardiso":
            from simfab.solve import pardiso

            if not pardiso.available():
                raise ValueError("linear-solver backend 'pardiso' needs MKL (pip install mkl)")
        self.backend = backend
        self._key = None  # (indptr, indices) of the analysed CSR pattern
        self._perm = None  # CSR value index of each factor-input entry (lower triangle, column-major)
        self._A = None  # CHOLMOD: cvxopt spmatrix holding the lower triangle
        self._F = None  # CHOLMOD symbolic (then numeric) factor, or a simfab.solve.pardiso.PardisoCholesky
        self._factored = None  # copy of the values of the current numeric factorization (None: none)
        self._full = None  # solve_free: (full pattern key, free indices, value map full -> factor input)

    @property
    def library(self) -> str | None:
        """The library of the current analysis: "cholmod", "pardiso", "splu", or None before the first solve."""
        if self.backend == "splu":
            return "splu"
        if self._F is None:
            return None
        return "cholmod" if self._A is not None else "pardiso"

    def solve(self, A: sp.spmatrix, b: np.ndarray) -> np.ndarray:
        """Solve ``A x = b`` for SPD ``A`` (n, n) and ``b`` (n,) or (n, k); returns x shaped like b.

        Raises :class:`NotPositiveDefinite` when the factorization fails.
        """
        b = np.asarray(b, dtype=np.float64)
        if self.backend == "splu":
            from scipy.sparse.linalg import splu

            lu = splu(sp.csc_matrix(A), permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})
            return lu.solve(b)
        return self._solve_factored(A, b)

    def solve_free(self, A: sp.spmatrix, free: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Solve ``A[free][:, free] x = b`` without forming the submatrix: ``free`` (m,) int indices
        of the unknowns, ``b`` (m,) or (m, k). The map from ``A``'s values straight to the factor's
        input order is computed once per (pattern, free set), so each later call is one gather and
        a numeric factorization (Newton on the free dofs of a fixed FEM pattern; SuperLU extracts
        the block).
        Raises :class:`NotPositiveDefinite` when the factorization fails."""
        free = np.asarray(free)
        A = canonical_csr(A)
        if self.backend == "splu":
            return self.solve(A[free][:, free], b)
        full = self._full
        if full is None or not (full[1].shape == free.shape and np.array_equal(full[1], free)
                                and same_pattern(full[0], A)):
            # positions (+1, so that no entry is an explicit zero) of A's values in the submatrix
            pos = sp.csr_matrix((np.arange(1.0, A.nnz + 1.0), A.indices, A.indptr), shape=A.shape)[free][:, free]
            pos = canonical_csr(pos)
            self._analyse(pos)
            composed = pos.data.astype(np.int64)[self._perm] - 1
            full = self._full = ((A.indptr.copy(), A.indices.copy()), free.copy(), composed)
        return self._factor_solve(A.data[full[2]], np.asarray(b, dtype=np.float64))

    def _solve_factored(self, A, b):
        A = canonical_csr(A)  # the value map gathers one value per entry
        if not same_pattern(self._key, A):
            self._analyse(A)
        return self._factor_solve(A.data[self._perm], b)

    def _factor_solve(self, values: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Numeric factorization of the analysed pattern with ``values`` (the factor's input order),
        unless they are those of the current factorization, then the solve for ``b`` (n,) or (n, k)."""
        if self._factored is None or not np.array_equal(values, self._factored):
            self._factored = None
            self._factor(values)
            self._factored = values.copy()
        if self._A is None:
            return self._F.solve(b)
        import cvxopt

        cholmod = import_cholmod()
        x = cvxopt.matrix(np.ascontiguousarray(b.reshape(self._A.size[0], -1)))
        cholmod.solve(self._F, x)
        return np.array(x).reshape(b.shape)

    def _factor(self, values: np.ndarray) -> None:
        """Numeric Cholesky factorization; NotPositiveDefinite when a pivot is not positive."""
        msg = "Cholesky factorization failed: matrix is not positive definite"
        if self._A is None:
            from simfab.solve.pardiso import NOT_POSITIVE_DEFINITE, PardisoError

            try:
                self._F.factor(values)
            except PardisoError as e:
                if e.code == NOT_POSITIVE_DEFINITE:
                    raise NotPositiveDefinite(msg) from e
                raise
            return
        import cvxopt

        cholmod = import_cholmod()
        self._A.V = cvxopt.matrix(values)
        try:
            cholmod.numeric(self._A, self._F)
        except ArithmeticError as e:
            raise NotPositiveDefinite(msg) from e

    def _analyse(self, A: sp.csr_matrix) -> None:
        self._full = None  # a value map built on the previous analysis no longer applies
        self._factored = None
        n = A.shape[0]
        rows = np.repeat(np.arange(n), np.diff(A.indptr))
        cols = A.indices
        low = np.flatnonzero(cols <= rows)
        r, c = rows[low], cols[low]
        order = np.lexsort((r, c))  # column-major, rows sorted within a column
        self._perm = low[order]
        self._key = (A.indptr.copy(), A.indices.copy())
        self._A = self._F = None
        if self._use_pardiso(n):
            from simfab.solve.pardiso import PardisoCholesky

            # the lower triangle column after column is the upper triangle row after row
            indptr = np.concatenate([[0], np.cumsum(np.bincount(c, minlength=n))])
            self._F = PardisoCholesky(indptr, r[order])
            return
        cholmod = import_cholmod()
        import cvxopt

        self._A = cvxopt.spmatrix(cvxopt.matrix(A.data[self._perm]), cvxopt.matrix(r[order].astype(np.int64)),
                                  cvxopt.matrix(c[order].astype(np.int64)), (n, n))
        cholmod.options["supernodal"] = 2
        self._F = cholmod.symbolic(self._A)

    def _use_pardiso(self, n: int) -> bool:
        if self.backend == "pardiso":
            return True
        if self.backend != "auto" or n < PARDISO_MIN_DOFS:
            return False
        from simfab.solve import pardiso

        return pardiso.available()
