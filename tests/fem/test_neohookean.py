"""Neo-Hookean energy, gradient and Hessian against finite differences and invariances."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from simfab.fem import elastic as nh
from simfab.fem.materials import Material
from simfab.fem.model import make_model
from _fem_meshes import fd_grad_hess

MAT = Material(name="test", youngs_modulus=1.0e3, poisson_ratio=0.3, yield_stress=1e9, density=1.0)
# nu = 0.3 -> mu/lam = (1 - 2 nu) / (2 nu) = 2/3: dPsi/dJ > 0 (eigensolver branch of the
# scaling block) needs log J > 2/3, i.e. J > ~1.95; the "expanded" cases below reach it.


def _element(dim, rng):
    """A random simplex with a random size, rejected while it is a sliver (measure / h^d small)
    since finite differences of a sliver need a step far below its mean edge length."""
    while True:
        P = np.vstack([np.zeros(dim), np.eye(dim)]) + 0.15 * rng.standard_normal((dim + 1, dim))
        model = make_model(P * rng.uniform(0.5, 2.0), np.arange(dim + 1)[None], MAT)
        if model.volume[0] / model.mean_edge_length() ** dim > 0.5 / (6.0 if dim == 3 else 2.0):
            return model


def _deform(model, rng, kind):
    """Random deformation of a model: general, strongly compressed, or strongly expanded."""
    d = model.dim
    A = np.eye(d) + 0.25 * rng.standard_normal((d, d))
    if kind == "compressed":
        A = A * 0.6
    elif kind == "expanded":
        A = A * 1.6
    elif kind == "near_rest":  # clustered singular values: stresses the closed-form projectors
        A = np.eye(d) + 1e-7 * rng.standard_normal((d, d))
    R = _rotation(d, rng)
    x = model.rest @ (R @ A).T + rng.standard_normal(d)
    if np.any(nh.det_F(model, x) <= 0):
        return _deform(model, rng, kind)
    return x


def _rot2(t):
    return np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])


def _rotation(dim, rng):
    """A random rotation matrix (dim, dim)."""
    return Rotation.random(random_state=rng).as_matrix() if dim == 3 else _rot2(rng.uniform(0, 2 * np.pi))


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("kind", ["general", "compressed", "expanded"])
def test_gradient_and_hessian_match_finite_differences(dim, kind):
    rng = np.random.default_rng(100 * dim + len(kind))
    for _ in range(4):
        model = _element(dim, rng)
        x = _deform(model, rng, kind)
        E, g, H = nh.energy_gradient_hessian(model, x, project_psd=False)
        assert E == pytest.approx(nh.energy(model, x), rel=1e-14)
        g_fd, H_fd = fd_grad_hess(model, x, eps=1e-6 * model.mean_edge_length())
        # central differences: truncation O(eps^2) ~ 1e-12 and round-off ~ 1e-16 |E| / eps ~ 1e-10 relative
        np.testing.assert_allclose(g.ravel(), g_fd, atol=1e-7 * np.abs(g).max())
        np.testing.assert_allclose(H.toarray(), H_fd, atol=1e-7 * np.abs(H_fd).max())
        np.testing.assert_allclose(H.toarray(), H.toarray().T, atol=1e-12 * np.abs(H_fd).max())


@pytest.mark.parametrize("dim", [2, 3])
def test_projected_hessian_is_psd_and_exact_where_already_psd(dim):
    rng = np.random.default_rng(7 + dim)
    saw_indefinite = False
    for kind in ["general", "compressed", "expanded", "near_rest"] * 3:
        model = _element(dim, rng)
        x = _deform(model, rng, kind)
        H = nh.energy_gradient_hessian(model, x, project_psd=False)[2].toarray()
        Hp = nh.energy_gradient_hessian(model, x, project_psd=True)[2].toarray()
        w = np.linalg.eigvalsh(H)
        wp_ = np.linalg.eigvalsh(Hp)
        scale = np.abs(w).max()
        assert np.all(np.isfinite(Hp))
        assert wp_.min() >= -1e-12 * scale
        if w.min() < -1e-9 * scale:
            saw_indefinite = True
            assert np.abs(Hp - H).max() > 1e-9 * scale  # projection changed something
        np.testing.assert_allclose(Hp, Hp.T, atol=1e-12 * scale)
        _check_projection_reference(model, x, Hp)
    assert saw_indefinite  # the cases exercise the clamping


def _check_projection_reference(model, x, Hp):
    """Projected element Hessian = V B^T [d2Psi/dF2]_+ B, with d2Psi/dF2 by finite differences of P
    and the PSD part from numpy's eigh (the kernel uses the analytic eigensystem instead)."""
    d = model.dim
    Dmi = model.Dm_inv[0]
    p = x[model.elements[0]]
    F = (p[1:] - p[:1]).T @ Dmi
    mu, lam = model.mu[0], model.lam[0]

    def pk1(F):
        FinvT = np.linalg.inv(F).T
        return mu * (F - FinvT) + lam * np.log(np.linalg.det(F)) * FinvT

    eps = 1e-6
    HF = np.zeros((d * d, d * d))
    for k in range(d * d):
        dF = np.zeros(d * d)
        dF[k] = eps
        HF[:, k] = ((pk1(F + dF.reshape(d, d)) - pk1(F - dF.reshape(d, d))) / (2 * eps)).ravel()
    HF = 0.5 * (HF + HF.T)
    w, Q = np.linalg.eigh(HF)
    HFp = (Q * np.maximum(w, 0)) @ Q.T
    # B: dF_ab / dx_(l, c) ; F = Ds Dm^-1, Ds[:, i] = x_{i+1} - x_0
    B = np.zeros((d * d, (d + 1) * d))
    for l in range(d + 1):
        for c in range(d):
            dDs = np.zeros((d, d))
            if l == 0:
                dDs[c, :] = -1.0
            else:
                dDs[c, l - 1] = 1.0
            B[:, l * d + c] = (dDs @ Dmi).ravel()
    ref = model.volume[0] * B.T @ HFp @ B
    np.testing.assert_allclose(Hp, ref, atol=1e-6 * np.abs(ref).max())


@pytest.mark.parametrize("dim", [2, 3])
def test_energy_rotation_invariant_and_zero_at_rest_and_rigid_motion(dim):
    rng = np.random.default_rng(3 + dim)
    from _fem_meshes import box_tet, rect_tri

    P, T = rect_tri(1.0, 0.5, 4, 3) if dim == 2 else box_tet(1.0, 0.5, 0.4, 3, 2, 2)
    model = make_model(P, T, MAT)
    scale = MAT.youngs_modulus * model.volume.sum()  # energy scale [J] at unit strain
    E0, g0 = nh.energy_gradient(model, model.rest)
    assert abs(E0) <= 1e-13 * scale
    assert np.abs(g0).max() <= 1e-12 * scale
    x = _deform(model, rng, "general")
    E = nh.energy(model, x)
    assert E > 1e-3 * scale
    for _ in range(3):
        R = _rotation(dim, rng)
        t = rng.standard_normal(dim)
        assert nh.energy(model, x @ R.T + t) == pytest.approx(E, rel=1e-12)
        Er, gr = nh.energy_gradient(model, model.rest @ R.T + t)  # rigid motion of the rest shape
        assert abs(Er) <= 1e-12 * scale
        assert np.abs(gr).max() <= 1e-11 * scale
        # at a rigid pose the exact Hessian is PSD (rotations are its null space): projection is a no-op
        xr = model.rest @ R.T + t
        Hx = nh.energy_gradient_hessian(model, xr, project_psd=False)[2].toarray()
        Hp = nh.energy_gradient_hessian(model, xr)[2].toarray()
        assert np.all(np.isfinite(Hp))
        np.testing.assert_allclose(Hp, Hx, atol=1e-9 * np.abs(Hx).max())
        # gradient rotates with the body: g(Rx + t) = g(x) R^T
        np.testing.assert_allclose(nh.energy_gradient(model, x @ R.T + t)[1], nh.energy_gradient(model, x)[1] @ R.T,
                                   atol=1e-10 * scale)


def test_mesh_gradient_and_hessian_assembly_match_finite_differences():
    from _fem_meshes import box_tet

    rng = np.random.default_rng(11)
    P, T = box_tet(1.0, 1.0, 1.0, 2, 2, 1)
    model = make_model(P, T, MAT)
    x = model.rest + 0.05 * rng.standard_normal(model.rest.shape)
    E, g, H = nh.energy_gradient_hessian(model, x, project_psd=False)
    g_fd, H_fd = fd_grad_hess(model, x, eps=1e-6)
    np.testing.assert_allclose(g.ravel(), g_fd, atol=1e-7 * np.abs(g).max())
    np.testing.assert_allclose(H.toarray(), H_fd, atol=1e-7 * np.abs(H_fd).max())
    # the assembled projected Hessian equals the sum of the per-element projected blocks
    blocks = nh.element_hessians(model, x, project_psd=True)
    Hp = nh.energy_gradient_hessian(model, x)[2].toarray()
    ref = np.zeros_like(Hp)
    for e, el in enumerate(model.elements):
        dofs = (el[:, None] * 3 + np.arange(3)).ravel()
        ref[np.ix_(dofs, dofs)] += blocks[e]
    np.testing.assert_allclose(Hp, ref, atol=1e-12 * np.abs(ref).max())


@pytest.mark.parametrize("dim", [2, 3])
def test_inverted_element_gives_infinite_energy(dim):
    P = np.vstack([np.zeros(dim), np.eye(dim)])
    model = make_model(P, np.arange(dim + 1)[None], MAT)
    x = P.copy()
    x[1, 0] = -0.5  # vertex 1 crosses the opposite facet: det F < 0
    assert nh.det_F(model, x)[0] < 0
    assert nh.energy(model, x) == np.inf
    E, g = nh.energy_gradient(model, x)
    assert E == np.inf and np.all(np.isfinite(g))
    x[1, 0] = 0.0  # flat: det F = 0
    assert nh.energy(model, x) == np.inf


def test_bad_positions_raise_input_error():
    from simfab.errors import InputError

    model = make_model(np.vstack([np.zeros(2), np.eye(2)]), [[0, 1, 2]], MAT)
    with pytest.raises(InputError, match="shape"):
        nh.energy(model, np.zeros((4, 2)))
    with pytest.raises(InputError, match="NaN"):
        nh.energy(model, np.full((3, 2), np.nan))


@pytest.mark.parametrize("stretches", [(1, 1, 1e-3), (1, 1e-2, 1e-3), (50, 1, 1e-2), (1e-3, 1e-3, 1e-3),
                                       (3, 3, 3), (10, 0.1, 1),  # 3D
                                       (1, 1e-3), (50, 1e-2), (1e-3, 1e-3), (3, 3), (10, 0.1)])  # 2D
def test_projection_robust_for_extreme_deformations(stretches):
    # F = R1 diag(s) R2 with condition numbers up to 5e3 and J from 1e-9 to 27: both projection
    # routes (polar/closed-form and SVD) must stay finite, PSD and equal to the eigh reference
    dim = len(stretches)
    rng = np.random.default_rng(int(1e3 * sum(stretches)) % 2**32)
    P = np.vstack([np.zeros(dim), np.eye(dim)])
    model = make_model(P, np.arange(dim + 1)[None], MAT)
    F = _rotation(dim, rng) @ np.diag(stretches) @ _rotation(dim, rng)
    x = P @ F.T
    H = nh.energy_gradient_hessian(model, x)[2].toarray()
    assert np.all(np.isfinite(H))
    w = np.linalg.eigvalsh(H)
    assert w.min() >= -1e-12 * np.abs(w).max()
    _check_projection_reference(model, x, H)


@pytest.mark.parametrize("dim", [2, 3])
def test_direct_route_equals_svd_eigensystem_route(dim):
    # the fast route (exact Hessian + twist-block projection via the polar decomposition) and the
    # full SVD eigensystem clamp must give the same PSD Hessian on a deformed mesh
    from _fem_meshes import box_tet, rect_tri

    rng = np.random.default_rng(40 + dim)
    P, T = rect_tri(1.0, 0.5, 6, 3) if dim == 2 else box_tet(1.0, 0.5, 0.5, 3, 2, 2)
    model = make_model(P, T, MAT)
    for amp in (1e-6, 0.01):
        A = np.eye(dim) + 0.1 * rng.standard_normal((dim, dim))
        x = model.rest @ A.T + amp * rng.standard_normal(model.rest.shape)
        assert np.linalg.det(A) > 0.5 and np.all(nh.det_F(model, x) > 0)
        H = nh.energy_gradient_hessian(model, x)[2].toarray()
        H_svd = nh.energy_gradient_hessian(model, x, projection="svd")[2].toarray()
        np.testing.assert_allclose(H, H_svd, atol=1e-10 * np.abs(H).max())


@pytest.mark.parametrize("dim", [2, 3])
def test_exact_and_projected_hessians_from_one_launch(dim):
    from _fem_meshes import box_tet, rect_tri

    rng = np.random.default_rng(60 + dim)
    P, T = rect_tri(1.0, 0.5, 4, 2) if dim == 2 else box_tet(1.0, 0.5, 0.5, 2, 2, 1)
    model = make_model(P, T, MAT)
    for scale in (0.8, 1.0, 1.7):  # 1.7: expansion, dPsi/dJ > 0 in every element (SVD route)
        x = model.rest @ ((np.eye(dim) + 0.05 * rng.standard_normal((dim, dim))) * scale).T
        E, g, Hx, Hp = nh.energy_gradient_hessians(model, x)
        E1, g1, Hp1 = nh.energy_gradient_hessian(model, x)
        Hx1 = nh.energy_gradient_hessian(model, x, project_psd=False)[2]
        assert E == E1
        np.testing.assert_array_equal(g, g1)
        np.testing.assert_array_equal(Hx.toarray(), Hx1.toarray())
        np.testing.assert_array_equal(Hp.toarray(), Hp1.toarray())


def test_returned_hessians_are_independent_of_later_launches():
    # the kernel writes into persistent buffers that are copied out: a matrix a caller keeps (and
    # modifies, as the contact code does) must not change with later launches, whatever they compute
    rng = np.random.default_rng(11)
    P = np.vstack([np.zeros(3), np.eye(3), [1.0, 1.0, 1.0]])
    model = make_model(P, np.array([[0, 1, 2, 3], [1, 2, 3, 4]]), MAT)
    x1 = model.rest + 0.05 * rng.standard_normal(model.rest.shape)
    x2 = model.rest + 0.05 * rng.standard_normal(model.rest.shape)
    E1, g1, H1 = nh.energy_gradient_hessian(model, x1, project_psd=False)
    keep = (E1, g1.copy(), H1.toarray())
    H1.data[0] += 1.0  # a caller's in-place change stays in its own matrix
    nh.energy_gradient_hessians(model, x2)  # exact and projected, into both buffers
    nh.energy_gradient_hessian(model, x2)
    nh.energy(model, x2)
    H1.data[0] -= 1.0
    assert E1 == keep[0] and np.array_equal(g1, keep[1]) and np.array_equal(H1.toarray(), keep[2])
    # and a fresh launch at x1 reproduces it bit for bit (the buffers are zeroed before each launch)
    E1b, g1b, H1b = nh.energy_gradient_hessian(model, x1, project_psd=False)
    assert E1b == E1 and np.array_equal(g1b, g1) and np.array_equal(H1b.toarray(), keep[2])
