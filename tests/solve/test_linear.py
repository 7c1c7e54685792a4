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
