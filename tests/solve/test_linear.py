"""SPDSolver: agrees with a dense solve, reuses its analysis, handles pattern changes and non-SPD input."""

import numpy as np
import pytest
import scipy.sparse as sp

from simfab.solve.linear import NotPositiveDefinite, SPDSolver


def _laplacian_2d(k, shift=0.1):
    T = sp.diags([-np.ones(k - 1), 2 * np.ones(k), -np.ones(k - 1)], [-1, 0, 1])
    return (sp.kron(T, sp.eye(k)) + sp.kron(sp.eye(k), T) + shift * sp.eye(k * k)).tocsr()


@pytest.mark.parametrize("backend", ["cholmod", "splu"])
def test_matches_dense_and_reuses_pattern(backend):
    rng = np.random.default_rng(0)
    solver = SPDSolver(backend)
    A = _laplacian_2d(9)
    for scale in (1.0, 3.0):  # same pattern, new values: the cached map must follow the values
        B = (A * scale).tocsr()
        b = rng.standard_normal((B.shape[0], 2))
        np.testing.assert_allclose(solver.solve(B, b), np.linalg.solve(B.toarray(), b), rtol=1e-10, atol=1e-12)
    C = _laplacian_2d(7)  # a new pattern triggers a new analysis
    c = rng.standard_normal(C.shape[0])
    np.testing.assert_allclose(solver.solve(C, c), np.linalg.solve(C.toarray(), c), rtol=1e-10, atol=1e-12)


def test_non_canonical_input_is_not_mutated():
    A = _laplacian_2d(5).tocoo()
    # the same matrix as a sum of duplicate entries, unsorted
    rows = np.concatenate([A.row, A.row]); cols = np.concatenate([A.col, A.col]); vals = np.concatenate([A.data, A.data]) / 2
    D = sp.csr_matrix((vals, (rows, cols)), shape=A.shape)
    D.has_canonical_format = False
    D_data = D.data.copy()
    b = np.ones(A.shape[0])
    np.testing.assert_allclose(SPDSolver().solve(D, b), np.linalg.solve(A.toarray(), b), rtol=1e-10)
    np.testing.assert_array_equal(D.data, D_data)


def test_indefinite_matrix_raises():
    A = _laplacian_2d(4, shift=-10.0)
    with pytest.raises(NotPositiveDefinite):
        SPDSolver().solve(A, np.ones(A.shape[0]))


@pytest.mark.parametrize("backend", ["cholmod", "splu"])
def test_solve_free_equals_the_solve_of_the_extracted_block(backend):
    # solve_free gathers the free block's values straight from the full matrix through a cached
    # map; it must follow new values, a new free set and a new pattern, and agree with a solve of
    # A[free][:, free] (bit for bit with CHOLMOD: the same factor input in the same order)
    rng = np.random.default_rng(4)
    A = _laplacian_2d(8)
    n = A.shape[0]
    solver, ref = SPDSolver(backend), SPDSolver(backend)
    for free, scale, extra in ((np.arange(5, n), 1.0, 0.0), (np.arange(5, n), 2.5, 0.0),
                               (np.arange(0, n - 7), 2.5, 0.0), (np.arange(0, n - 7), 1.0, 0.3)):
        R = sp.random(n, n, density=0.02, random_state=1)  # extra > 0: a new pattern (A + R R^T + I is SPD)
        M = (scale * A + extra * (R @ R.T + sp.eye(n))).tocsr() if extra else (scale * A).tocsr()
        b = rng.standard_normal(len(free))
        x = solver.solve_free(M, free, b)
        expect = ref.solve(M[free][:, free], b)
        if backend == "cholmod":
            assert np.array_equal(x, expect)
        np.testing.assert_allclose(M[free][:, free] @ x, b, atol=1e-10 * np.abs(b).max())
    if backend == "cholmod":  # (SuperLU does not test definiteness)
        with pytest.raises(NotPositiveDefinite):
            solver.solve_free(-A, np.arange(n), np.ones(n))


def test_banded_solver_solves_the_free_block_through_its_own_solve():
    # the rods' banded solver overrides solve; its solve_free must solve the same free block
    from simfab.solve.banded import BandedOrSparseCholesky

    A = _laplacian_2d(8)
    n = A.shape[0]
    free = np.arange(3, n - 2)
    b = np.random.default_rng(2).standard_normal(len(free))
    x = BandedOrSparseCholesky().solve_free(A, free, b)
    np.testing.assert_allclose(A[free][:, free] @ x, b, atol=1e-10 * np.abs(b).max())
