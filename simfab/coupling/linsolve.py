"""CHOLMOD solves for a fixed sparsity pattern with per-call overhead kept to a copy of the values.

:class:`simfab.solve.linear.SPDSolver` converts every matrix (lower triangle, CSC, a new cvxopt
``spmatrix``), which for the small systems of an insertion simulation costs more than the numeric
factorization itself. Here the map from the CSR values to CHOLMOD's lower-triangle CSC order is
computed once per pattern; each solve only gathers the values into the existing ``spmatrix``,
refactorizes numerically (reusing the symbolic analysis) and solves. Same interface as
``SPDSolver.solve`` (so :func:`simfab.solve.newton.minimize` accepts it); raises
:class:`simfab.solve.linear.NotPositiveDefinite` when the factorization fails.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from simfab.solve.linear import NotPositiveDefinite


class PatternCholesky:
    """Sparse SPD solver specialised for repeated solves with one CSR pattern (falls back to a
    fresh analysis whenever the pattern changes)."""

    def __init__(self):
        self._key = None
        self._perm = None
        self._A = None
        self._F = None

    def solve(self, A, b: np.ndarray) -> np.ndarray:
        import cvxopt
        import cvxopt.cholmod as cholmod

        A = A if isinstance(A, sp.csr_matrix) else sp.csr_matrix(A)
        if not (self._key is not None and self._key[0].shape == A.indptr.shape and self._key[1].shape == A.indices.shape
                and np.array_equal(self._key[0], A.indptr) and np.array_equal(self._key[1], A.indices)):
            self._analyse(A)
        self._A.V = cvxopt.matrix(A.data[self._perm])
        try:
            cholmod.numeric(self._A, self._F)
        except ArithmeticError as e:
            raise NotPositiveDefinite("Cholesky factorization failed: matrix is not positive definite") from e
        n = A.shape[0]
        x = cvxopt.matrix(np.ascontiguousarray(np.asarray(b, dtype=np.float64).reshape(n, -1)))
        cholmod.solve(self._F, x)
        return np.array(x).reshape(np.shape(b))

    def _analyse(self, A: sp.csr_matrix) -> None:
        import cvxopt
        import cvxopt.cholmod as cholmod

        n = A.shape[0]
        rows = np.repeat(np.arange(n), np.diff(A.indptr))
        cols = A.indices
        low = np.flatnonzero(cols <= rows)
        r, c = rows[low], cols[low]
        order = np.lexsort((r, c))  # CHOLMOD: column-major, rows sorted within a column
        self._perm = low[order]
        self._A = cvxopt.spmatrix(cvxopt.matrix(A.data[self._perm]), cvxopt.matrix(r[order].astype(np.int64)),
                                  cvxopt.matrix(c[order].astype(np.int64)), (n, n))
        if len(self._A.V) != len(self._perm):  # duplicates would break the value map
            raise ValueError("matrix pattern has duplicate entries")
        cholmod.options["supernodal"] = 2
        self._F = cholmod.symbolic(self._A)
        self._key = (A.indptr.copy(), A.indices.copy())
