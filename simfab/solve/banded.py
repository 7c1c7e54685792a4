"""Banded Cholesky solves for narrow-band SPD systems (rods and chains), and the shifted variant
for possibly indefinite Newton systems.

:class:`BandedOrSparseCholesky` reorders the matrix once per sparsity pattern (reverse
Cuthill-McKee) and uses LAPACK's banded Cholesky when the half-bandwidth is small, CHOLMOD
(:class:`simfab.solve.linear.SPDSolver`) otherwise; :class:`ShiftedCholesky` adds the smallest
diagonal shift that makes a failed factorization succeed.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from simfab.solve.linear import NotPositiveDefinite, SPDSolver, canonical_csr, same_pattern


class BandedOrSparseCholesky(SPDSolver):
    """SPD solves that use LAPACK's banded Cholesky when a bandwidth-reducing ordering
    (reverse Cuthill-McKee, computed once per sparsity pattern) gives a narrow band, and
    CHOLMOD (:class:`SPDSolver`) otherwise. Single rods and chains have bandwidths of about
    a dozen, where the banded factorization costs O(n b^2) with no sparse-setup overhead.
    """

    max_band = 16  # banded path when the reordered half-bandwidth is at most this (chains: ~5-12)

    def __init__(self):
        super().__init__()
        self._band_key = None
        self._band = None

    def _prepare(self, A: sp.csr_matrix):
        from scipy.sparse.csgraph import reverse_cuthill_mckee

        n = A.shape[0]
        perm = reverse_cuthill_mckee(A, symmetric_mode=True)
        inv = np.empty_like(perm)
        inv[perm] = np.arange(n)
        rows = np.repeat(np.arange(n), np.diff(A.indptr))
        pi, pj = inv[rows], inv[A.indices]
        bw = int(np.max(np.abs(pi - pj))) if A.nnz else 0
        if bw > self.max_band:
            return None
        upper = pj >= pi  # LAPACK upper band storage: ab[bw + i - j, j] = A[i, j], j >= i
        return dict(perm=perm, bw=bw, sel=np.flatnonzero(upper), pos=(bw + pi[upper] - pj[upper], pj[upper]))

    def solve_free(self, A, free, b):
        """The free block's solve through :meth:`solve` (the banded path decides on the block's own
        pattern; :meth:`SPDSolver.solve_free` maps values straight to CHOLMOD's input)."""
        free = np.asarray(free)
        return self.solve(canonical_csr(A)[free][:, free], b)

    def solve_free_update(self, A, free, b, U, mu):
        """``(A[free][:, free] + mu U U^T) x = b`` by Woodbury through :meth:`solve_free` (U's r
        columns solved beside b): y = A^-1 b, Z = A^-1 U, x = y - Z (I/mu + U^T Z)^-1 U^T y."""
        b, U = np.asarray(b, dtype=np.float64), np.asarray(U, dtype=np.float64)
        k = 1 if b.ndim == 1 else b.shape[1]
        X = np.column_stack([self.solve_free(A, free, b.reshape(len(b), k)[:, j]) for j in range(k)]
                            + [self.solve_free(A, free, U[:, j]) for j in range(U.shape[1])])
        y, Z = X[:, :k], X[:, k:]
        return (y - Z @ np.linalg.solve(np.eye(U.shape[1]) / mu + U.T @ Z, U.T @ y)).reshape(b.shape)

    def solve(self, A, b):
        from scipy.linalg import LinAlgError, cho_solve_banded, cholesky_banded

        A = canonical_csr(A)  # the band map gathers one value per entry, like SPDSolver's value map
        if not same_pattern(self._band_key, A):
            self._band_key, self._band = (A.indptr.copy(), A.indices.copy()), self._prepare(A)
        info = self._band
        if info is None:
            return super().solve(A, b)
        n = A.shape[0]
        ab = np.zeros((info["bw"] + 1, n))
        ab[info["pos"]] = A.data[info["sel"]]
        try:
            c = cholesky_banded(ab, lower=False, check_finite=False)
        except LinAlgError:
            raise NotPositiveDefinite("banded Cholesky failed: matrix is not positive definite") from None
        x = np.empty(n)
        rhs = np.asarray(b, dtype=np.float64)[info["perm"]]
        x[info["perm"]] = cho_solve_banded((c, False), rhs, check_finite=False)
        return x


class ShiftedCholesky(BandedOrSparseCholesky):
    """SPD solver for possibly indefinite Newton systems: on a failed Cholesky factorization it
    searches the smallest diagonal shift ``mu`` (factor-2 bracket, geometric steps from
    ``1e-10 * mean|diag|``) that makes ``H + mu I`` positive definite and solves with it.

    Near a buckling point the Hessian has a negative eigenvalue; a shift just above it gives
    a long step along the buckling mode (capped by ``max_step``) instead of the crawl that a
    large shift would cause.
    """

    def __init__(self):
        super().__init__()
        self._diag_key = None
        self._diag = None  # positions of the diagonal in the CSR data (None: not all stored)

    def shifter(self, A: sp.csr_matrix):
        """Function mu -> A + mu I. When every diagonal entry is stored (Newton Hessians), the shift
        is added to those values in a copy (same pattern, no sparse addition per trial shift)."""
        if not same_pattern(self._diag_key, A):
            rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
            pos = np.flatnonzero(A.indices == rows)
            self._diag_key = (A.indptr.copy(), A.indices.copy())
            self._diag = pos if len(pos) == A.shape[0] else None
        if self._diag is None:
            I = sp.identity(A.shape[0], format="csr")
            return lambda mu: A + mu * I
        pos = self._diag

        def shifted(mu):
            B = A.copy()
            B.data[pos] += mu
            return B

        return shifted

    def solve(self, A, b):
        try:
            return super().solve(A, b)
        except NotPositiveDefinite:
            pass
        A = canonical_csr(A)
        shifted = self.shifter(A)
        base = float(np.mean(np.abs(A.diagonal()))) or 1.0
        lo, mu = 0.0, 1e-10 * base
        x = None
        while mu <= 1e3 * base:
            try:
                x = super().solve(shifted(mu), b)
                break
            except NotPositiveDefinite:
                lo, mu = mu, mu * 16.0
        if x is None:
            raise NotPositiveDefinite("Hessian not positive definite even with a shift of 1e3 x mean|diag|")
        for _ in range(3):  # tighten the bracket [lo, mu] to a factor 2
            mid = np.sqrt(max(lo, 1e-300) * mu) if lo > 0 else 0.5 * mu
            if mu / max(lo, 1e-300) <= 2.0:
                break
            try:
                x = super().solve(shifted(mid), b)
                mu = mid
            except NotPositiveDefinite:
                lo = mid
        return x
