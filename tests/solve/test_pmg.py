"""Two-level P2 -> P1 p-multigrid (simfab.solve.pmg): the prolongation is exact on linear fields, the
preconditioner is symmetric, and CG with it solves a real P2 Hessian as CHOLMOD does."""

import numpy as np
import pytest
import scipy.sparse as sp

from simfab.solve.linear import NotPositiveDefinite, SPDSolver, conjugate_gradients
from simfab.solve.pmg import (
    MultigridConfig,
    MultigridSolver,
    SmootherConfig,
    TwoLevelP2,
    corner_prolongation,
    insertion_solver,
)


def _p2_box():
    """A clamped, slightly stretched 3D quadratic-tet box: 3 x 3 x 8 cubes of 6 tets lifted to 10-node
    tets, the z = 0 end clamped; (model, full Hessian CSR, free unknowns)."""
    from simfab.fem import elastic
    from simfab.fem.meshing import structured_box
    from simfab.fem.p2 import make_p2_model

    P, T = structured_box((0.01, 0.01, 0.03), (3, 3, 8))
    m = make_p2_model(P, T, "pla")
    H = sp.csr_matrix(elastic.energy_gradient_hessian(m, m.rest * 1.01)[2])
    free = np.flatnonzero(np.repeat(m.rest[:, 2] > 1e-9, 3))
    return m, H, free


def test_prolongation_reproduces_linear_fields():
    # a P2 field whose vertex values are those of u(X) = G X + c has, at every edge midpoint, the
    # mean of its edge's vertex values, which for a linear u is u at the midpoint: P u_c = u(X) exactly
    # (to round-off), per component; restricted to a free set, the free vertex values give the free rows
    m, _, free = _p2_box()
    rng = np.random.default_rng(0)
    G, c = rng.standard_normal((3, 3)), rng.standard_normal(3)
    u = m.rest @ G.T + c  # (n, 3)
    P = corner_prolongation(m.n_corners, m.edges, 3)
    assert P.shape == (3 * len(m.rest), 3 * m.n_corners)
    np.testing.assert_allclose(P @ u[: m.n_corners].ravel(), u.ravel(), rtol=0, atol=1e-12 * np.abs(u).max())
    Pf = corner_prolongation(m.n_corners, m.edges, 3, free)
    coarse = free[free < 3 * m.n_corners]
    assert Pf.shape == (len(free), len(coarse))
    uc = u.ravel()[coarse]
    # the free rows whose vertices are all free get the linear field; rows next to the clamp see 0 there
    u_clamped = u.ravel().copy()
    u_clamped[np.setdiff1d(np.arange(3 * m.n_corners), coarse)] = 0.0
    np.testing.assert_allclose(Pf @ uc, (P @ u_clamped[: 3 * m.n_corners])[free], rtol=0, atol=1e-12)


@pytest.mark.parametrize("kind", ["chebyshev", "sgs"])
def test_preconditioned_cg_matches_cholmod_on_a_p2_hessian(kind):
    # CG's error after a relative residual of 1e-10 is at most cond(A) * 1e-10 ~ 1e-5 relative (cond ~
    # 1e5 here); the solutions agree much better in practice: 1e-7 fails on a wrong preconditioner
    # only through the iteration count, so that is bounded too: the two-level cycle needs ~20
    # iterations here, point Jacobi alone > 300 (a prolongation that missed the vertices' motions
    # would leave the smooth modes to the smoother and need hundreds)
    if kind == "sgs":
        pytest.importorskip("pyamg")
    m, H, free = _p2_box()
    A = H[free][:, free].tocsr()
    b = np.random.default_rng(1).standard_normal(len(free))
    ref = SPDSolver().solve(A, b)
    pre = TwoLevelP2(corner_prolongation(m.n_corners, m.edges, 3, free), SmootherConfig(kind=kind, sweeps=2))
    pre.setup(A)
    bn = np.linalg.norm(b)
    res = conjugate_gradients(pre.apply, pre, b, max_iter=200, converged=lambda r, rn: rn <= 1e-10 * bn)
    assert res.converged and res.iterations <= 60
    assert np.linalg.norm(res.x - ref) <= 1e-7 * np.linalg.norm(ref)
    d = 1.0 / A.diagonal()
    jac = conjugate_gradients(pre.apply, lambda r: d * r, b, max_iter=200, converged=lambda r, rn: rn <= 1e-10 * bn)
    assert not jac.converged  # the comparison above is not trivially easy


def test_preconditioner_is_symmetric_with_the_low_rank_term():
    # CG needs M^-1 symmetric: u . M^-1 v = v . M^-1 u to round-off (Chebyshev pre- and post-smoothing
    # with the same polynomial around the exact coarse solve); the pin's rank-r term included
    m, H, free = _p2_box()
    A = H[free][:, free].tocsr()
    rng = np.random.default_rng(2)
    U = np.linalg.qr(rng.standard_normal((len(free), 3)))[0]
    pre = TwoLevelP2(corner_prolongation(m.n_corners, m.edges, 3, free))
    pre.setup(A, U, float(A.diagonal().mean()))
    u, v = rng.standard_normal((2, len(free)))
    assert u @ pre(v) == pytest.approx(v @ pre(u), rel=1e-10)
    assert u @ pre(u) > 0.0


def test_multigrid_solver_matches_the_woodbury_direct_solve():
    # the pinned Newton solve (A + mu U U^T) x = b by p-multigrid CG to rtol 1e-9, no fine factorization
    m, H, free = _p2_box()
    rng = np.random.default_rng(3)
    U = np.linalg.qr(rng.standard_normal((len(free), 3)))[0]
    mu = float(H.diagonal().mean())
    b = rng.standard_normal(len(free))
    ref = SPDSolver().solve_free_update(H, free, b, U, mu)
    s = insertion_solver(m, multigrid=MultigridConfig(min_unknowns=0, rtol=1e-9))
    assert isinstance(s, MultigridSolver)
    x = s.solve_free_lagged(H, free, b, U, mu)
    assert np.linalg.norm(x - ref) <= 1e-6 * np.linalg.norm(ref)
    assert s.factorizations == 0 and s.multigrid_solves == 1 and s.coarse_factorizations == 1
    y = s.solve_free(H, free, b)  # without the pin: the plain free block
    assert np.linalg.norm(H[free][:, free] @ y - b) <= 1e-9 * np.linalg.norm(b)


def test_iterative_solves_stop_at_the_forcing_they_are_given():
    # inexact Newton: a multigrid solve stops at the rtol or the residual's largest entry (atol) it is
    # given; the insertion's unpinned solves get them from Newton's force target (far from it two
    # digits, near it the solver's own rtol, either way a tenth of the target), as its pinned ones do
    from simfab.coupling.objective import pinned
    from simfab.coupling.rigid import LAG_RTOL_FAR, LAG_TARGET, PCG_NEAR, ForcedSolver

    m, H, free = _p2_box()
    rng = np.random.default_rng(5)
    b = rng.standard_normal(len(free))
    Aff = H[free][:, free]
    s = insertion_solver(m, multigrid=MultigridConfig(min_unknowns=0, rtol=1e-9))
    x = s.solve_free(H, free, b)
    full = s.multigrid_iterations
    assert np.linalg.norm(Aff @ x - b) <= 1e-9 * np.linalg.norm(b)
    x = s.solve_free(H, free, b, rtol=1e-2)
    loose = s.multigrid_iterations - full
    assert np.linalg.norm(Aff @ x - b) <= 1e-2 * np.linalg.norm(b) and 0 < loose < full / 2
    atol = 1e-4 * np.abs(b).max()
    x = s.solve_free(H, free, b, atol=atol)
    assert np.abs(Aff @ x - b).max() <= atol and s.factorizations == 0
    # far from the target (|b| > PCG_NEAR target): two digits
    far = float(np.abs(b).max()) / (10 * PCG_NEAR)
    forced = pinned(s, None, target=far)
    assert isinstance(forced, ForcedSolver) and pinned(s, None) is s
    done = s.multigrid_iterations
    x = forced.solve_free(H, free, b)
    r = Aff @ x - b
    assert np.linalg.norm(r) <= LAG_RTOL_FAR * np.linalg.norm(b) or np.abs(r).max() <= LAG_TARGET * far
    assert s.multigrid_iterations - done <= loose
    # near it: the solver's rtol, or a tenth of the target
    near = float(np.abs(b).max()) / 10
    x = pinned(s, None, target=near).solve_free(H, free, b)
    assert np.abs(Aff @ x - b).max() <= LAG_TARGET * near


def test_below_the_threshold_it_factorizes_and_indefinite_matrices_raise():
    m, H, free = _p2_box()
    b = np.ones(len(free))
    s = insertion_solver(m, multigrid=MultigridConfig(min_unknowns=len(free) + 1))
    x = s.solve_free(H, free, b)
    assert s.factorizations == 1 and s.multigrid_solves == 0
    np.testing.assert_allclose(x, SPDSolver().solve_free(H, free, b), rtol=1e-10, atol=1e-14)
    # clearly indefinite: negative curvature in CG (or a failed factorization) says so
    lam = float(np.abs(H.diagonal()).max())
    Hn = (H - 2 * lam * sp.identity(H.shape[0])).tocsr()
    forced = insertion_solver(m, multigrid=MultigridConfig(min_unknowns=0))
    with pytest.raises(NotPositiveDefinite):
        forced.solve_free(Hn, free, b)


def test_a_linear_model_gets_the_plain_solver_and_configs_are_checked():
    from simfab.fem.meshing import structured_box
    from simfab.fem.model import make_model

    P, T = structured_box((0.01, 0.01, 0.01), (2, 2, 2))
    assert type(insertion_solver(make_model(P, T, "pla"))) is SPDSolver
    for bad in ({"min_unknowns": -1}, {"rtol": 1.0}, {"max_iter": 0}, {"smoother": SmootherConfig(kind="sgs")}):
        with pytest.raises(ValueError):
            MultigridConfig(**bad)
    for bad in ({"kind": "jacobi"}, {"sweeps": 0}, {"ratio": 1.0}):
        with pytest.raises(ValueError):
            SmootherConfig(**bad)


def test_a_lagged_solve_comes_first_and_is_skipped_after_it_fails():
    # cost order: on a factorization of this pattern, the lagged solve (LagConfig) is tried first; once
    # it has failed on that factorization, later solves go straight to p-multigrid CG
    from simfab.solve.linear import LagConfig

    m, H, free = _p2_box()
    rng = np.random.default_rng(4)
    b = rng.standard_normal(len(free))
    s = insertion_solver(m, lag=LagConfig(min_unknowns=0, max_iter=12),
                         multigrid=MultigridConfig(min_unknowns=0, rtol=1e-9))
    s.solve_free(H, free, b)
    assert s.factorizations == 0 and s.multigrid_solves == 1  # no factorization to lag on yet
    H2 = H.copy()
    H2.data = H2.data * 1.001  # a nearby Hessian: the factorization preconditions it within 12 iterations
    s.solve_free(H, free, np.column_stack([b, b]))  # two columns: neither iteration, H is factorized
    assert s.factorizations == 1
    x = s.solve_free(H2, free, b)
    assert s.lagged_solves == 1 and s.multigrid_solves == 1
    assert np.linalg.norm(H2[free][:, free] @ x - b) <= 1e-6 * np.linalg.norm(b)
    # a Hessian far from the factorized one (a stiff diagonal term, as a barrier's): the lagged solve
    # does not converge in 12 iterations, p-multigrid CG does
    H3 = H.copy()
    H3.setdiag(H.diagonal() + 5.0 * float(H.diagonal().mean()))  # the same pattern
    iters = s.pcg_iterations
    y = s.solve_free(H3, free, b)
    assert s.pcg_iterations > iters and s.lagged_solves == 1 and s.multigrid_solves == 2
    assert np.linalg.norm(H3[free][:, free] @ y - b) <= 1.01e-9 * np.linalg.norm(b)
    iters = s.pcg_iterations
    s.solve_free(H2, free, b)  # the same factorization: not lagged again
    assert s.pcg_iterations == iters and s.multigrid_solves == 3


def test_coarse_factorizations_are_counted_across_free_sets():
    # a new free set (fewer clamped vertices) builds a new coarse solver; the count keeps the old one's
    m, H, free = _p2_box()
    s = insertion_solver(m, multigrid=MultigridConfig(min_unknowns=0, rtol=1e-9))
    s.solve_free(H, free, np.ones(len(free)))
    free2 = free[3:]  # one more node held
    s.solve_free(H, free2, np.ones(len(free2)))
    assert s.multigrid_solves == 2 and s.coarse_factorizations == 2 and s.factorizations == 0


def test_the_gauss_seidel_smoother_without_pyamg_is_a_clear_error(monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "pyamg" else real(name, *a))
    with pytest.raises(ValueError, match="needs pyamg"):
        SmootherConfig(kind="sgs")
    SmootherConfig(kind="chebyshev")  # the default smoother needs nothing more
