"""Sparse symmetric positive-definite solves.

CHOLMOD (through ``cvxopt.cholmod``, which bundles SuiteSparse, so it installs with pip)
is the default: it is several times faster than SuperLU on 3D elasticity systems. The
symbolic analysis (fill-reducing ordering) is kept and reused while the sparsity pattern
is unchanged, which is the case across Newton iterations of one simulation.

    solver = SPDSolver()
    x = solver.solve(A, b)      # A: scipy.sparse (n, n) SPD, b: (n,) or (n, k)
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from simfab.errors import ConvergenceError


class NotPositiveDefinite(ConvergenceError):
    """The matrix handed to :class:`SPDSolver` is not numerically positive definite."""


class SPDSolver:
    """Cholesky solver for sparse SPD matrices with reuse of the symbolic factorization.

    Parameters
    ----------
    backend : "cholmod" | "splu" | "auto"
        "auto" uses CHOLMOD when cvxopt is importable, else SciPy's SuperLU.
    """

    def __init__(self, backend: str = "auto"):
        if backend == "auto":
            try:
                import cvxopt.cholmod  # noqa: F401

                backend = "cholmod"
            except ImportError:  # pragma: no cover - cvxopt is a dependency
                backend = "splu"
        if backend not in ("cholmod", "splu"):
            raise ValueError(f"unknown linear-solver backend {backend!r}")
        self.backend = backend
        self._symbolic = None
        self._pattern_key = None

    def solve(self, A: sp.spmatrix, b: np.ndarray) -> np.ndarray:
        """Solve ``A x = b`` for SPD ``A`` (only its lower triangle is read by CHOLMOD)."""
        b = np.asarray(b, dtype=np.float64)
        if self.backend == "splu":
            from scipy.sparse.linalg import splu

            lu = splu(sp.csc_matrix(A), permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})
            return lu.solve(b)
        return self._solve_cholmod(A, b)

    def _solve_cholmod(self, A, b):
        import cvxopt
        import cvxopt.cholmod as cholmod

        A = sp.tril(sp.csc_matrix(A), format="csc")
        A.sort_indices()
        n = A.shape[0]
        Ac = cvxopt.spmatrix(A.data, A.indices.astype(np.int64), np.repeat(np.arange(n), np.diff(A.indptr)), (n, n))
        key = (n, A.nnz, hash(A.indices[: min(64, A.nnz)].tobytes()), hash(A.indptr.tobytes()))
        cholmod.options["supernodal"] = 2
        if self._symbolic is None or key != self._pattern_key:
            self._symbolic = cholmod.symbolic(Ac)
            self._pattern_key = key
        F = self._symbolic
        try:
            cholmod.numeric(Ac, F)
        except ArithmeticError as e:
            raise NotPositiveDefinite("Cholesky factorization failed: matrix is not positive definite") from e
        x = cvxopt.matrix(np.ascontiguousarray(b.reshape(n, -1)))
        cholmod.solve(F, x)
        out = np.array(x).reshape(b.shape)
        return out


def solve_spd(A: sp.spmatrix, b: np.ndarray) -> np.ndarray:
    """One-shot SPD solve (no reuse of the symbolic analysis)."""
    return SPDSolver().solve(A, b)
