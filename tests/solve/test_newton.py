"""Projected Newton (simfab.solve.newton) on problems with known minimizers."""

import numpy as np
import pytest
import scipy.sparse as sp

from simfab.errors import ConvergenceError
from simfab.solve.linear import SPDSolver
from simfab.solve.newton import NewtonOptions, minimize


def _spd(n, seed):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    return A @ A.T + n * np.eye(n)


def _quadratic(A, b):
    """f = 1/2 x^T A x - b^T x, g = A x - b, H = A; minimizer x* = A^-1 b."""
    As = sp.csr_matrix(A)

    def fun(x, need_h):
        g = A @ x - b
        return 0.5 * x @ A @ x - b @ x, g, (As if need_h else None)

    return fun


def test_convex_quadratic_converges_in_one_step():
    A = _spd(12, 0)
    b = np.random.default_rng(1).standard_normal(12)
    res = minimize(_quadratic(A, b), np.zeros(12))
    assert res.converged and res.iterations == 1
    # exact Newton step on a quadratic: x1 = A^-1 b up to round-off of the Cholesky solve
    np.testing.assert_allclose(res.x, np.linalg.solve(A, b), rtol=1e-10, atol=1e-12)


def test_free_mask_keeps_fixed_dofs_and_solves_reduced_problem():
    A = _spd(10, 2)
    b = np.random.default_rng(3).standard_normal(10)
    x0 = np.random.default_rng(4).standard_normal(10)
    free = np.ones(10, bool)
    free[[0, 3, 7]] = False
    res = minimize(_quadratic(A, b), x0, free=free)
    np.testing.assert_array_equal(res.x[~free], x0[~free])
    # reduced optimality: A_ff x_f = b_f - A_fc x_c
    xf = np.linalg.solve(A[np.ix_(free, free)], b[free] - A[np.ix_(free, ~free)] @ x0[~free])
    np.testing.assert_allclose(res.x[free], xf, rtol=1e-10, atol=1e-12)


def test_raises_when_iteration_capped():
    # Rosenbrock-like nonconvex problem needs many iterations from far away; cap at 2
    def fun(x, need_h):
        a, b = 1.0, 100.0
        f = (a - x[0]) ** 2 + b * (x[1] - x[0] ** 2) ** 2
        g = np.array([-2 * (a - x[0]) - 4 * b * x[0] * (x[1] - x[0] ** 2), 2 * b * (x[1] - x[0] ** 2)])
        H = np.array([[2 - 4 * b * (x[1] - 3 * x[0] ** 2), -4 * b * x[0]], [-4 * b * x[0], 2 * b]])
        w, V = np.linalg.eigh(H)
        H = (V * np.maximum(w, 1e-8)) @ V.T  # PSD projection
        return f, g, sp.csr_matrix(H) if need_h else None

    with pytest.raises(ConvergenceError, match="did not converge in 2 iterations"):
        minimize(fun, np.array([-1.2, 1.0]), options=NewtonOptions(max_iter=2))
    res = minimize(fun, np.array([-1.2, 1.0]), options=NewtonOptions(max_iter=200, grad_tol=1e-10))
    np.testing.assert_allclose(res.x, [1.0, 1.0], atol=1e-6)
    # Armijo backtracking: the energy never increases
    energies = [h["energy"] for h in res.history]
    assert all(b <= a for a, b in zip(energies, energies[1:]))
    assert any(h["alpha"] < 1 for h in res.history)  # the nonconvex valley needs backtracking


def test_max_step_caps_every_step():
    A = np.eye(3) * 2.0
    b = np.array([10.0, 0.0, 0.0])  # minimizer at (5, 0, 0)
    caps = []

    def max_step(x, dx):
        # never move more than 1.0 in x[0] per iteration
        a = min(1.0, 1.0 / max(abs(dx[0]), 1e-300))
        caps.append(a)
        return a

    res = minimize(_quadratic(A, b), np.zeros(3), max_step=max_step)
    np.testing.assert_allclose(res.x, [5.0, 0, 0], atol=1e-9)
    assert res.iterations >= 5  # 5 units at <= 1 per step
    assert all(c <= 1.0 for c in caps)
    assert all(h["alpha"] <= c for h, c in zip(res.history, caps))


def test_admissible_rejects_trial_points():
    # minimizer of the quadratic is x=-1, but only x > 0 is admissible; with a log barrier
    # f = (x+1)^2/2 - mu log x the minimizer is x* = (-1 + sqrt(1 + 4 mu)) / 2
    mu = 1e-2

    def fun(x, need_h):
        if x[0] <= 0:
            return np.inf, np.full(1, np.nan), None
        f = 0.5 * (x[0] + 1) ** 2 - mu * np.log(x[0])
        g = np.array([x[0] + 1 - mu / x[0]])
        H = sp.csr_matrix([[1 + mu / x[0] ** 2]])
        return f, g, H if need_h else None

    seen = []

    def admissible(x):
        seen.append(x[0])
        return x[0] > 0

    res = minimize(fun, np.array([2.0]), admissible=admissible)
    np.testing.assert_allclose(res.x[0], (-1 + np.sqrt(1 + 4 * mu)) / 2, rtol=1e-9)
    assert any(s <= 0 for s in seen)  # a full step went infeasible and was rejected
    assert all(h["energy"] < np.inf for h in res.history)


def test_indefinite_hessian_is_regularized():
    # a singular (PSD, not PD) Hessian: f = 1/2 (x0 - 1)^2 + 0 * x1 ... plus a tiny quartic in x1
    def fun(x, need_h):
        f = 0.5 * (x[0] - 1) ** 2 + 0.25 * x[1] ** 4
        g = np.array([x[0] - 1, x[1] ** 3])
        H = sp.csr_matrix(np.diag([1.0, 3 * x[1] ** 2]))
        return f, g, H if need_h else None

    res = minimize(fun, np.array([0.0, 0.0]))  # H singular at the start: shift needed
    assert res.x[0] == pytest.approx(1.0, abs=1e-9)
    assert res.history[0]["shift"] > 0


def test_start_point_not_admissible_raises():
    with pytest.raises(ConvergenceError, match="start point"):
        minimize(_quadratic(np.eye(2), np.zeros(2)), np.ones(2), admissible=lambda x: False)


def test_unreachable_gradient_tolerance_stops_at_roundoff_not_stagnation():
    # f = sum 1e8 (x - 1)^2 + 1e10 offset: at the minimizer g is limited by round-off of
    # 2e8 (x - 1) with x ~ 1 (~1e-8), far above grad_tol * scale for grad_tol = 1e-30. Newton
    # must stop by the step / round-off criteria (not iterate until max_iter, not raise).
    n = 50
    rng = np.random.default_rng(9)
    c = 1.0 + 1e-3 * rng.standard_normal(n)

    def fun(x, need_h):
        r = x - c
        return 1e10 + 1e8 * r @ r, 2e8 * r, (sp.identity(n, format="csr") * 2e8 if need_h else None)

    res = minimize(fun, np.zeros(n), options=NewtonOptions(grad_tol=1e-30))
    assert res.reason in ("step", "roundoff")
    assert res.iterations <= 3
    np.testing.assert_allclose(res.x, c, rtol=0, atol=1e-14)


def test_line_search_failure_raises():
    # a gradient inconsistent with f (wrong sign): every Newton step increases f
    def fun(x, need_h):
        return float(x @ x), -2 * x, (sp.identity(2, format="csr") * 2 if need_h else None)

    with pytest.raises(ConvergenceError, match="line search failed"):
        minimize(fun, np.array([1.0, -2.0]))


def test_a_step_whose_energy_change_is_below_resolution_is_taken_when_it_lowers_the_gradient():
    # f = 1 + q(x) + e(x): q = 1e-10/2 |x - c|^2 decreases by 2.5e-12 at the Newton step, less than
    # the 1e-11 that e (the rounding of a sum of cancelling terms, made deterministic here) adds at
    # every point but the start, so no trial passes the sufficient-decrease test while the predicted
    # decrease is above f's own rounding (not a flat search). The full step is within 1e-10 |f| and
    # zeroes the gradient: it is taken; a step that raises f by more is still a failure (above).
    c = np.array([0.1, -0.2])
    x0 = np.zeros(2)
    k = 1e-10

    def fun(x, need_h):
        r = x - c
        e = 0.0 if np.array_equal(x, x0) else 1e-11
        return 1.0 + 0.5 * k * r @ r + e, k * r, (sp.identity(2, format="csr") * k if need_h else None)

    with pytest.raises(ConvergenceError, match="line search failed"):
        minimize(fun, x0, options=NewtonOptions(grad_tol=1e-3, roundoff_terms=0.0))
    res = minimize(fun, x0, options=NewtonOptions(grad_tol=1e-3))
    assert res.converged and res.iterations == 1
    np.testing.assert_allclose(res.x, c, rtol=0, atol=1e-12)


def test_a_full_step_below_resolution_is_not_traded_for_a_shorter_one_that_passes_on_rounding():
    # f = 1 + q(x) + e(x): q = 1/2 |x - c|^2, e = 3e-11 (rounding, made deterministic here) only at the
    # minimizer c. From |x0 - c|^2 = 5e-11 the full Newton step lands on c and raises f by 5e-12 (<=
    # 1e-10 |f|: unresolved) while zeroing the gradient; the half step misses the bump and passes the
    # sufficient-decrease test on q alone. Taking the half step would repeat at every iteration (the
    # gradient halving each time): a Newton solve at a tight target was measured doing so 100 times.
    c = np.array([0.1, -0.2])
    x0 = c + np.sqrt(5e-11 / 2.0) * np.ones(2)

    def fun(x, need_h):
        r = x - c
        e = 3e-11 if np.allclose(x, c, rtol=0, atol=1e-15) else 0.0
        return 1.0 + 0.5 * r @ r + e, r, (sp.identity(2, format="csr") if need_h else None)

    res = minimize(fun, x0, options=NewtonOptions(grad_tol=1e-9))
    assert res.converged and res.reason == "gradient" and res.iterations == 1
    np.testing.assert_allclose(res.x, c, rtol=0, atol=1e-15)


def test_free_mask_shape_is_checked_and_all_fixed_returns_x0():
    A = _spd(4, 5)
    fun = _quadratic(A, np.ones(4))
    with pytest.raises(ValueError, match="free mask"):
        minimize(fun, np.zeros(4), free=np.ones(3, bool))
    x0 = np.arange(4.0)
    res = minimize(fun, x0, free=np.zeros(4, bool))
    np.testing.assert_array_equal(res.x, x0)
    assert res.iterations == 0


def test_invalid_options_are_rejected():
    with pytest.raises(ValueError, match="armijo"):
        NewtonOptions(armijo=0.7)
    with pytest.raises(ValueError, match="max_iter"):
        NewtonOptions(max_iter=0)


def test_exact_hessian_used_when_positive_definite_else_psd_fallback():
    # f = 1/2 x^T A x - b^T x with an "exact" Hessian A and a deliberately different PSD one:
    # with A positive definite the exact one must be used (1 step); with A indefinite the PSD
    # matrix is used and Newton still converges (on the convex quadratic defined by it)
    A = _spd(6, 11)
    b = np.ones(6)
    B = np.diag(np.diag(A))  # a PSD surrogate

    def fun(x, need_h):
        return 0.5 * x @ A @ x - b @ x, A @ x - b, ((sp.csr_matrix(A), sp.csr_matrix(B)) if need_h else None)

    res = minimize(fun, np.zeros(6))
    assert res.iterations == 1 and res.history[0]["hessian"] == "exact"

    A_ind = A - 1.5 * np.abs(np.linalg.eigvalsh(A)).max() * np.eye(6) * np.r_[1, 0, 0, 0, 0, 0][:, None]
    assert np.linalg.eigvalsh(A_ind).min() < 0
    Q = sp.csr_matrix(A + np.eye(6))  # convex objective, indefinite "exact" Hessian offered first

    def fun2(x, need_h):
        return 0.5 * x @ (A + np.eye(6)) @ x - b @ x, (A + np.eye(6)) @ x - b, \
            ((sp.csr_matrix(A_ind), Q) if need_h else None)

    res2 = minimize(fun2, np.zeros(6))
    assert all(h["hessian"] == "psd" for h in res2.history)
    np.testing.assert_allclose(res2.x, np.linalg.solve(A + np.eye(6), b), rtol=1e-9)


def test_retry_exact_false_stops_offering_an_indefinite_exact_hessian():
    # f = sum cosh(x_i) - b.x (convex, Hessian diag cosh x): Newton needs several iterations. The
    # "exact" Hessian offered first is indefinite at every iterate, so each of its factorizations
    # fails; with retry_exact=False it is tried once per solve, and the iterates are the same
    b = np.array([3.0, -2.0, 1.0, 0.5])

    def fun(x, need_h):
        h = np.cosh(x)
        pair = (sp.diags(h - np.r_[h[0] + 1.0, 0, 0, 0]).tocsr(), sp.diags(h).tocsr()) if need_h else None
        return float(np.cosh(x).sum() - b @ x), np.sinh(x) - b, pair

    class Counting:
        def __init__(self):
            self.inner, self.calls = SPDSolver(), 0

        def solve(self, A, rhs):
            self.calls += 1
            return self.inner.solve(A, rhs)

    runs = {}
    for retry in (True, False):
        solver = Counting()
        res = minimize(fun, np.zeros(4), options=NewtonOptions(grad_tol=1e-12, retry_exact=retry), solver=solver)
        runs[retry] = (res, solver.calls)
    (res_t, calls_t), (res_f, calls_f) = runs[True], runs[False]
    assert res_t.iterations == res_f.iterations >= 3
    np.testing.assert_allclose(res_t.x, res_f.x, rtol=1e-12)  # (the failed attempts leave round-off only)
    np.testing.assert_allclose(res_f.x, np.arcsinh(b), rtol=1e-10)
    assert calls_t == 2 * res_t.iterations  # a failed exact attempt and the PSD solve, every iteration
    assert calls_f == res_f.iterations + 1  # the exact one only at the first
    assert (res_t.exact_failures, res_f.exact_failures) == (res_t.iterations, 1)
    # exact_first=False: the projected Hessian throughout (no failed attempt, the same iterates)
    solver = Counting()
    res_p = minimize(fun, np.zeros(4), options=NewtonOptions(grad_tol=1e-12, retry_exact=False, exact_first=False),
                     solver=solver)
    assert solver.calls == res_p.iterations == res_f.iterations and res_p.exact_failures == 0
    assert all(h["hessian"] == "psd" for h in res_p.history)
    np.testing.assert_allclose(res_p.x, res_f.x, rtol=1e-12)


def test_zero_max_step_and_inadmissible_trials_raise():
    A = _spd(3, 12)
    fun = _quadratic(A, np.ones(3))
    with pytest.raises(ConvergenceError, match="max_step returned 0"):
        minimize(fun, np.zeros(3), max_step=lambda x, dx: 0.0)
    calls = []

    def admissible(x):  # only the start point is admissible: every trial is rejected
        calls.append(1)
        return len(calls) == 1

    with pytest.raises(ConvergenceError, match="line search failed"):
        minimize(fun, np.zeros(3), admissible=admissible)
