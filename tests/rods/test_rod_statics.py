"""Static solver with rigid bodies: exact reduced gradient (chain rule through body rotations),
equilibrium of a cantilever against Euler-Bernoulli, bad input."""

import numpy as np
import pytest

from simfab.errors import InputError
from simfab.rods.model import NetworkBuilder, RodMaterial, Section
from simfab.rods.statics import StaticSolver

MAT = RodMaterial(young=2e9, poisson=0.35)
SEC = Section(width=5e-3, thickness=1e-3)


def two_rods_on_a_free_body():
    nb = NetworkBuilder()
    nb.add_body("anchor", pos=(0, 0, 0), driven=True)
    nb.add_body("junction", pos=(0.05, 0, 0))
    nb.add_rod("a", np.linspace([0, 0, 0], [0.05, 0, 0], 9), section=SEC, material=MAT)
    nb.add_rod("b", np.linspace([0.05, 0, 0], [0.05, 0.04, 0.01], 9), section=SEC, material=MAT)
    nb.clamp("a", "start", "anchor")
    nb.clamp("a", "end", "junction")
    nb.clamp("b", "start", "junction")
    return nb.build()


def test_reduced_gradient_through_rigid_body_matches_finite_differences():
    model, st = two_rods_on_a_free_body()
    solver = StaticSolver(model)
    rng = np.random.default_rng(3)
    # a generic deformed state (body moved and rotated, nodes displaced)
    q = rng.normal(scale=2e-3, size=solver.red.nq)
    st = solver.red.apply(st, q)
    E, g, _ = solver.objective(st, True, False, None, None)
    h = 1e-7
    I = np.eye(solver.red.nq)
    gfd = np.array([(solver.objective(solver.red.apply(st, h * I[i]), False, False, None, None)[0]
                     - solver.objective(solver.red.apply(st, -h * I[i]), False, False, None, None)[0]) / (2 * h)
                    for i in range(solver.red.nq)])
    assert np.max(np.abs(g - gfd)) <= 1e-5 * np.max(np.abs(g))


def test_cantilever_tip_load_small_deflection():
    """Clamped cantilever (clamp = first edge, centred on the support), tip force F:
    delta = F L^3 / (3 B1) for small loads. Tolerance 1% (O(h^2) discretization + O(delta^2/L^2)
    geometric nonlinearity at delta/L ~ 1e-3)."""
    n, L = 40, 0.1
    h = L / n
    nb = NetworkBuilder()
    s = -0.5 * h + h * np.arange(n + 2)
    s[-1] = L
    nb.add_rod("c", np.stack([s, 0 * s, 0 * s], 1), section=SEC, material=MAT)
    nb.fix("c", nodes=[0, 1], thetas=[0])
    model, st = nb.build()
    B1 = SEC.stiffness(MAT)["B1"]
    F = 3 * B1 * 1e-3 * L / L**3  # tip deflection 1e-3 L
    f = np.zeros((model.n_nodes, 3))
    f[-1, 2] = F
    res = StaticSolver(model).solve(st, node_forces=f)
    assert res.state.x[-1, 2] == pytest.approx(F * L**3 / (3 * B1), rel=1e-2)


def test_builder_rejects_bad_input():
    nb = NetworkBuilder()
    with pytest.raises(InputError):
        nb.add_rod("r", np.zeros((3, 3)), section=SEC, material=MAT)  # repeated points
    with pytest.raises(InputError):
        Section(width=-1, thickness=1e-3)
    with pytest.raises(InputError):
        RodMaterial(young=1e9, poisson=0.7)
    nb.add_rod("r", np.linspace([0, 0, 0], [1, 0, 0], 5), section=SEC, material=MAT)
    nb.clamp("r", "start", "nobody")
    with pytest.raises(InputError):
        nb.build()
    for fix in (dict(rod="nowhere", nodes=[0]), dict(rod="r", nodes=[5]), dict(rod="r", thetas=[4])):
        nb = NetworkBuilder()
        nb.add_rod("r", np.linspace([0, 0, 0], [1, 0, 0], 5), section=SEC, material=MAT)  # 5 nodes, 4 edges
        nb.fix(**fix)
        with pytest.raises(InputError):
            nb.build()


def test_banded_cholesky_matches_sparse_and_detects_indefinite():
    import scipy.sparse as sp

    from simfab.rods.statics import BandedOrSparseCholesky, ShiftedCholesky
    from simfab.solve.linear import NotPositiveDefinite, SPDSolver

    rng = np.random.default_rng(5)
    n = 60
    # a shuffled chain (band after RCM) made SPD
    A = sp.diags([rng.uniform(4, 5, n), rng.uniform(-1, 1, n - 1), rng.uniform(-1, 1, n - 2)], [0, 1, 2])
    A = (A + A.T).tocsr()
    p = rng.permutation(n)
    A = A[p][:, p]
    b = rng.normal(size=n)
    x = BandedOrSparseCholesky().solve(A, b)
    assert np.allclose(x, SPDSolver().solve(A, b), rtol=1e-12, atol=1e-12)
    # non-canonical input (each value split into two duplicate entries) is summed, not overwritten
    A.sort_indices()
    dup = sp.csr_matrix((np.repeat(0.5 * A.data, 2), np.repeat(A.indices, 2), 2 * A.indptr), shape=A.shape)
    assert not dup.has_canonical_format
    assert np.allclose(BandedOrSparseCholesky().solve(dup, b), x, rtol=1e-12, atol=1e-12)
    with pytest.raises(NotPositiveDefinite):
        BandedOrSparseCholesky().solve(A - 20 * sp.identity(n), b)
    # the shifted solver returns a descent direction for an indefinite matrix
    d = ShiftedCholesky().solve(A - 6 * sp.identity(n), b)
    assert np.all(np.isfinite(d)) and d @ b > 0


def test_flat_unit_cell_network_is_stress_free():
    """Rods joined through free junction bodies, before any insert mismatch: zero energy and residual."""
    from simfab.deploy.unitcell import CellConfig, build_cell

    cell = build_cell(CellConfig())
    solver = StaticSolver(cell.model)
    g, _ = solver.reduced_system(cell.state)
    E, _, _ = solver.evaluator(cell.state, False, False)
    assert abs(E) <= 1e-18
    assert np.max(np.abs(g)) <= 1e-9 * cell.model.force_scale


def unit_cell_network():
    from simfab.deploy.unitcell import CellConfig, build_cell

    cell = build_cell(CellConfig())  # 13 free bodies (insert, T-junctions, corner junctions)
    return cell.model, cell.state


# (network, size of the random deformation [m], second-difference step hs): the unit cell's
# 2.5 mm edges and 15 mm clamp levers make its energy vary on shorter scales, hence the smaller
# step; the truncation error ~ hs^2 is below 1e-5 relative in both cases (checked by varying hs)
@pytest.mark.parametrize("network, deform, hs",
                         [(two_rods_on_a_free_body, 2e-3, 1e-5), (unit_cell_network, 1e-4, 1e-6)])
def test_reduced_hessian_through_rigid_body_matches_second_differences(network, deform, hs):
    """H_q (J^T H J + geometric term of the body rotations) vs d^2/ds^2 E(apply(state, s v)) at s = 0,
    for one free body and for many (the geometric term is assembled for all bodies at once)."""
    model, st = network()
    solver = StaticSolver(model)
    rng = np.random.default_rng(4)
    st = solver.red.apply(st, rng.normal(scale=deform, size=solver.red.nq))
    E, _, H = solver.objective(st, True, True, None, None)
    Hd = H.toarray()
    for _ in range(4):
        v = rng.normal(size=solver.red.nq)
        e2 = (solver.objective(solver.red.apply(st, hs * v), False, False, None, None)[0] - 2 * E
              + solver.objective(solver.red.apply(st, -hs * v), False, False, None, None)[0]) / hs**2
        assert v @ Hd @ v == pytest.approx(e2, rel=1e-4)


def test_shifted_cholesky_shift_is_a_plus_mu_identity():
    """The in-place diagonal shift equals A + mu I, also for a pattern with an unstored diagonal entry."""
    import scipy.sparse as sp

    from simfab.rods.statics import ShiftedCholesky

    rng = np.random.default_rng(6)
    n = 12
    D = rng.normal(size=(n, n)) * (rng.uniform(size=(n, n)) < 0.3)
    full = sp.csr_matrix(D + D.T + np.diag(rng.uniform(1, 2, n)))
    holed = full.tolil()
    holed[3, 3] = 0.0
    holed = sp.csr_matrix(holed)
    holed.eliminate_zeros()
    assert full.diagonal().all() and holed.nnz < full.nnz
    solver = ShiftedCholesky()
    for A in (full, holed, full):  # pattern changes, then back: the diagonal map follows
        A0 = A.toarray()
        shifted = solver.shifter(A)
        for mu in (1e-3, 7.5):
            np.testing.assert_array_equal(shifted(mu).toarray(), A0 + mu * np.eye(n))
        np.testing.assert_array_equal(A.toarray(), A0)  # the caller's matrix is not modified
