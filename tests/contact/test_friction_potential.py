"""The lagged friction potential (simfab.contact.friction): gradient and Hessian against finite
differences in stick and slip, 2D and 3D; the force magnitude mu lambda once slipping; a PSD Hessian."""

import numpy as np
import pytest

from simfab.contact.friction import friction_potential, tangent_bases


def _points(dim, a, rng, eps, scale):
    n = rng.normal(size=(a, dim))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    dy = rng.normal(size=(a, dim)) * scale * eps
    return dy, tangent_bases(n), rng.uniform(0.5, 2.0, a), np.full(a, eps)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("scale", [0.3, 5.0])  # stick (|u| < eps) and slip
def test_friction_gradient_and_hessian_match_finite_differences(dim, scale):
    rng = np.random.default_rng(dim * 10 + int(scale))
    eps = 1e-6
    dy, T, ml, e = _points(dim, 40, rng, eps, scale)
    ev = friction_potential(dy, T, ml, e)
    h = 1e-4 * eps  # central differences: error ~ h^2 |D'''| ~ 1e-8 relative
    for i in range(dim):
        step = np.zeros(dim)
        step[i] = h
        ep = friction_potential(dy + step, T, ml, e)
        em = friction_potential(dy - step, T, ml, e)
        np.testing.assert_allclose(ev.gradient[:, i], (ep.energy - em.energy) / (2 * h), rtol=1e-5,
                                   atol=1e-6 * np.abs(ev.gradient).max())
        np.testing.assert_allclose(ev.hessian[:, :, i], (ep.gradient - em.gradient) / (2 * h), rtol=1e-5,
                                   atol=1e-5 * np.abs(ev.hessian).max())


@pytest.mark.parametrize("dim", [2, 3])
def test_friction_force_is_mu_lambda_in_slip_and_hessian_is_psd(dim):
    rng = np.random.default_rng(7)
    eps = 1e-6
    for scale in (0.01, 0.5, 0.99, 3.0, 100.0):
        dy, T, ml, e = _points(dim, 60, rng, eps, scale)
        ev = friction_potential(dy, T, ml, e)
        force = np.linalg.norm(ev.gradient, axis=1)
        slip = ev.slip
        # f1(y) = 1 beyond eps (Coulomb: |f| = mu lambda), 2y/eps - y^2/eps^2 below (a C1 ramp to it)
        f1 = np.where(slip >= eps, 1.0, 2 * slip / eps - slip**2 / eps**2)
        np.testing.assert_allclose(force, ml * f1, rtol=1e-10, atol=1e-14)
        assert np.all(force <= ml * (1 + 1e-12))
        # the friction force opposes the tangential slip
        assert np.all(np.einsum("kd,kd->k", ev.gradient, dy) >= -1e-20)
        # PSD (in 2D slip the Hessian is exactly zero: the scale is the stick stiffness 2 mu lambda / eps)
        w = np.linalg.eigvalsh(0.5 * (ev.hessian + np.swapaxes(ev.hessian, 1, 2)))
        assert w.min() >= -1e-12 * 2 * ml.max() / eps


def test_normal_displacement_costs_nothing():
    # only the tangential part of the displacement slips: a purely normal move has zero potential change
    rng = np.random.default_rng(3)
    n = rng.normal(size=(20, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    T = tangent_bases(n)
    ev = friction_potential(n * 1e-3, T, np.ones(20), np.full(20, 1e-6))
    assert np.allclose(ev.gradient, 0.0, atol=1e-9) and np.allclose(ev.slip, 0.0, atol=1e-15)
    # the tangent bases are orthonormal and orthogonal to the normals
    assert np.allclose(np.einsum("kdi,kdj->kij", T, T), np.eye(2)) and np.allclose(np.einsum("kd,kdi->ki", n, T), 0)


@pytest.mark.parametrize("dim", [2, 3])
def test_point_sets_sharing_pooled_buffers_keep_their_own_data(dim):
    # two sets of the same size share the pooled device buffers (FrictionPoints loads its data when
    # another set used them last): evaluations interleaved must equal each set evaluated alone
    from simfab.contact.friction import FrictionPoints

    rng = np.random.default_rng(11 + dim)
    eps = 1e-6
    sets = [_points(dim, 5, rng, eps, scale) for scale in (0.3, 5.0)]
    alone = [friction_potential(dy, T, ml, e) for dy, T, ml, e in sets]
    fps = [FrictionPoints(T, ml, e) for _, T, ml, e in sets]
    for _ in range(2):
        for fp, (dy, _, _, _), ref in zip(fps, sets, alone):
            for hessian in (False, True):
                ev = fp.evaluate(dy, hessian=hessian)
                np.testing.assert_array_equal(ev.energy, ref.energy)
                np.testing.assert_array_equal(ev.gradient, ref.gradient)
                np.testing.assert_array_equal(ev.slip, ref.slip)
                if hessian:
                    np.testing.assert_array_equal(ev.hessian, ref.hessian)
