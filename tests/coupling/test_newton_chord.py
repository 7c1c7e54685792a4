"""Chord steps in Newton (``NewtonConfig.chord_within``) and the pinned solve of a Hessian that is
indefinite only along the pinned rigid motions (:class:`simfab.coupling.rigid.PinnedSolver`)."""

import numpy as np
import pytest
import scipy.sparse as sp

from simfab.coupling import rigid
from simfab.solve.linear import NotPositiveDefinite, SPDSolver
from simfab.solve.newton import NewtonConfig, minimize


def _stiff_chain(n):
    """SPD tridiagonal K (a chain of unit springs held at both ends)."""
    return sp.diags([-np.ones(n - 1), 2.0 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1], format="csr")


def _quartic(n, c=0.3):
    """f = 1/2 x^T K x + c/4 sum x^4 - b^T x: convex, its Hessian K + 3c diag(x^2) changes with x, so
    Newton converges quadratically and a chord step (the old Hessian) only linearly."""
    K = _stiff_chain(n)
    b = np.linspace(1.0, 2.0, n)

    def fun(x, need_h):
        g = K @ x + c * x**3 - b
        f = 0.5 * x @ (K @ x) + 0.25 * c * np.sum(x**4) - b @ x
        return f, g, (K + sp.diags(3 * c * x**2, format="csr")) if need_h else None

    return fun


def test_chord_steps_reach_the_same_minimizer_with_fewer_factorizations():
    n = 40
    fun = _quartic(n)
    x0 = np.zeros(n)
    base = dict(grad_tol=1e-9, grad_scale=1.0, eager_hessian=False)
    plain, chord = SPDSolver(), SPDSolver()
    a = minimize(fun, x0, options=NewtonConfig(**base), solver=plain)
    b = minimize(fun, x0, options=NewtonConfig(**base, chord_within=1e6), solver=chord)
    # the same stopping rule: both minimizers satisfy |g|_inf <= 1e-9
    assert a.grad_norm <= 1e-9 and b.grad_norm <= 1e-9
    np.testing.assert_allclose(b.x, a.x, rtol=0, atol=1e-8)  # |dx| <= |K^-1| |g| ~ n^2/8 * 1e-9
    assert b.chord_steps >= 1 and a.chord_steps == 0
    # a chord step reuses the factorization: fewer numeric factorizations than Newton iterations
    assert chord.factorizations == b.iterations - b.chord_steps
    assert chord.factorizations < plain.factorizations


def test_chord_within_zero_is_plain_newton():
    fun = _quartic(20)
    res = minimize(fun, np.zeros(20), options=NewtonConfig(grad_tol=1e-9, grad_scale=1.0))
    assert res.chord_steps == 0


def test_solve_free_update_with_shift_matches_dense():
    rng = np.random.default_rng(0)
    n, r = 30, 3
    A = _stiff_chain(n) + sp.identity(n, format="csr")
    free = np.arange(2, n)
    U = np.linalg.qr(rng.standard_normal((len(free), r)))[0]
    b = rng.standard_normal(len(free))
    mu, shift = 5.0, 0.25
    x = SPDSolver().solve_free_update(A, free, b, U, mu, shift)
    dense = A.toarray()[np.ix_(free, free)] + shift * np.eye(len(free)) + mu * U @ U.T
    np.testing.assert_allclose(x, np.linalg.solve(dense, b), rtol=1e-10, atol=1e-12)


def test_pinned_solver_solves_a_hessian_indefinite_along_the_pin():
    n = 60
    K = _stiff_chain(n).toarray()
    w, V = np.linalg.eigh(K)
    U = V[:, :2]  # the two softest modes, pinned
    eps = 5e-6  # A's eigenvalue along them: -eps (1e-6 of mu below); the others are K's (>= w[2] ~ 1e-2)
    A = sp.csr_matrix(K - U @ np.diag(w[:2] + eps) @ U.T)
    free = np.arange(n)
    b = np.random.default_rng(1).standard_normal(n)
    with pytest.raises(NotPositiveDefinite):
        SPDSolver().solve_free(A, free, b)
    mu = float(np.abs(K.diagonal()).mean())
    solver = SPDSolver()
    ps = rigid.PinnedSolver(solver, rigid.Pin(U, mu, np.zeros(n)))
    x = ps.solve_free(A, free, b)
    exact = np.linalg.solve(A.toarray() + mu * U @ U.T, b)
    # PCG stops at |r| <= PCG_TOL |b|; the error is within cond(A + mu U U^T) times that
    Kp = A.toarray() + mu * U @ U.T
    assert np.linalg.norm(Kp @ x - b) <= rigid.PCG_TOL * np.linalg.norm(b)
    cond = np.linalg.cond(Kp)
    assert np.linalg.norm(x - exact) <= cond * rigid.PCG_TOL * np.linalg.norm(exact)
    assert solver.shift_hint >= rigid.SHIFT_START and ps.pcg_iterations >= 1
    # a later solve starts from the shift found (no failed factorization of A first)
    before = solver.factorizations
    rigid.PinnedSolver(solver, rigid.Pin(U, mu, np.zeros(n))).solve_free(A, free, b)
    assert solver.factorizations == before  # the same values: the shifted factor is reused


def test_pinned_solver_near_the_target_leaves_a_residual_below_a_fraction_of_it():
    # Newton's last steps (right-hand side within PCG_NEAR of the force target t): the shifted solve's
    # residual must not keep Newton from t, |K x - b|_inf <= PCG_ATOL t (the step then lands within
    # ~PCG_ATOL t of the quadratic model's minimizer); far from t, the relative PCG_TOL is enough
    n = 60
    K = _stiff_chain(n).toarray()
    w, V = np.linalg.eigh(K)
    U = V[:, :2]
    A = sp.csr_matrix(K - U @ np.diag(w[:2] + 5e-6) @ U.T)
    mu = float(np.abs(K.diagonal()).mean())
    Kp = A.toarray() + mu * U @ U.T
    b = np.random.default_rng(2).standard_normal(n)
    for target in (np.abs(b).max() / 50.0, np.abs(b).max() / 5.0):
        ps = rigid.PinnedSolver(SPDSolver(), rigid.Pin(U, mu, np.zeros(n)), target=target)
        x = ps.solve_free(A, np.arange(n), b)
        r = Kp @ x - b
        assert np.abs(r).max() <= rigid.PCG_ATOL * target or np.linalg.norm(r) <= rigid.PCG_TOL_NEAR * np.linalg.norm(b)


def test_pinned_solver_refuses_a_hessian_indefinite_outside_the_pin():
    n = 60
    K = _stiff_chain(n).toarray()
    w, V = np.linalg.eigh(K)
    A = sp.csr_matrix(K - 2 * w[2] * np.outer(V[:, 2], V[:, 2]))  # negative along an unpinned mode
    U = V[:, :2]
    mu = float(np.abs(K.diagonal()).mean())
    ps = rigid.PinnedSolver(SPDSolver(), rigid.Pin(U, mu, np.zeros(n)))
    with pytest.raises(NotPositiveDefinite):
        ps.solve_free(A, np.arange(n), np.ones(n))
