"""The per-step objective E_d + kappa sum b(d_j): gradient against finite differences and the
assembled contact Hessian against J^T blockdiag(H_j) J for points interpolated on edges."""

import numpy as np
import pytest

from simfab.contact.barrier import point_barrier
from simfab.coupling import config as C
from simfab.coupling.layout import EDGE_PAIRS
from simfab.coupling.objective import StepObjective
from simfab.coupling.points import edge_weights, facet_points, vertex_points
from simfab.coupling.refine import COVER, check_lattice
from simfab.coupling.rigid import mean_stiffness
from simfab.coupling.timing import Timer
from simfab.fem.elastic import energy_gradient_hessian


def _objective_near_contact(coarse_block_model):
    cm = coarse_block_model(refine=True)
    facets = np.asarray(cm.fem.boundary_facets)
    top = [i for i, f in enumerate(facets) if set(f.tolist()) == {2, 3}]
    pts = vertex_points(np.asarray(cm.fem.boundary_vertices), 2).concat(facet_points(facets, top, edge_weights(20)))
    # place the circle so that the top edge's middle points are inside the barrier band
    R, p = cm.pose(0.0)
    p = np.array([0.0, 3e-3 + 0.4 * cm.dhat, 0.0])
    obj = StepObjective(cm, pts, R, p, Timer())
    return cm, pts, obj


def test_objective_gradient_matches_finite_differences(coarse_block_model):
    cm, pts, obj = _objective_near_contact(coarse_block_model)
    x = cm.fem.rest.ravel().copy()
    f, g, _ = obj(x, True)
    d, _, _ = obj.distances(x.reshape(-1, 2), False)
    assert np.isfinite(f) and np.any(d < cm.dhat)  # some points are in the barrier band
    rng = np.random.default_rng(0)
    h = 1e-4 * cm.dhat
    for i in rng.choice(x.size, 6, replace=False).tolist() + [5, 7]:  # include the top vertices' y dofs
        e = np.zeros_like(x)
        e[i] = h
        fd = (obj(x + e, False)[0] - obj(x - e, False)[0]) / (2 * h)
        assert abs(fd - g[i]) <= 1e-5 * max(abs(g[i]), 1e-3 * np.abs(g).max())


def test_contact_hessian_is_jt_h_j(coarse_block_model):
    # Both Hessians handed to Newton (exact first, PSD-projected fallback) carry the contact term
    # J^T blockdiag(H_j) J, with H_j exact or projected per point, plus the same diagonal
    # rigid-mode regularization.
    cm, pts, obj = _objective_near_contact(coarse_block_model)
    x = cm.fem.rest.copy()
    _, _, (H_exact, H_psd) = obj(x.ravel(), True)
    H_psd = H_psd() if callable(H_psd) else H_psd  # the projected Hessian may be built on demand
    d, gd, hd = obj.distances(x, True)
    act = d < obj.dhat  # the activation distance of each point (local edge length)
    n = cm.fem.n_vertices
    J = np.zeros((act.sum(), 2, 2 * n))
    for k, j in enumerate(np.flatnonzero(act)):
        for a in range(2):
            v, w = pts.verts[j, a], pts.weights[j, a]
            J[k, :, 2 * v:2 * v + 2] += w * np.eye(2)
    for H, project in ((H_psd, True), (H_exact, False)):
        _, _, Hf = energy_gradient_hessian(cm.fem, x, project_psd=project)
        _, _, Hy = point_barrier(d[act], gd[act], hd[act], obj.dhat[act], cm.kappa, psd=project)
        ref = np.einsum("kia,kij,kjb->ab", J, Hy, J)
        off = (H - Hf).toarray() - ref
        reg = C.FACTOR_REG * mean_stiffness(cm)
        # what remains is the diagonal rigid-mode regularization only
        assert np.allclose(off - np.diag(np.diag(off)), 0.0, atol=1e-9 * np.abs(ref).max())
        assert np.all(np.abs(np.diag(off)) <= 10 * reg + 1e-9 * np.abs(ref).max())


def test_evaluation_without_hessian_defers_the_same_psd_hessian(coarse_block_model):
    # Newton may stop at a trial evaluated without its Hessian; the objective then keeps a deferred
    # PSD Hessian (for the predictor) that must equal the one an evaluation with Hessian builds.
    cm, pts, obj = _objective_near_contact(coarse_block_model)
    x = cm.fem.rest.ravel().copy()
    f1, g1, H = obj(x, False)
    assert H is None and np.array_equal(obj.last_x, x)
    deferred = obj.last_H()
    f2, g2, (_, lazy) = obj(x, True)
    assert f1 == f2 and np.array_equal(g1, g2)
    assert np.any(obj.last_d < cm.dhat)  # contact blocks are part of it
    diff = deferred - lazy()
    assert diff.nnz == 0 or np.abs(diff.data).max() == 0.0


@pytest.mark.parametrize("gap_dhats", [0.5, 1.5, 3.0, 7.0])
def test_step_cap_stops_approaching_points_outside_o(coarse_block_model, gap_dhats):
    # the top edge pushed straight into the circle by more than its gap: the full step penetrates,
    # the capped one leaves every point at least t from O: 0.1 d within the barrier's range, else
    # CAP_LAND_DHATS d_hat (d its gap before the step: at 1.5 d_hat no deeper than 0.5 d_hat, not 0.15;
    # the curvature bound K >= 0.1 / sigma exceeds the circle's 1 / (3 mm))
    cm = coarse_block_model(refine=True)
    facets = np.asarray(cm.fem.boundary_facets)
    top = [i for i, f in enumerate(facets) if set(f.tolist()) == {2, 3}]
    pts = vertex_points(np.asarray(cm.fem.boundary_vertices), 2).concat(facet_points(facets, top, edge_weights(20)))
    R, _ = cm.pose(0.0)
    obj = StepObjective(cm, pts, R, np.array([0.0, 3e-3 + gap_dhats * cm.dhat, 0.0]), Timer())
    x = cm.fem.rest.copy()
    obj(x.ravel(), True)  # sets the curvature bound from the contact Hessians
    d0 = obj.last_d.copy()
    dx = np.zeros_like(x)
    dx[[2, 3], 1] = (gap_dhats + 1.0) * cm.dhat
    alpha = obj.max_step(x.ravel(), dx.ravel())
    R_, p_ = obj.R, obj.p
    full = -cm.field.evaluate(pts.positions(x + dx), (R_, p_), hessian=False).psi
    capped = -cm.field.evaluate(pts.positions(x + alpha * dx), (R_, p_), hessian=False).psi
    assert full.min() < 0 and 0 < alpha < 1
    t = np.where(d0 < obj.dhat, (1 - C.STEP_FRACTION) * d0, C.CAP_LAND_DHATS * obj.dhat)
    assert np.all(capped >= t * (1 - 1e-6))


@pytest.mark.parametrize("dim,order,refined", [(2, 10, False), (2, 10, True), (3, 4, False), (3, 4, True),
                                               (3, 9, True)])
def test_check_lattice_gaps_equal_the_distances_to_the_facet_vertices(dim, order, refined):
    # the facet check bounds psi at a check point from the facet's vertices by L |y - v|; the
    # distances come from squared edge lengths through a precomputed map: compare with |y - v|
    rng = np.random.default_rng(3)
    xv = rng.standard_normal((50, dim, dim)) * rng.uniform(0.01, 3.0, (50, 1, 1))  # 50 facets of dim vertices
    w, G = check_lattice(dim, order, refined)
    a, c = EDGE_PAIRS[dim]
    edges2 = np.sum((xv[:, a] - xv[:, c]) ** 2, axis=2)
    gap = np.sqrt(np.maximum(edges2 @ G, 0.0)).reshape(50, len(w), dim)
    y = w @ xv
    ref = np.linalg.norm(y[:, :, None, :] - xv[:, None, :, :], axis=3)
    np.testing.assert_allclose(gap, ref, rtol=1e-12, atol=1e-12 * np.abs(xv).max())


@pytest.mark.parametrize("repeat_vertices", [False, True])
def test_scatter_is_the_transpose_of_positions(repeat_vertices):
    # positions(x) = W x for a fixed weight matrix W; scatter applies W^T, also to given rows (the
    # gradient and force route of every point term), also for a set listing a vertex twice.
    from simfab.coupling.points import face_weights

    rng = np.random.default_rng(5)
    n, dim = 30, 3
    facets = rng.integers(0, n, size=(12, 3))
    plain = np.arange(0, n, 2) if not repeat_vertices else np.r_[np.arange(0, n, 2), [4, 4]]
    pts = vertex_points(plain, dim).concat(facet_points(facets, np.arange(12), face_weights(3)))
    k = len(pts)
    W = np.zeros((k, n))
    for j in range(k):
        np.add.at(W[j], pts.verts[j], pts.weights[j])
    x = rng.normal(size=(n, dim))
    assert np.allclose(pts.positions(x), W @ x, rtol=0, atol=1e-14)
    g = rng.normal(size=(k, dim))
    assert np.allclose(pts.scatter(g, n), W.T @ g, rtol=0, atol=1e-13)
    rows = rng.choice(k, size=k // 3, replace=False)
    if repeat_vertices:  # both listings of vertex 4
        rows = np.union1d(rows, [len(plain) - 2, len(plain) - 1])
    for sub in (np.sort(rows), rows[rows < len(plain)]):  # mixed, plain vertices only
        dense = np.zeros((k, dim))
        dense[sub] = g[sub]
        assert np.allclose(pts.scatter(g[sub], n, rows=sub), W.T @ dense, rtol=0, atol=1e-13)


@pytest.mark.parametrize("dim", [2, 3])
def test_every_facet_point_is_within_cover_of_a_vertex(dim):
    # the facet check leaves out facets whose vertices are all farther than L * cover from O:
    # sound only if no point of a facet is farther than cover (x longest edge) from every vertex
    rng = np.random.default_rng(9)
    w = rng.dirichlet(np.ones(dim), size=4000)  # points on the facet (barycentric)
    worst = 0.0
    for _ in range(300):
        v = rng.normal(size=(dim, 3)) * rng.uniform(0.1, 3.0, size=(1, 3))  # acute, obtuse, slivers
        y = w @ v
        near = np.min(np.linalg.norm(y[:, None, :] - v[None], axis=2), axis=1).max()
        c = max(np.linalg.norm(v[a] - v[b]) for a in range(dim) for b in range(a))
        worst = max(worst, near / c)
    assert worst <= COVER[dim] * (1 + 1e-12)
    assert worst > 0.9 * COVER[dim]  # and the bound is nearly reached (not loose)
