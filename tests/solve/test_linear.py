"""SPDSolver: agrees with a dense solve, reuses its analysis, handles pattern changes and non-SPD input."""

import numpy as np
import pytest
import scipy.sparse as sp

from simfab.solve import pardiso
from simfab.solve.linear import PARDISO_MIN_DOFS, NotPositiveDefinite, SPDSolver

needs_mkl = pytest.mark.skipif(not pardiso.available(), reason="MKL (the mkl wheel, x86-64 only) is not installed")
FACTORED = ["cholmod", pytest.param("pardiso", marks=needs_mkl)]


def _laplacian_2d(k, shift=0.1):
    T = sp.diags([-np.ones(k - 1), 2 * np.ones(k), -np.ones(k - 1)], [-1, 0, 1])
    return (sp.kron(T, sp.eye(k)) + sp.kron(sp.eye(k), T) + shift * sp.eye(k * k)).tocsr()


@pytest.mark.parametrize("backend", FACTORED + ["splu"])
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


@pytest.mark.parametrize("backend", FACTORED)
def test_indefinite_matrix_raises(backend):
    # the Newton solver tells an indefinite exact Hessian from a positive-definite one by this:
    # one slightly negative eigenvalue (min eig -0.07 of 1..8 here) must fail, and the solver must
    # recover with the next, positive-definite matrix of the same pattern
    A = _laplacian_2d(12)
    lam = np.linalg.eigvalsh(A.toarray())[0]
    solver = SPDSolver(backend)
    b = np.ones(A.shape[0])
    for shift in (-lam - 0.07, -10.0):
        with pytest.raises(NotPositiveDefinite):
            solver.solve((A + shift * sp.eye(A.shape[0])).tocsr(), b)
    np.testing.assert_allclose(solver.solve(A, b), np.linalg.solve(A.toarray(), b), rtol=1e-10)


@pytest.mark.parametrize("backend", FACTORED + ["splu"])
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
        if backend != "splu":
            assert np.array_equal(x, expect)
        np.testing.assert_allclose(M[free][:, free] @ x, b, atol=1e-10 * np.abs(b).max())
    if backend != "splu":  # (SuperLU does not test definiteness)
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


def _p2_elasticity_system():
    """Free block of the stiffness of a clamped 3D quadratic-tet box (the systems PARDISO is for):
    4 x 4 x 12 cubes of 6 tets lifted to 10-node tets, one end clamped, 6,000+ free dofs."""
    from simfab.fem import elastic
    from simfab.fem.meshing import structured_box
    from simfab.fem.p2 import make_p2_model

    P, T = structured_box((0.01, 0.01, 0.03), (4, 4, 12))
    m = make_p2_model(P, T, "pla")
    x = m.rest + 1e-4 * np.random.default_rng(3).standard_normal(m.rest.shape)
    H = elastic.energy_gradient_hessian(m, x)[2]
    free = np.flatnonzero(np.repeat(m.rest[:, 2] > 1e-9, 3))
    return sp.csr_matrix(H), free


def test_pardiso_path_on_a_3d_quadratic_element_system():
    # the automatic choice factorizes this system with PARDISO when MKL is installed; either way
    # the solution must satisfy the system to a residual set by the conditioning (double
    # precision Cholesky: |A x - b| <= c eps |A| |x| with cond(A) ~ 1e5 here -> 1e-9 relative)
    from scipy.sparse.linalg import spsolve

    H, free = _p2_elasticity_system()
    assert len(free) >= PARDISO_MIN_DOFS
    Hf = H[free][:, free].tocsc()
    rng = np.random.default_rng(5)
    b = rng.standard_normal((len(free), 2))
    solver = SPDSolver()
    x = solver.solve_free(H, free, b)
    assert solver.library == ("pardiso" if pardiso.available() else "cholmod")
    ref = spsolve(Hf, b)
    for k in range(2):
        assert np.linalg.norm(Hf @ x[:, k] - b[:, k]) <= 1e-9 * np.linalg.norm(b[:, k])
        assert np.linalg.norm(x[:, k] - ref[:, k]) <= 1e-7 * np.linalg.norm(ref[:, k])


def test_small_systems_stay_on_cholmod():
    # below PARDISO_MIN_DOFS PARDISO's fixed cost per call outweighs its faster kernels
    A = _laplacian_2d(20)
    solver = SPDSolver()
    solver.solve(A, np.ones(A.shape[0]))
    assert A.shape[0] < PARDISO_MIN_DOFS and solver.library == "cholmod"


@pytest.mark.parametrize("backend", FACTORED)
def test_unchanged_values_are_not_factorized_again(backend, monkeypatch):
    # Newton's predictor can hand the same Hessian twice: the factorization is reused then, and
    # only then (a changed value must refactorize, also after a failed factorization)
    A = _laplacian_2d(9)
    n = A.shape[0]
    solver = SPDSolver(backend)
    calls = []
    factor = solver._factor
    monkeypatch.setattr(solver, "_factor", lambda v: (calls.append(1), factor(v))[1])
    rng = np.random.default_rng(6)
    free = np.arange(2, n)
    for M, expect_calls in ((A, 1), (A.copy(), 1), (2.0 * A, 2), (2.0 * A, 2)):
        b = rng.standard_normal(len(free))
        x = solver.solve_free(M.tocsr(), free, b)
        np.testing.assert_allclose(M[free][:, free] @ x, b, atol=1e-10 * np.abs(b).max())
        assert len(calls) == expect_calls
    with pytest.raises(NotPositiveDefinite):
        solver.solve_free(-A, free, np.ones(len(free)))
    x = solver.solve_free(2.0 * A, free, np.ones(len(free)))  # the same values as before the failure
    assert len(calls) == 4
    np.testing.assert_allclose((2.0 * A)[free][:, free] @ x, np.ones(len(free)), atol=1e-10)
