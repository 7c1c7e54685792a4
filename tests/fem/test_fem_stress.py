"""Cauchy and von Mises stress."""

import numpy as np
import pytest
from _fem_meshes import box_tet, rect_tri
from scipy.spatial.transform import Rotation

from simfab.fem.materials import Material
from simfab.fem.model import make_model
from simfab.fem.stress import cauchy_stress, deformation_gradient, det_and_von_mises, von_mises, von_mises_from_cauchy

MAT = Material(name="t", youngs_modulus=2.0e9, poisson_ratio=0.35, yield_stress=50e6, density=1000.0)


def test_von_mises_of_uniaxial_stress_equals_its_magnitude():
    for s in (-3.0e6, 1.0, 7.5e7):
        sigma = np.zeros((3, 3))
        sigma[0, 0] = s
        assert von_mises_from_cauchy(sigma) == pytest.approx(abs(s), rel=1e-14)
    # hydrostatic stress has no von Mises part; pure shear tau gives sqrt(3) tau
    assert von_mises_from_cauchy(np.eye(3) * 5e6) == pytest.approx(0.0, abs=1e-8)
    tau = np.zeros((3, 3))
    tau[0, 1] = tau[1, 0] = 2e6
    assert von_mises_from_cauchy(tau) == pytest.approx(np.sqrt(3) * 2e6, rel=1e-14)


@pytest.mark.parametrize("dim", [2, 3])
def test_zero_stress_at_rest_and_under_rigid_motion(dim):
    P, T = rect_tri(1.0, 0.5, 3, 2) if dim == 2 else box_tet(1.0, 0.5, 0.5, 2, 1, 1)
    m = make_model(P, T, MAT)
    R = Rotation.from_euler("xyz", [0.3, -1.1, 2.0]).as_matrix()
    R = R if dim == 3 else np.array([[np.cos(1.0), -np.sin(1.0)], [np.sin(1.0), np.cos(1.0)]])
    for x in (m.rest, m.rest @ R.T + 0.7):
        assert np.abs(cauchy_stress(m, x)).max() <= 1e-12 * MAT.youngs_modulus
        assert von_mises(m, x).max() <= 1e-12 * MAT.youngs_modulus


def test_small_strain_matches_linear_elasticity_and_plane_strain_szz():
    # sigma -> lam tr(eps) I + 2 mu eps for small strains (error O(|eps|^2) relative)
    rng = np.random.default_rng(5)
    mu, lam = MAT.lame()
    for dim in (2, 3):
        P, T = rect_tri(1.0, 1.0, 2, 2) if dim == 2 else box_tet(1.0, 1.0, 1.0, 1, 1, 1)
        m = make_model(P, T, MAT)
        G = 1e-5 * rng.standard_normal((dim, dim))
        eps = 0.5 * (G + G.T)
        sig = cauchy_stress(m, m.rest @ (np.eye(dim) + G).T)
        lin = np.zeros((3, 3))
        lin[:dim, :dim] = lam * np.trace(eps) * np.eye(dim) + 2 * mu * eps
        if dim == 2:
            lin[2, 2] = lam * np.trace(eps)  # plane strain: eps_zz = 0 but sigma_zz = lam tr(eps)
        np.testing.assert_allclose(sig, np.broadcast_to(lin, sig.shape), atol=1e-4 * np.abs(lin).max())
        np.testing.assert_allclose(sig, np.swapaxes(sig, 1, 2), atol=1e-9 * np.abs(lin).max())


def test_uniaxial_stretch_3d_stress_state():
    # homogeneous F = diag(a, b, b) with b chosen so that sigma_yy = 0 (free lateral faces):
    # then sigma is uniaxial and von Mises = |sigma_xx|
    from scipy.optimize import brentq

    P, T = box_tet(1.0, 1.0, 1.0, 1, 1, 1)
    m = make_model(P, T, MAT)
    a = 1.01
    syy = lambda b: cauchy_stress(m, m.rest * [a, b, b])[0, 1, 1]  # noqa: E731
    b = brentq(syy, 0.98, 1.0)
    sig = cauchy_stress(m, m.rest * [a, b, b])
    assert np.abs(sig[:, 1:, 1:]).max() < 1e-6 * abs(sig[0, 0, 0])
    np.testing.assert_allclose(von_mises(m, m.rest * [a, b, b]), np.abs(sig[:, 0, 0]), rtol=1e-6)
    # small-strain limit: sigma_xx ~ E (a - 1)
    assert sig[0, 0, 0] == pytest.approx(MAT.youngs_modulus * (a - 1), rel=0.02)


def test_inverted_element_has_no_stress():
    m = make_model(np.vstack([np.zeros(2), np.eye(2)]), [[0, 1, 2]], MAT)
    with pytest.raises(ValueError, match="inverted"):
        cauchy_stress(m, np.array([[0, 0], [1, 0], [0, -1.0]]))


@pytest.mark.parametrize("dim", [2, 3])
def test_closed_form_von_mises_matches_the_cauchy_tensor_route(dim):
    # sigma_vm = sqrt(3/2) mu |dev(F F^T)| / J must equal sqrt(3/2 s:s) of the full Cauchy tensor
    # (plane strain: sigma_zz included) on large, random, non-inverted deformations
    P, T = rect_tri(1.0, 0.5, 4, 3) if dim == 2 else box_tet(1.0, 0.5, 0.5, 3, 2, 2)
    m = make_model(P, T, MAT)
    rng = np.random.default_rng(7)
    x = m.rest @ (np.eye(dim) + 0.3 * rng.standard_normal((dim, dim))).T + 0.02 * rng.standard_normal(m.rest.shape)
    J, vm = det_and_von_mises(m, x)
    ok = J > 0
    assert ok.sum() > len(J) // 2
    F = deformation_gradient(m, x)
    np.testing.assert_allclose(J, np.linalg.det(F), rtol=1e-12)
    assert np.all(np.isinf(vm[~ok]))
    sub = make_model(P, T[ok], MAT)  # the non-inverted elements only
    ref = von_mises_from_cauchy(cauchy_stress(sub, x))
    np.testing.assert_allclose(vm[ok], ref, rtol=1e-10, atol=1e-9 * MAT.youngs_modulus)


def _det_and_von_mises_numpy(model, x):
    """det F and sqrt(3/2) mu |dev(F F^T - I)| / J per element in NumPy (+inf where det F <= 0)."""
    F = deformation_gradient(model, x)
    J = np.linalg.det(F)
    # dev B = dev (B - I); with C = B - I (small near rest) the sum C:C - tr(C)^2 / 3 cancels only
    # relative to |C|^2, so the stress at rest is zero to round-off (in plane strain C_zz = 0)
    C = F @ np.swapaxes(F, 1, 2) - np.eye(model.dim)
    tr = np.einsum("mii->m", C)
    dev = np.sqrt(1.5 * np.maximum(np.einsum("mij,mij->m", C, C) - tr * tr / 3.0, 0.0))
    vm = np.full(J.shape, np.inf)
    ok = J > 0
    vm[ok] = dev[ok] * model.mu[ok] / J[ok]
    return J, vm


@pytest.mark.parametrize("dim", [2, 3])
def test_stress_kernel_matches_the_numpy_formula(dim):
    # the Warp kernel behind det_and_von_mises and the same formula in NumPy, at rest (zero stress
    # to round-off) and on random deformations with inverted elements (+inf)
    P, T = rect_tri(1.0, 0.5, 4, 3) if dim == 2 else box_tet(1.0, 0.5, 0.5, 3, 2, 2)
    m = make_model(P, T, MAT)
    J0, vm0 = det_and_von_mises(m, m.rest)
    assert np.allclose(J0, 1.0, rtol=1e-12) and np.abs(vm0).max() <= 1e-6 * MAT.youngs_modulus
    rng = np.random.default_rng(3)
    x = m.rest @ (np.eye(dim) + 0.4 * rng.standard_normal((dim, dim))).T + 0.05 * rng.standard_normal(m.rest.shape)
    J, vm = det_and_von_mises(m, x)
    Jn, vmn = _det_and_von_mises_numpy(m, x)
    assert (J <= 0).any() and (J > 0).any()
    np.testing.assert_allclose(J, Jn, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(np.isinf(vm), np.isinf(vmn))
    ok = np.isfinite(vmn)
    np.testing.assert_allclose(vm[ok], vmn[ok], rtol=1e-10, atol=1e-9 * MAT.youngs_modulus)
