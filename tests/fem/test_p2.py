"""Quadratic (P2) elements: quadrature, shape functions, model structure, Neo-Hookean derivatives
against finite differences, PSD projection, patch and quadratic-field tests, and the cantilever
against Timoshenko beam theory (where linear elements lock)."""

import itertools
from math import factorial

import numpy as np
import pytest
from _fem_meshes import box_tet, fd_grad_hess
from scipy.spatial.transform import Rotation

from simfab.fem import elastic as nh
from simfab.fem.materials import Material
from simfab.fem.model import make_model
from simfab.fem.neohookean import LINEAR
from simfab.fem.neohookean_p2 import QUADRATIC, projected_stress_hessian
from simfab.fem.p2 import RULES, make_p2_model, shape_functions, to_p2
from simfab.verification.cantilever import cantilever_model, rectangle_mesh, solve_cantilever, static_solve

MAT = Material(name="test", youngs_modulus=1.0e3, poisson_ratio=0.3, yield_stress=1e9, density=1.0)


# ----------------------------------------------------------------------------------------------
# quadrature, shape functions, model structure
# ----------------------------------------------------------------------------------------------
def _monomial_errors(dim, degree):
    """Max relative error of the rule on the barycentric monomials of each total degree 0..degree+1.
    Exact: int L^a dV / V = a_0! .. a_d! d! / (|a| + d)!"""
    L, w = RULES[(dim, degree)]
    errs = {}
    for exps in itertools.product(range(degree + 2), repeat=dim + 1):
        p = sum(exps)
        if p > degree + 1:
            continue
        exact = np.prod([factorial(e) for e in exps]) * factorial(dim) / factorial(p + dim)
        got = (w * np.prod(L ** np.array(exps), axis=1)).sum()
        errs[p] = max(errs.get(p, 0.0), abs(got - exact) / exact)
    return errs


@pytest.mark.parametrize("dim,degree", sorted(RULES))
def test_quadrature_is_exact_to_its_degree_and_not_beyond(dim, degree):
    errs = _monomial_errors(dim, degree)
    assert max(errs[p] for p in range(degree + 1)) < 1e-13  # tabulated digits: ~15
    assert errs[degree + 1] > 1e-3  # the stated degree is the rule's actual degree
    L, w = RULES[(dim, degree)]
    assert np.all(w > 0) and np.all(L >= 0)  # positive weights (PSD sums), points inside


@pytest.mark.parametrize("dim", [2, 3])
def test_shape_functions_are_nodal_and_reproduce_quadratics(dim):
    rng = np.random.default_rng(dim)
    # node barycentrics: corners, then edge midpoints in the documented order
    from simfab.fem.p2 import EDGE_PAIRS

    eye = np.eye(dim + 1)
    nodes = np.vstack([eye, 0.5 * (eye[EDGE_PAIRS[dim][:, 0]] + eye[EDGE_PAIRS[dim][:, 1]])])
    N, dN = shape_functions(nodes, dim)
    np.testing.assert_allclose(N, np.eye(len(nodes)), atol=1e-15)  # Kronecker property
    L = rng.dirichlet(np.ones(dim + 1), size=20)
    N, dN = shape_functions(L, dim)
    np.testing.assert_allclose(N.sum(1), 1.0, atol=1e-14)  # partition of unity
    # any quadratic in L is interpolated exactly: f = L^T Q L
    Q = rng.standard_normal((dim + 1, dim + 1))
    f = lambda L: np.einsum("qi,ij,qj->q", L, Q, L)  # noqa: E731
    np.testing.assert_allclose(N @ f(nodes), f(L), atol=1e-13)
    # derivatives along the element (L_i up, L_0 down: the barycentric extension off the plane
    # sum L = 1 is not unique, its tangential derivatives are)
    D, Df = np.einsum("qal,a->ql", dN, f(nodes)), L @ (Q + Q.T)
    np.testing.assert_allclose(D[:, 1:] - D[:, :1], Df[:, 1:] - Df[:, :1], atol=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_p2_model_structure_midpoints_and_boundary(dim):
    if dim == 2:
        P, T = rectangle_mesh(2.0, 1.0, 4, 3)
        lin = make_model(P, T, MAT, thickness=0.1)
    else:
        P, T = box_tet(2.0, 1.0, 1.0, 3, 2, 2)
        lin = make_model(P, T, MAT)
    m = to_p2(lin)
    n_edges = len({tuple(sorted(e)) for t in T for e in itertools.combinations(t, 2)})
    assert m.n_vertices == lin.n_vertices + n_edges == m.n_corners + len(m.edges)
    np.testing.assert_array_equal(m.corner_elements, lin.elements)
    # midpoint nodes sit at the centre of their edge, element-locally in the documented order
    from simfab.fem.p2 import EDGE_PAIRS

    pairs = EDGE_PAIRS[dim]
    Xc = m.rest[m.elements[:, : dim + 1]]
    np.testing.assert_allclose(m.rest[m.elements[:, dim + 1:]], 0.5 * (Xc[:, pairs[:, 0]] + Xc[:, pairs[:, 1]]))
    # quadrature weights integrate the volume
    np.testing.assert_allclose(m.qp_weight.sum(1), lin.volume, rtol=1e-14)
    # boundary: every P2 facet's corners are a linear boundary facet, midpoints in between;
    # sub-facets have the parent's orientation and tile it; total boundary measure = box surface
    np.testing.assert_array_equal(m.boundary_facets[:, :dim], lin.boundary_facets)
    if dim == 2:
        seg = m.rest[m.boundary_subfacets]
        d = seg[:, 1] - seg[:, 0]
        parent = m.rest[m.boundary_facets[:, 1]] - m.rest[m.boundary_facets[:, 0]]
        np.testing.assert_allclose(d.reshape(-1, 2, 2).sum(1), parent, atol=1e-14)
        assert np.linalg.norm(d, axis=1).sum() == pytest.approx(2 * (2.0 + 1.0))
    else:
        tri = m.rest[m.boundary_subfacets]
        nrm = 0.5 * np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        ptri = m.rest[m.boundary_facets[:, :3]]
        pn = 0.5 * np.cross(ptri[:, 1] - ptri[:, 0], ptri[:, 2] - ptri[:, 0])
        np.testing.assert_allclose(nrm.reshape(-1, 4, 3).sum(1), pn, atol=1e-14)
        np.testing.assert_allclose(nrm.reshape(-1, 4, 3), np.repeat(pn[:, None] / 4, 4, 1), atol=1e-14)
        # outward: the divergence theorem gives the volume from the oriented boundary
        assert np.sum(np.einsum("fi,fi->f", tri.mean(1), nrm)) / 3 == pytest.approx(2.0, rel=1e-12)
        assert np.linalg.norm(nrm, axis=1).sum() == pytest.approx(2 * (2 + 2 + 1), rel=1e-12)
    on_box = np.any(np.isclose(m.rest, 0) | np.isclose(m.rest, m.rest.max(0)), axis=1)
    np.testing.assert_array_equal(m.boundary_vertices, np.flatnonzero(on_box))
    # the node numbering is the red refinement's (simfab.fem.subdivide): its sub-simplices live on
    # the same nodes and tile the element volume
    from simfab.fem.subdivide import subdivide

    X2, sub, edges = subdivide(lin.rest, lin.elements)
    np.testing.assert_array_equal(m.edges, edges)
    np.testing.assert_array_equal(m.rest, X2)
    np.testing.assert_array_equal(m.linear_elements(), sub)
    assert make_model(m.rest, m.linear_elements(), MAT, thickness=0.1).volume.sum() == pytest.approx(lin.volume.sum())
    # lifting corner positions puts midpoints between them
    xc = lin.rest * 1.1 + 0.3
    np.testing.assert_allclose(m.lift(xc), m.rest * 1.1 + 0.3, atol=1e-14)
    # the model pickles (for Dask workers) without its kernel workspace, and stays read-only
    import pickle

    x = m.lift(xc)
    E = nh.energy(m, x)
    m2 = pickle.loads(pickle.dumps(m))
    assert nh.energy(m2, x) == E and not m2.grad_N.flags.writeable


# ----------------------------------------------------------------------------------------------
# derivatives
# ----------------------------------------------------------------------------------------------
def _small_mesh(dim, rng, degree=None):
    """Two perturbed simplices sharing a facet, lifted to P2, random size."""
    if dim == 2:
        P = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
        T = np.array([[0, 1, 2], [0, 2, 3]])
    else:
        P = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], float)
        T = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    P = (P + 0.1 * rng.standard_normal(P.shape)) * rng.uniform(0.5, 2.0)
    return make_p2_model(P, T, MAT, thickness=0.3, degree=degree)


def _rotation(dim, rng):
    if dim == 3:
        return Rotation.random(random_state=rng).as_matrix()
    t = rng.uniform(0, 2 * np.pi)
    return np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])


def _deform(model, rng, kind):
    """A random smooth deformation (affine, rotated, plus a quadratic part that bends the
    elements' edges): general, strongly compressed or strongly expanded (dPsi/dJ > 0)."""
    d = model.dim
    scale = {"general": 1.0, "compressed": 0.6, "expanded": 1.6}[kind]
    while True:
        A = scale * (np.eye(d) + 0.2 * rng.standard_normal((d, d)))
        X = model.rest - model.rest.mean(0)
        h = model.mean_edge_length()
        quad = 0.15 / h * np.einsum("nk,nl,ikl->ni", X, X, rng.standard_normal((d, d, d)))
        x = (X @ A.T + scale * quad) @ _rotation(d, rng).T + rng.standard_normal(d)
        if np.all(nh.det_F(model, x) > 0.05):
            return x


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("kind", ["general", "compressed", "expanded"])
def test_gradient_and_hessian_match_finite_differences(dim, kind):
    rng = np.random.default_rng(10 * dim + len(kind))
    # the general state with the higher-degree rule (same kernels, other points and weights)
    model = _small_mesh(dim, rng, degree=max(d for (dd, d) in RULES if dd == dim) if kind == "general" else None)
    x = _deform(model, rng, kind)
    E, g, H = nh.energy_gradient_hessian(model, x, project_psd=False)
    assert E == pytest.approx(nh.energy(model, x), rel=1e-14)
    g_fd, H_fd = fd_grad_hess(model, x, eps=1e-6 * model.mean_edge_length())
    # central differences: truncation O(eps^2) ~ 1e-12, round-off ~ 1e-16 |E| / eps ~ 1e-10 relative
    np.testing.assert_allclose(g.ravel(), g_fd, atol=1e-7 * np.abs(g).max())
    Hd = H.toarray()
    np.testing.assert_allclose(Hd, H_fd, atol=1e-7 * np.abs(H_fd).max())
    np.testing.assert_allclose(Hd, Hd.T, atol=1e-12 * np.abs(Hd).max())
    # one launch for both Hessians gives the same matrices
    E2, g2, H_exact, H_psd = nh.energy_gradient_hessians(model, x)
    np.testing.assert_allclose(H_exact.toarray(), Hd, atol=1e-13 * np.abs(Hd).max())
    np.testing.assert_allclose(H_psd.toarray(), nh.energy_gradient_hessian(model, x)[2].toarray(),
                               atol=1e-13 * np.abs(Hd).max())
    # element blocks assemble to the same matrix
    blocks = nh.element_hessians(model, x, project_psd=False)
    np.testing.assert_allclose(model.pattern.assemble(blocks).toarray(), Hd, atol=1e-12 * np.abs(Hd).max())


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("kind", ["general", "compressed", "expanded"])
def test_projected_hessian_is_psd_and_matches_the_eigensystem_route(dim, kind):
    rng = np.random.default_rng(5 + 10 * dim + len(kind))
    model = _small_mesh(dim, rng)
    x = _deform(model, rng, kind)
    H_exact = nh.energy_gradient_hessian(model, x, project_psd=False)[2].toarray()
    H = nh.energy_gradient_hessian(model, x)[2].toarray()
    scale = np.abs(H_exact).max()
    ev = np.linalg.eigvalsh(H)
    assert ev.min() > -1e-12 * scale
    if kind == "compressed":  # the exact Hessian is indefinite here: projection did something
        assert np.linalg.eigvalsh(H_exact).min() < -1e-3 * scale
    # the direct route (twist-block projection) equals the full SVD eigensystem route
    blocks = nh.element_hessians(model, x)
    blocks_svd = nh.element_hessians(model, x, projection="svd")
    np.testing.assert_allclose(blocks, blocks_svd, atol=1e-10 * scale)
    # the projection clamps only negative curvature: H_exact - H is PSD
    assert np.linalg.eigvalsh(H_exact - H).max() < 1e-10 * scale


@pytest.mark.parametrize("dim", [2, 3])
def test_projected_stress_hessian_is_the_eigenvalue_clamp_of_the_exact_one(dim):
    # A = d2Psi/dF2 by central differences of P(F); clamp with numpy eigh; compare with the kernels'
    # analytic eigensystem (incl. the expanded dPsi/dJ > 0 regime)
    rng = np.random.default_rng(70 + dim)
    mu, lam = MAT.lame()

    def pk1(F):
        Fit = np.linalg.inv(F).T
        return mu * (F - Fit) + lam * np.log(np.linalg.det(F)) * Fit

    Fs = []
    for s in (0.6, 1.0, 1.7):
        for _ in range(3):
            F = s * (np.eye(dim) + 0.25 * rng.standard_normal((dim, dim))) @ _rotation(dim, rng)
            if np.linalg.det(F) > 0.1:
                Fs.append(F)
    Fs = np.array(Fs)
    got = projected_stress_hessian(Fs, mu, lam)
    eps = 1e-6
    for F, A_proj in zip(Fs, got):
        A = np.zeros((dim * dim, dim * dim))
        for c in range(dim * dim):
            dF = np.zeros(dim * dim)
            dF[c] = eps
            A[:, c] = (pk1(F + dF.reshape(dim, dim)) - pk1(F - dF.reshape(dim, dim))).ravel() / (2 * eps)
        w, V = np.linalg.eigh(0.5 * (A + A.T))
        ref = (V * np.maximum(w, 0)) @ V.T
        np.testing.assert_allclose(A_proj, ref, atol=1e-7 * np.abs(A).max())


@pytest.mark.parametrize("dim", [2, 3])
def test_quadrature_rules_agree_exactly_on_the_small_strain_stiffness(dim):
    # at rest d2Psi/dF2 is constant and grad N . grad N quadratic: every rule of degree >= 2 gives
    # the same stiffness matrix to round-off; away from rest they differ (the default degree-2 rule
    # is then an approximation; its size is measured in tools/benchmarks/p2.py)
    rng = np.random.default_rng(90 + dim)
    lin = _small_mesh(dim, rng).linear
    degrees = sorted(d for (dd, d) in RULES if dd == dim)
    models = [to_p2(lin, degree=d) for d in degrees]
    K = [nh.energy_gradient_hessian(m, m.rest)[2].toarray() for m in models]
    np.testing.assert_allclose(K[1], K[0], atol=1e-12 * np.abs(K[0]).max())
    x = _deform(models[0], rng, "general")
    K = [nh.energy_gradient_hessian(m, x, project_psd=False)[2].toarray() for m in models]
    assert np.abs(K[1] - K[0]).max() > 1e-4 * np.abs(K[0]).max()


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("degree", [2, None])
def test_element_stiffness_has_only_rigid_zero_modes(dim, degree):
    # one element at rest: exactly dim (dim + 1) / 2 zero eigenvalues (translations, rotations),
    # also with the minimal degree-2 rule (no spurious zero-energy modes)
    rng = np.random.default_rng(dim)
    P = np.vstack([np.zeros(dim), np.eye(dim)]) + 0.1 * rng.standard_normal((dim + 1, dim))
    m = make_p2_model(P, np.arange(dim + 1)[None], MAT, degree=degree or max(d for (dd, d) in RULES if dd == dim))
    ev = np.linalg.eigvalsh(nh.element_hessians(m, m.rest)[0])
    n_rigid = dim * (dim + 1) // 2
    assert np.all(np.abs(ev[:n_rigid]) < 1e-10 * ev[-1])
    assert ev[n_rigid] > 1e-4 * ev[-1]


@pytest.mark.parametrize("dim", [2, 3])
def test_rigid_motion_costs_nothing_and_inversion_at_a_quadrature_point_is_infinite(dim):
    rng = np.random.default_rng(3 * dim)
    model = _small_mesh(dim, rng)
    x = model.rest @ _rotation(dim, rng).T + rng.standard_normal(dim)
    E, g = nh.energy_gradient(model, x)
    assert abs(E) < 1e-12 * MAT.youngs_modulus * model.volume.sum()
    assert np.abs(g).max() < 1e-10 * MAT.youngs_modulus * model.volume.sum() / model.mean_edge_length()
    # push one edge midpoint far across the element: corners untouched (the linear element would
    # not notice), but F inverts near that edge
    x = model.rest.copy()
    e0 = model.elements[0]
    mid = e0[dim + 1]
    a, b = model.edges[mid - model.n_corners]
    centroid = model.rest[e0[: dim + 1]].mean(0)
    x[mid] += 3.0 * (centroid - x[mid])
    assert nh.det_F(model.linear, x[: model.n_corners]).min() > 0
    assert nh.det_F(model, x).min() <= 0
    assert nh.energy(model, x) == np.inf
    assert nh.energy_gradient(model, x)[0] == np.inf


# ----------------------------------------------------------------------------------------------
# patch tests and quadratic fields
# ----------------------------------------------------------------------------------------------
def _block(dim, n=3, seed=0):
    """A block with its interior corners moved randomly by 15% of the cell size (irregular
    elements: on a uniform grid P1 can be nodally exact for quadratic fields)."""
    if dim == 2:
        P, T = rectangle_mesh(1.0, 0.8, n + 1, n)
    else:
        P, T = box_tet(1.0, 0.8, 0.6, n, n, n - 1)
    P = P.copy()
    inner = np.flatnonzero(np.all((P > 1e-9) & (P < P.max(0) - 1e-9), axis=1))
    P[inner] += 0.15 * 0.8 / n * np.random.default_rng(seed).uniform(-1, 1, (len(inner), dim))
    return to_p2(make_model(P, T, MAT, thickness=0.2))


@pytest.mark.parametrize("dim", [2, 3])
def test_patch_test_affine_field_is_an_exact_equilibrium(dim):
    # x = A X + t gives the same F at every quadrature point, so the interior nodal forces cancel
    # (P2 shape-function gradients sum to zero); with the boundary prescribed from the map the
    # interior must reproduce it from a far start (to the Newton tolerance), at large strain.
    rng = np.random.default_rng(40 + dim)
    model = _block(dim)
    A = np.eye(dim) + 0.2 * rng.standard_normal((dim, dim))
    assert np.linalg.det(A) > 0.3
    t = rng.standard_normal(dim)
    exact = model.rest @ A.T + t
    Fq = np.einsum("mqad,mai->mqid", model.grad_N, exact[model.elements])
    np.testing.assert_allclose(Fq, np.broadcast_to(A, Fq.shape), atol=1e-12)
    g = nh.energy_gradient(model, exact)[1]
    interior = np.setdiff1d(np.arange(model.n_vertices), model.boundary_vertices)
    assert np.abs(g[interior]).max() < 1e-10 * np.abs(g).max()
    x0 = exact.copy()  # interior displaced by 1% of the edge length (F off by ~10%)
    x0[interior] += 0.01 * model.mean_edge_length() * rng.standard_normal((len(interior), dim))
    free = np.zeros(model.n_vertices, bool)
    free[interior] = True
    x, res = static_solve(model, x0, free, np.zeros_like(x0))
    assert res.iterations >= 2
    # relative Newton tolerance 1e-8 on the residual: displacement error ~1e-8 of the initial 1e-2 h
    np.testing.assert_allclose(x, exact, atol=1e-9)


def _pure_bending(X, kappa, nu, dim):
    """Exact small-strain displacement of pure bending about z (sigma_xx = E' kappa y only):
    2D plane strain u = (kappa x y, -kappa/2 (x^2 + nu' y^2)), nu' = nu / (1 - nu);
    3D u = (kappa x y, -kappa/2 (x^2 + nu (y^2 - z^2)), -kappa nu y z). Quadratic in X."""
    x, y = X[:, 0], X[:, 1]
    if dim == 2:
        nup = nu / (1 - nu)
        return np.c_[kappa * x * y, -0.5 * kappa * (x * x + nup * y * y)]
    z = X[:, 2]
    return np.c_[kappa * x * y, -0.5 * kappa * (x * x + nu * (y * y - z * z)), -kappa * nu * y * z]


@pytest.mark.parametrize("dim", [2, 3])
def test_quadratic_field_pure_bending_is_reproduced_by_p2_not_by_p1(dim):
    # Pure bending has a quadratic exact small-strain displacement. Its F is reproduced exactly at
    # every quadrature point by P2 interpolation, and with the boundary prescribed from it the P2
    # equilibrium differs from it only by the Neo-Hookean nonlinearity (relative error proportional
    # to the strain, 1e-3 here: measured ~1.5e-4), while P1 on the same irregular corners has an
    # O(h) error independent of the strain (measured 1.4-1.9e-2).
    model = _block(dim)
    Xc = model.rest.mean(0)
    kappa = 1e-3 / np.abs(model.rest - Xc).max()
    nu = MAT.poisson_ratio
    exact = model.rest + _pure_bending(model.rest - Xc, kappa, nu, dim)
    # interpolation: F at every quadrature point equals the exact gradient there
    Xq = np.einsum("ql,mld->mqd", model.qp_bary, model.rest[model.corner_elements]).reshape(-1, dim) - Xc
    Fq = np.einsum("mqad,mai->mqid", model.grad_N, exact[model.elements]).reshape(-1, dim, dim)
    eps = 1e-6
    for c in range(dim):  # the exact gradient by central differences (exact for a quadratic field)
        dX = np.zeros(dim)
        dX[c] = eps
        col = (_pure_bending(Xq + dX, kappa, nu, dim) - _pure_bending(Xq - dX, kappa, nu, dim)) / (2 * eps)
        np.testing.assert_allclose(Fq[..., c], np.eye(dim)[c] + col, atol=1e-12)

    def error(m, ex):
        inner = np.setdiff1d(np.arange(m.n_vertices), m.boundary_vertices)
        free = np.zeros(m.n_vertices, bool)
        free[inner] = True
        x, _ = static_solve(m, np.where(free[:, None], m.rest, ex), free, np.zeros_like(ex))
        return np.abs(x - ex)[inner].max() / np.abs(ex - m.rest).max()

    err_p2 = error(model, exact)
    err_p1 = error(model.linear, exact[: model.n_corners])
    assert err_p2 < 5e-4
    assert err_p1 > 5e-3
    # the P2 error is the nonlinearity: it halves with the strain
    half = model.rest + _pure_bending(model.rest - Xc, kappa / 2, nu, dim)
    assert error(model, half) == pytest.approx(err_p2 / 2, rel=0.2)


# ----------------------------------------------------------------------------------------------
# cantilever vs Timoshenko
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("dim", [2, 3])
def test_cantilever_p2_matches_timoshenko_where_linear_locks(dim):
    # delta = P L^3 / (3 E' I) + P L / (kappa G A) (simfab.verification.cantilever), L/h = 10, load for a
    # 1e-3 L deflection (nonlinearity ~1e-6). P2 error is O(h^2) in energy; measured (6-tet cubes /
    # 2 triangles per square): 3D -2.4% (1 cell through the height), -1.1% (2); 2D -1.7%, -0.7%;
    # mesh-converged -0.3..-0.5% (the clamp restrains the root's Poisson contraction, which beam
    # theory ignores). Linear elements with 2 cells lock: ~50% of the deflection.
    r1 = solve_cantilever(cantilever_model(dim, 1, order=2))
    r2 = solve_cantilever(cantilever_model(dim, 2, order=2))
    lin = solve_cantilever(cantilever_model(dim, 2, order=1))
    assert 0.965 < r1.ratio < 1.0
    assert 0.98 < r2.ratio < 1.0
    assert r1.ratio < r2.ratio  # converges from below (stiff), as a conforming displacement method must
    assert lin.ratio < 0.6
    assert r2.iterations <= 4


# ----------------------------------------------------------------------------------------------
# stress, and the benchmark's output
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("dim", [2, 3])
def test_det_and_von_mises_are_min_and_max_over_quadrature_points(dim):
    rng = np.random.default_rng(60 + dim)
    model = _block(dim)
    # affine: every quadrature point has the linear element's F -> identical figures
    A = np.eye(dim) + 0.1 * rng.standard_normal((dim, dim))
    x = model.rest @ A.T
    J2, vm2 = nh.det_and_von_mises(model, x)
    J1, vm1 = nh.det_and_von_mises(model.linear, x[: model.n_corners])
    np.testing.assert_allclose(J2, J1, rtol=1e-12)
    np.testing.assert_allclose(vm2, vm1, rtol=1e-10)
    # general smooth field: min det F and max von Mises over the points, against NumPy
    x = _deform(model, rng, "general")
    Fq = np.einsum("mqad,mai->mqid", model.grad_N, x[model.elements])
    J = np.linalg.det(Fq)
    C = Fq @ np.swapaxes(Fq, -1, -2) - np.eye(dim)
    tr = np.einsum("mqii->mq", C)
    vm = np.sqrt(1.5 * np.maximum(np.einsum("mqij,mqij->mq", C, C) - tr**2 / 3, 0)) * model.mu[:, None] / J
    J2, vm2 = nh.det_and_von_mises(model, x)
    np.testing.assert_allclose(J2, J.min(1), rtol=1e-12)
    np.testing.assert_allclose(vm2, vm.max(1), rtol=1e-10)
    assert np.any(vm.max(1) > 1.05 * vm.min(1))  # the points differ: max is not just any point
    np.testing.assert_allclose(nh.det_F(model, x), J.min(1), rtol=1e-12)


def test_benchmark_reports_p2_ahead_of_linear():
    # the benchmark's study at small levels (2D only): the JSON it prints has the figures the
    # README quotes, P2 within 2% at one cell through the height while linear is not
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))
    from benchmarks import p2 as bench

    out = bench.run(["--dims", "2", "--levels1-2d", "1,2", "--levels2-2d", "1,2,4", "--no-cost", "--no-knocker"])
    study = out["cantilever_2d"]
    rows = {(r["order"], r["cells_through"]): r for r in study["rows"]}
    assert abs(rows[(2, 1)]["error_vs_converged"]) < 0.02
    assert rows[(1, 2)]["error_vs_converged"] < -0.3
    assert study["summary"]["p2_seconds_to_2pct"] is not None
    assert study["summary"]["linear_seconds_to_2pct"] is None
    assert 0.99 < study["summary"]["converged_over_timoshenko"] < 1.0
    ld = study["large_deflection"]
    assert len(ld) == 4 and all(0.98 < r["delta_over_elastica"] < 1.02 for r in ld)


@pytest.mark.parametrize("dim", [2, 3])
def test_det_F_lower_bound_bounds_J_everywhere_and_catches_folds_between_quadrature_points(dim):
    from simfab.fem.p2 import det_F_lower_bound

    rng = np.random.default_rng(80 + dim)
    model = _small_mesh(dim, rng)
    # affine: J is constant, the bound equals it
    A = np.eye(dim) + 0.2 * rng.standard_normal((dim, dim))
    np.testing.assert_allclose(det_F_lower_bound(model, model.rest @ A.T), np.linalg.det(A), rtol=1e-12)
    L = rng.dirichlet(np.ones(dim + 1), size=4000)
    L = np.vstack([L, np.eye(dim + 1)])

    def J_sampled(x):  # det F at many points of each element: F(L) = sum_a x_a (x) grad N_a(L)
        _, dN = shape_functions(L, dim)
        gradL = np.concatenate([-model.Dm_inv.sum(1, keepdims=True), model.Dm_inv], axis=1)
        F = np.einsum("mai,qal,mld->mqid", x[model.elements], dN, gradL)
        return np.linalg.det(F)

    for _ in range(3):  # curved states: bound <= every sampled J, and not absurdly loose
        x = _deform(model, rng, "general")
        Js = J_sampled(x)
        bound = det_F_lower_bound(model, x)
        assert np.all(bound <= Js.min(1) + 1e-12)
        assert np.all(bound > 0.2 * Js.min(1))
    # a midpoint dragged towards a corner folds the element near that corner, while J stays
    # positive at the quadrature points (the kernels' check): the bound sees it, sampling confirms
    x = model.rest.copy()
    e0 = model.elements[0]
    c0, mid = e0[0], e0[dim + 1]  # corner 0 and the midpoint of edge (0, 1)
    x[mid] = x[c0] + 0.2 * (x[mid] - x[c0])
    assert nh.det_F(model, x)[0] > 0
    assert J_sampled(x)[0].min() < 0
    assert det_F_lower_bound(model, x)[0] < 0


@pytest.mark.parametrize("dim", [2, 3])
def test_consistent_loads_carry_the_resultant_and_moment(dim):
    from simfab.fem.loads import body_force_loads, traction_loads

    rng = np.random.default_rng(100 + dim)
    model = _block(dim)
    # one element, uniform load: P2 tet corners -V/20, edge nodes V/5; 6-node triangle 0 and V/3
    one = make_p2_model(model.linear.rest[model.corner_elements[0]], np.arange(dim + 1)[None], MAT, thickness=0.2)
    f = body_force_loads(one, lambda X: np.tile(np.eye(dim)[0], (len(X), 1)))[:, 0] / one.volume[0]
    np.testing.assert_allclose(f, [-1 / 20] * 4 + [1 / 5] * 6 if dim == 3 else [0] * 3 + [1 / 3] * 3, atol=1e-14)
    # a linear density b(X) = c + G X: resultant and first moment integrated exactly by both orders
    # (sum_a X_a N_a = X for P1 and P2, so sum_a X_a f_a = integral of X b, a quadratic)
    c, G = rng.standard_normal(dim), rng.standard_normal((dim, dim))
    density = lambda X: c + X @ G.T  # noqa: E731
    L, w = RULES[(dim, 2)]
    Xq = np.einsum("ql,mld->mqd", L, model.rest[model.corner_elements])
    exact_R = np.einsum("m,q,mqd->d", model.volume, w, density(Xq.reshape(-1, dim)).reshape(Xq.shape))
    exact_M = np.einsum("m,q,mqi,mqj->ij", model.volume, w, Xq, density(Xq.reshape(-1, dim)).reshape(Xq.shape))
    for m in (model, model.linear):
        f = body_force_loads(m, density)
        np.testing.assert_allclose(f.sum(0), exact_R, rtol=1e-12)
        np.testing.assert_allclose(np.einsum("ai,aj->ij", m.rest, f), exact_M, rtol=1e-11, atol=1e-14)
    # traction on the X = max face: resultant traction * face area, for both orders
    for m in (model, model.linear):
        face = np.all(np.isclose(m.rest[m.boundary_facets, 0], 1.0), axis=1)
        f = traction_loads(m, face, np.eye(dim)[1] * 3.0)
        area = 0.8 * (0.2 if dim == 2 else 0.6)
        assert f[:, 1].sum() == pytest.approx(3.0 * area, rel=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_elastic_runs_the_kernels_of_the_element_order(dim):
    # an affine deformation has the same constant F in the P2 and the linear model: equal energies,
    # det F and stresses through the two kernel sets, and the linear gradient at the corners equals
    # the P2 gradient lumped from the midpoints to their edges' ends (dx_mid = (dx_a + dx_b) / 2)
    rng = np.random.default_rng(7 + dim)
    model = _small_mesh(dim, rng)
    assert nh.kernels(model) is QUADRATIC and nh.kernels(model.linear) is LINEAR
    A = np.eye(dim) + 0.1 * rng.standard_normal((dim, dim))
    x, xl = model.rest @ A.T, model.linear.rest @ A.T
    assert nh.energy(model, x) == pytest.approx(nh.energy(model.linear, xl), rel=1e-12)
    for a, b in zip(nh.det_and_von_mises(model, x), nh.det_and_von_mises(model.linear, xl)):
        np.testing.assert_allclose(a, b, rtol=1e-12)
    g = nh.energy_gradient(model, x)[1]
    lumped = g[: model.n_corners].copy()
    for i, (a, b) in enumerate(model.edges):
        lumped[a] += 0.5 * g[model.n_corners + i]
        lumped[b] += 0.5 * g[model.n_corners + i]
    gl = nh.energy_gradient(model.linear, xl)[1]
    np.testing.assert_allclose(lumped, gl, atol=1e-12 * np.abs(gl).max())


def test_large_deflection_p2_cantilever_matches_the_elastica():
    # alpha = P L^2 / (E' I) = 1: tip deflection 0.3017 L for the inextensible Euler-Bernoulli
    # elastica (Bisshopp & Drucker 1945; tests/fem/test_fem_statics.py shoots it). Slenderness 10
    # adds shear compliance (~+0.5%) and the clamp stiffens (~-0.3%): measured +0.34% with 2 P2
    # cells through the height, where 2 linear cells lock (~-50%). Large rotations: exact-first
    # Newton steps (PSD projection as the fallback) converge in ~12 iterations.
    r = solve_cantilever(cantilever_model(2, 2, order=2), rel_deflection=1.0 / 3.0)
    assert r.delta == pytest.approx(0.3017207738, rel=0.01)
    assert r.iterations <= 20


def test_two_thread_launch_of_a_large_mesh_equals_the_assembled_element_blocks():
    """A tet mesh of >= QUADRATIC.split_elements[3] elements runs its Hessian in two halves on two
    threads, each half adding into its own CSR buffer: the summed buffers equal the assembly of the
    per-element blocks (to summation round-off), and the Hessian launch's energy and gradient equal
    those of the (whole) energy and gradient launches."""
    P, T = box_tet(0.04, 0.01, 0.015, 8, 2, 3)  # 48 cubes of 6 tets: 288 tets
    m = make_p2_model(P, T, MAT)
    assert m.n_elements >= QUADRATIC.split_elements[3]
    rng = np.random.default_rng(5)
    x = m.rest + 1e-4 * rng.standard_normal(m.rest.shape)
    E, g, He, Hp = nh.energy_gradient_hessians(m, x)
    for H, project in ((He, False), (Hp, True)):
        ref = m.pattern.assemble(nh.element_hessians(m, x, project_psd=project)).toarray()
        assert np.abs(H.toarray() - ref).max() <= 1e-13 * np.abs(ref).max()
    # two launches sum the element energies in different orders: round-off up to ~n_elements ulp
    assert E == pytest.approx(nh.energy(m, x), rel=m.n_elements * np.finfo(float).eps)
    np.testing.assert_array_equal(g, nh.energy_gradient(m, x)[1])
