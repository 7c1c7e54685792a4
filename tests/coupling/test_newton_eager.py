"""Newton's eager-Hessian line search (used by the insertion solver) takes the same steps as the
plain one: only where the Hessian is evaluated changes, not the iterates."""

import numpy as np
import scipy.sparse as sp

from simfab.solve.newton import NewtonOptions, minimize


def _objective(calls):
    # f(x) = sum_i (x_i^4 / 4 + x_i^2 / 2 - b_i x_i) + 1/2 sum_i (x_{i+1} - x_i)^2: strictly convex,
    # minimizer where x^3 + x + (L x) = b (L: path Laplacian)
    n = 12
    b = np.linspace(-2.0, 3.0, n)
    L = sp.diags([-np.ones(n - 1), np.r_[1.0, 2.0 * np.ones(n - 2), 1.0], -np.ones(n - 1)], [-1, 0, 1]).tocsr()

    def fun(x, need_hessian):
        calls.append(need_hessian)
        f = float(np.sum(x**4 / 4 + x**2 / 2 - b * x) + 0.5 * x @ (L @ x))
        g = x**3 + x - b + L @ x
        H = (sp.diags(3 * x**2 + 1) + L).tocsr() if need_hessian else None
        return f, g, H

    return fun, b, L, n


def test_eager_hessian_gives_the_same_iterates():
    results = {}
    for eager in (False, True):
        calls = []
        fun, b, L, n = _objective(calls)
        res = minimize(fun, np.full(n, 3.0), options=NewtonOptions(grad_tol=1e-12, eager_hessian=eager))
        results[eager] = (res, calls)
    (r0, c0), (r1, c1) = results[False], results[True]
    assert r0.iterations == r1.iterations
    assert np.array_equal(r0.x, r1.x)
    g = r1.x**3 + r1.x - b + L @ r1.x
    assert np.abs(g).max() <= 1e-10
    # eager: an accepted first trial already carries its Hessian, so fewer evaluations overall
    assert len(c1) < len(c0)


def test_no_hessian_for_a_trial_that_is_likely_the_last():
    # Near the target (eager_above_tol), the trial is evaluated without its Hessian and Newton
    # checks convergence first: the same iterates, one Hessian fewer when the trial converges.
    results = {}
    for above in (0.0, 1e6):
        calls = []
        fun, b, L, n = _objective(calls)
        opts = NewtonOptions(grad_tol=1e-12, eager_hessian=True, eager_above_tol=above)
        results[above] = (minimize(fun, np.full(n, 3.0), options=opts), calls)
    (r0, c0), (r1, c1) = results[0.0], results[1e6]
    assert r0.iterations == r1.iterations and np.array_equal(r0.x, r1.x)
    assert sum(c0) == sum(c1) + 1  # the converged last trial carried no Hessian
    assert not c1[-1]  # ... and was the last evaluation
