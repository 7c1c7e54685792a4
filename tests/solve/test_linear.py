"""SPDSolver: agrees with a dense solve, reuses its analysis, handles pattern changes and non-SPD input."""

import numpy as np
import pytest
import scipy.sparse as sp

from simfab.solve.linear import LagConfig, NotPositiveDefinite, SPDSolver


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
    rows = np.concatenate([A.row, A.row])
    cols = np.concatenate([A.col, A.col])
    vals = np.concatenate([A.data, A.data]) / 2
    D = sp.csr_matrix((vals, (rows, cols)), shape=A.shape)
    D.has_canonical_format = False
    D_data = D.data.copy()
    b = np.ones(A.shape[0])
    np.testing.assert_allclose(SPDSolver().solve(D, b), np.linalg.solve(A.toarray(), b), rtol=1e-10)
    np.testing.assert_array_equal(D.data, D_data)


def test_indefinite_matrix_raises():
    # the Newton solver tells an indefinite exact Hessian from a positive-definite one by this:
    # one slightly negative eigenvalue (-0.07 against a spectrum up to 8) must fail as well as a
    # clearly indefinite matrix, and the solver must recover with the next, positive-definite
    # matrix of the same pattern
    A = _laplacian_2d(12)
    lam = np.linalg.eigvalsh(A.toarray())[0]
    solver = SPDSolver()
    b = np.ones(A.shape[0])
    for shift in (-lam - 0.07, -10.0):
        with pytest.raises(NotPositiveDefinite):
            solver.solve((A + shift * sp.eye(A.shape[0])).tocsr(), b)
    np.testing.assert_allclose(solver.solve(A, b), np.linalg.solve(A.toarray(), b), rtol=1e-10)


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
                               (np.arange(0, n - 7), 2.5, 0.0), (np.arange(0, n - 7), 1.0, 0.3),
                               (rng.permutation(np.arange(3, n)), 1.0, 0.3)):  # (free in any order)
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


def _p2_elasticity_system():
    """Free block of the stiffness of a clamped, slightly stretched 3D quadratic-tet box (the
    systems whose factorizations dominate 3D P2 insertions): 4 x 4 x 12 cubes of 6 tets lifted to
    10-node tets, one end clamped, 5,832 free dofs."""
    from simfab.fem import elastic
    from simfab.fem.meshing import structured_box
    from simfab.fem.p2 import make_p2_model

    P, T = structured_box((0.01, 0.01, 0.03), (4, 4, 12))
    m = make_p2_model(P, T, "pla")
    H = elastic.energy_gradient_hessian(m, m.rest * 1.01)[2]
    free = np.flatnonzero(np.repeat(m.rest[:, 2] > 1e-9, 3))
    return sp.csr_matrix(H), free


def test_solve_free_on_a_3d_quadratic_element_system():
    # against SuperLU's direct solve of the extracted block; double-precision Cholesky is backward
    # stable (|A x - b| <= c n eps |A| |x|), so with cond(A) ~ 1e5 here the residual must be
    # ~1e-13 relative and the solutions agree to ~1e-11: 1e-10 / 1e-8 would fail on a wrong
    # value map (an entry of the wrong place changes x at O(1))
    from scipy.sparse.linalg import splu

    H, free = _p2_elasticity_system()
    Hf = H[free][:, free].tocsc()
    b = np.random.default_rng(5).standard_normal((len(free), 2))
    x = SPDSolver().solve_free(H, free, b)
    ref = splu(Hf, permc_spec="MMD_AT_PLUS_A").solve(b)
    for k in range(2):
        assert np.linalg.norm(Hf @ x[:, k] - b[:, k]) <= 1e-10 * np.linalg.norm(b[:, k])
        assert np.linalg.norm(x[:, k] - ref[:, k]) <= 1e-8 * np.linalg.norm(ref[:, k])


def test_unchanged_values_are_not_factorized_again():
    # Newton's predictor can hand the same Hessian twice: the factorization is reused then, and
    # only then (a changed value refactorizes, and so does anything after a failed factorization)
    A = _laplacian_2d(9)
    n = A.shape[0]
    solver = SPDSolver()
    rng = np.random.default_rng(6)
    free = np.arange(2, n)
    for M, expect_calls in ((A, 1), (A.copy(), 1), (2.0 * A, 2), (2.0 * A, 2)):
        b = rng.standard_normal(len(free))
        x = solver.solve_free(M.tocsr(), free, b)
        np.testing.assert_allclose(M[free][:, free] @ x, b, atol=1e-10 * np.abs(b).max())
        assert solver.factorizations == expect_calls
    with pytest.raises(NotPositiveDefinite):
        solver.solve_free(-A, free, np.ones(len(free)))
    x = solver.solve_free(2.0 * A, free, np.ones(len(free)))  # the values before the failure
    assert solver.factorizations == 4
    np.testing.assert_allclose((2.0 * A)[free][:, free] @ x, np.ones(len(free)), atol=1e-10)


def test_cholmod_blas_uses_the_machines_vector_kernels():
    # cvxopt's bundled OpenBLAS 0.3.15 falls back to SSE3 ("Prescott") kernels on CPUs newer than
    # itself, which doubles CHOLMOD's factorization time; import_cholmod selects the AVX2 kernels
    # on CPUs that have them and leaves the process environment as it was. A fresh interpreter:
    # OpenBLAS chooses its kernels once, when cvxopt first loads it.
    import os
    import subprocess
    import sys

    from simfab.solve.linear import has_avx2_fma

    if not has_avx2_fma():
        pytest.skip("a CPU without AVX2/FMA: OpenBLAS's own kernel choice stands")
    code = """
import ctypes, os, pathlib
from simfab.solve.linear import import_cholmod
import_cholmod()
import cvxopt
libs = sorted((pathlib.Path(cvxopt.__file__).parent.parent / "cvxopt.libs").glob("libopenblas*.so*"))
if libs:
    lib = ctypes.CDLL(str(libs[0]))
    lib.openblas_get_corename.restype = ctypes.c_char_p
    print(lib.openblas_get_corename().decode(), os.environ.get("OPENBLAS_CORETYPE"))
else:
    print("none", os.environ.get("OPENBLAS_CORETYPE"))
"""
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True).stdout.split()
    core, after = out[-2], out[-1]
    assert after == "None"  # the variable was set only around the import
    if core == "none":
        pytest.skip("cvxopt without a bundled OpenBLAS")
    assert core.lower() == "haswell", core


def _woodbury_case(A, free, rng, r=3):
    """Orthonormal dense U (m, r) and mu of the order of A's diagonal, so that the update moves x at O(1)."""
    U = np.linalg.qr(rng.standard_normal((len(free), r)))[0]
    return U, float(np.abs(A.diagonal()).mean())


@pytest.mark.parametrize("backend", ["cholmod", "splu"])
def test_solve_free_update_matches_the_dense_solve_of_the_updated_block(backend):
    # (A[free][:, free] + mu U U^T) x = b through half solves of A's factor (a simplicial L D L^T
    # here: D != I); against a dense solve to 1e-10 (cond ~ 1e2: an error in the update, e.g. a
    # missing D^-1, changes x at O(1))
    rng = np.random.default_rng(7)
    A = _laplacian_2d(8)
    free = np.arange(4, A.shape[0])
    U, mu = _woodbury_case(A, free, rng)
    dense = A.toarray()[np.ix_(free, free)] + mu * U @ U.T
    for b in (rng.standard_normal(len(free)), rng.standard_normal((len(free), 2))):
        x = SPDSolver(backend).solve_free_update(A, free, b, U, mu)
        assert x.shape == b.shape
        np.testing.assert_allclose(x, np.linalg.solve(dense, b), rtol=1e-10, atol=1e-12 * np.abs(x).max())


def test_solve_free_update_on_a_3d_quadratic_element_system():
    # the supernodal L L^T factor of a 3D P2 system (the insertion's pinned solves), against the
    # Woodbury update through full solves; both backward stable, cond ~1e5: agreement to 1e-8
    from simfab.solve.banded import BandedOrSparseCholesky

    rng = np.random.default_rng(8)
    H, free = _p2_elasticity_system()
    U, mu = _woodbury_case(H, free, rng)
    b = rng.standard_normal(len(free))
    x = SPDSolver().solve_free_update(H, free, b, U, mu)
    ref = BandedOrSparseCholesky().solve_free_update(H, free, b, U, mu)
    Hf = H[free][:, free]
    assert np.linalg.norm(Hf @ x + mu * U @ (U.T @ x) - b) <= 1e-10 * np.linalg.norm(b)
    assert np.linalg.norm(x - ref) <= 1e-8 * np.linalg.norm(ref)


def _free_system(k=14, seed=0):
    """A 2D Laplacian-like SPD matrix with a few held dofs, and a nearby matrix of the same pattern
    (a Newton Hessian a step later: values changed by up to 5 %)."""
    rng = np.random.default_rng(seed)
    A = _laplacian_2d(k)
    n = A.shape[0]
    free = np.setdiff1d(np.arange(n), rng.choice(n, 10, replace=False))
    D = sp.diags(1.0 + 0.05 * rng.random(n))
    A1 = (D @ A @ D).tocsr()  # congruent: still SPD, same pattern
    A1.sort_indices()
    return A.tocsr(), A1, free, rng


def test_lagged_solve_matches_the_direct_solve_without_a_factorization():
    # the lagged path (conjugate gradients preconditioned with the last factorization) solves the
    # new matrix to LagConfig.rtol: the error against the direct solve is bounded by the residual
    # times ||A^-1||, checked here at 1e-8 relative to x
    A0, A1, free, rng = _free_system()
    lag = LagConfig(min_unknowns=0, rtol=1e-10, max_iter=30)
    solver = SPDSolver(lag=lag)
    b = rng.standard_normal(len(free))
    solver.solve_free(A0, free, b)  # the first matrix is factorized
    assert solver.factorizations == 1
    x = solver.solve_free(A1, free, b)
    exact = np.linalg.solve(A1.toarray()[np.ix_(free, free)], b)
    assert np.abs(x - exact).max() <= 1e-8 * np.abs(exact).max()
    assert solver.factorizations == 1 and solver.lagged_solves == 1 and 1 < solver.pcg_iterations <= 30


def test_lagged_update_solve_matches_the_woodbury_direct_solve():
    A0, A1, free, rng = _free_system(seed=1)
    m = len(free)
    U = np.linalg.qr(rng.standard_normal((m, 3)))[0]
    mu = 2.0
    b = rng.standard_normal(m)
    solver = SPDSolver(lag=LagConfig(min_unknowns=0, rtol=1e-10, max_iter=30))
    solver.solve_free_update(A0, free, b, U, mu)
    x = solver.solve_free_lagged(A1, free, b, U, mu)
    K = A1.toarray()[np.ix_(free, free)] + mu * U @ U.T
    exact = np.linalg.solve(K, b)
    assert x is not None and np.abs(x - exact).max() <= 1e-8 * np.abs(exact).max()
    assert solver.factorizations == 1
    # an absolute tolerance on the residual's largest entry stops earlier, and the residual honours it
    solver2 = SPDSolver(lag=LagConfig(min_unknowns=0, rtol=1e-12, max_iter=30))
    solver2.solve_free_update(A0, free, b, U, mu)
    y = solver2.solve_free_lagged(A1, free, b, U, mu, atol=1e-3 * np.abs(b).max())
    assert y is not None and np.abs(K @ y - b).max() <= 1e-3 * np.abs(b).max()
    assert solver2.pcg_iterations < solver.pcg_iterations


def test_lagging_falls_back_to_a_factorization_and_respects_its_size_threshold():
    A0, A1, free, rng = _free_system(seed=2)
    b = rng.standard_normal(len(free))
    exact = np.linalg.solve(A1.toarray()[np.ix_(free, free)], b)
    # one iteration cannot reach 1e-12: the new matrix is factorized and solved directly
    solver = SPDSolver(lag=LagConfig(min_unknowns=0, rtol=1e-12, max_iter=1))
    solver.solve_free(A0, free, b)
    np.testing.assert_allclose(solver.solve_free(A1, free, b), exact, rtol=1e-9, atol=1e-12)
    assert solver.factorizations == 2 and solver.lagged_solves == 0 and solver.pcg_iterations == 1
    # below min_unknowns the solver factorizes as without lag
    small = SPDSolver(lag=LagConfig(min_unknowns=len(free) + 1))
    small.solve_free(A0, free, b)
    np.testing.assert_allclose(small.solve_free(A1, free, b), exact, rtol=1e-9, atol=1e-12)
    assert small.factorizations == 2 and small.pcg_iterations == 0


def test_a_slow_lagged_solve_leaves_the_factorization_stale():
    # LagConfig.refactor_after: a lagged solve that converged in more iterations than it leaves the
    # factorization stale, and the next new matrix is factorized (solved exactly, no iteration); one
    # within it keeps the factorization for the next solve
    A0, A1, free, rng = _free_system(seed=3)
    D = sp.diags(1.0 + 0.05 * rng.random(A0.shape[0]))
    A2 = (D @ A0 @ D).tocsr()
    A2.sort_indices()
    b = rng.standard_normal(len(free))
    probe = SPDSolver(lag=LagConfig(min_unknowns=0, rtol=1e-10, max_iter=30))
    probe.solve_free(A0, free, b)
    probe.solve_free(A1, free, b)
    it = probe.pcg_iterations
    assert probe.lagged_solves == 1 and it >= 2
    for after, stale in ((it, False), (it - 1, True)):
        solver = SPDSolver(lag=LagConfig(min_unknowns=0, rtol=1e-10, max_iter=30, refactor_after=after))
        solver.solve_free(A0, free, b)
        solver.solve_free(A1, free, b)
        assert solver.pcg_iterations == it and solver.stale == stale
        x = solver.solve_free(A2, free, b)
        exact = np.linalg.solve(A2.toarray()[np.ix_(free, free)], b)
        assert np.abs(x - exact).max() <= 1e-8 * np.abs(exact).max()
        assert solver.factorizations == (2 if stale else 1)
        if stale:  # factorized: no iteration, and the new factorization is fresh
            assert solver.pcg_iterations == it and solver.lagged_solves == 1 and not solver.stale
        else:
            assert solver.pcg_iterations > it and solver.lagged_solves == 2


def test_lagging_below_the_size_threshold_once_a_pinned_solve_needed_its_shift():
    # LagConfig.when_shifted: below min_unknowns a solver lags only after a pinned solve has set its
    # shift_hint (every solve is then conjugate gradients on a factorization that is not the matrix's
    # own); the lagged solve at an explicit rtol reaches that relative residual
    A0, A1, free, rng = _free_system(seed=4)
    m = len(free)
    U = np.linalg.qr(rng.standard_normal((m, 3)))[0]
    mu, b = 2.0, rng.standard_normal(m)
    K = A1.toarray()[np.ix_(free, free)] + mu * U @ U.T
    for hint, lags in ((0.0, False), (1e-7, True)):
        solver = SPDSolver(lag=LagConfig(min_unknowns=m + 1, max_iter=30))
        solver.shift_hint = hint
        solver.solve_free_update(A0, free, b, U, mu)
        x = solver.solve_free_lagged(A1, free, b, U, mu, rtol=1e-6)
        assert (x is not None) == lags
        if lags:
            assert np.linalg.norm(K @ x - b) <= 1e-6 * np.linalg.norm(b) and solver.factorizations == 1
    off = SPDSolver(lag=LagConfig(min_unknowns=m + 1, when_shifted=False))
    off.shift_hint = 1e-7
    off.solve_free_update(A0, free, b, U, mu)
    assert off.solve_free_lagged(A1, free, b, U, mu) is None


@pytest.mark.parametrize("backend", ["cholmod", "splu"])
def test_solve_factored_update_reuses_the_current_factorization(backend):
    # the preconditioner of the pinned solve's conjugate gradients: (F + mu U U^T)^-1 b with F the
    # last factorized block (its shift included), no new factorization; against a dense solve
    rng = np.random.default_rng(9)
    A = _laplacian_2d(8)
    free = np.arange(4, A.shape[0])
    U, mu = _woodbury_case(A, free, rng)
    shift = 0.3
    solver = SPDSolver(backend)
    with pytest.raises(RuntimeError):
        solver.solve_factored_update(np.ones(len(free)), U, mu)
    solver.solve_free_update(A, free, np.ones(len(free)), U, mu, shift)
    done = solver.factorizations
    dense = A.toarray()[np.ix_(free, free)] + shift * np.eye(len(free)) + mu * U @ U.T
    b = rng.standard_normal(len(free))
    x = solver.solve_factored_update(b, U, mu)
    np.testing.assert_allclose(x, np.linalg.solve(dense, b), rtol=1e-10, atol=1e-12 * np.abs(x).max())
    assert solver.factorizations == done


def test_lagged_solve_of_an_indefinite_matrix_raises():
    # the exact-first Newton step relies on NotPositiveDefinite for an indefinite Hessian; the lagged
    # path meets negative curvature in the iterations (a matrix with eigenvalue -1 along b's largest
    # components) and must raise, not return a non-descent step
    A0, _, free, rng = _free_system(seed=3)
    A_bad = (A0 - 5.0 * sp.eye(A0.shape[0])).tocsr()
    A_bad.sort_indices()
    solver = SPDSolver(lag=LagConfig(min_unknowns=0, rtol=1e-10, max_iter=50))
    b = rng.standard_normal(len(free))
    solver.solve_free(A0, free, b)
    with pytest.raises(NotPositiveDefinite):
        solver.solve_free(A_bad, free, b)
    assert solver.factorizations == 1  # proved indefinite by the iterations, no factorization tried


def test_lag_config_rejects_bad_fields():
    with pytest.raises(ValueError, match="rtol"):
        LagConfig(rtol=0.0)
    with pytest.raises(ValueError, match="max_iter"):
        LagConfig(max_iter=0)
    with pytest.raises(ValueError, match="refactor_after"):
        LagConfig(refactor_after=0)


def test_alternating_matrices_solve_right_while_the_solver_recycles_its_value_arrays():
    # the solver gathers a matrix's values into a spare array and, on factorizing them, keeps them and
    # recycles its previous values as the next spare: three matrices of one pattern, in turn, with the
    # Woodbury update (cached per factorization: a recycled array must not revive an old cache) and
    # lagged solves between the factorizations; every solve against a dense one
    rng = np.random.default_rng(11)
    base = _laplacian_2d(8)
    free = np.arange(4, base.shape[0])
    U, mu = _woodbury_case(base, free, rng)
    mats = [base.copy() for _ in range(3)]
    for k, A in enumerate(mats):
        A.data *= 1.0 + 0.3 * k
        A.setdiag(A.diagonal() + 0.2 * k)
    # (one lagged iteration at most: the solve between two updates factorizes too, so each update's
    # factorization gets the array of the update before it back)
    solver = SPDSolver("cholmod", lag=LagConfig(min_unknowns=0, rtol=1e-12, max_iter=1))
    for i in range(9):
        A = mats[i % 3]
        dense = A.toarray()[np.ix_(free, free)]
        b = rng.standard_normal(len(free))
        x = solver.solve_free_update(A, free, b, U, mu)
        np.testing.assert_allclose(x, np.linalg.solve(dense + mu * U @ U.T, b), rtol=1e-9, atol=1e-12)
        B = mats[(i + 2) % 3]  # (neither this update's matrix nor the next one's)
        x = solver.solve_free(B, free, b)
        np.testing.assert_allclose(x, np.linalg.solve(B.toarray()[np.ix_(free, free)], b), rtol=1e-8, atol=1e-11)
    assert solver.factorizations == 18
