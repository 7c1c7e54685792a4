"""Model densities: stable log masses, rounded likelihood normalization, Warp == numpy."""

import numpy as np
import pytest
from scipy import integrate

from simfab.crowd import model as M
from simfab.crowd.config import Priors


def _log_mass_quad(a, b):
    """Independent reference: log of int_a^b phi(t) dt by quadrature of a rescaled integrand."""
    m = min(abs(a), abs(b)) if a * b > 0 else 0.0  # peak of exp(-t^2/2) on [a, b]
    val, _ = integrate.quad(lambda t: np.exp(-0.5 * t * t + 0.5 * m * m), a, b, epsabs=0, epsrel=1e-13, limit=200)
    return np.log(val) - 0.5 * m * m - 0.5 * np.log(2 * np.pi)


@pytest.mark.parametrize("a,b", [(-1.0, 2.0), (-40.0, -39.5), (-8.0, -7.9), (39.5, 40.0), (3.0, 3.001), (-0.2, 0.1),
                                 (-300.0, -299.0)])
def test_log_normal_mass_matches_quadrature_in_both_tails(a, b):
    assert M.log_normal_mass(a, b) == pytest.approx(_log_mass_quad(a, b), rel=1e-9, abs=1e-12)


def test_log_unit_mass_equals_general_mass():
    rng = np.random.default_rng(0)
    x = rng.uniform(0, 1, 200)
    inv_s = np.exp(rng.uniform(-0.5, 6, 200))
    np.testing.assert_allclose(M.log_unit_mass(x, inv_s), M.log_normal_mass(-x * inv_s, (1 - x) * inv_s),
                               rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("x,s", [(0.3, 0.05), (0.0, 0.7), (1.0, 0.2), (0.55, 1.0), (0.9, 1e-3)])
def test_rounded_likelihood_is_a_distribution_over_scale_points(x, s):
    # P(rating k) over the 10 points of a 1..10 scale sums to 1 (cells tile [0, 1])
    h = 0.5 / 9
    y = np.arange(10) / 9
    p = np.exp(M.loglik_rounded(np.clip(y - h, 0, 1), np.clip(y + h, 0, 1), x, 1.0 / s))
    assert p.sum() == pytest.approx(1.0, abs=1e-12)


def test_density_integrates_to_one_on_the_unit_interval():
    for x, s in [(0.2, 0.3), (0.9, 0.8)]:
        val, _ = integrate.quad(lambda y: np.exp(M.loglik(y, x, 1.0 / s)), 0, 1, epsrel=1e-12)
        assert val == pytest.approx(1.0, abs=1e-10)


def test_inv_sd_is_one_over_sqrt_delta():
    a, b = np.array([-3.0, 0.0, 2.0, 50.0]), np.array([0.5, 1.0, 1.5, 0.5])
    delta = 1.0 / (1.0 + np.exp(a / b))  # sigmoid(-a/b)
    np.testing.assert_allclose(M.inv_sd(a, b), delta**-0.5, rtol=1e-12)
    np.testing.assert_allclose(M.log_delta(a, b), np.log(delta), rtol=1e-12)


def test_warp_kernel_likelihood_equals_numpy():
    """Per-rating log-likelihood cached by the Warp kernel at start == numpy model, including
    the 8.3-sigma shortcuts and the log-space tail path (tiny and large s, x near the ends)."""
    from simfab.crowd._kernels import WarpKernel
    from simfab.crowd.config import SamplerConfig

    rng = np.random.default_rng(3)
    B, C, R, Q = 2, 3, 7, 5
    y = rng.integers(0, 10, (B, R, Q)) / 9.0
    mask = rng.random((B, R, Q)) > 0.1
    alpha = rng.normal(1, 3, (B, C, R))
    beta = np.exp(rng.normal(-1, 1.5, (B, C, Q)))
    x = rng.uniform(0, 1, (B, C, Q))
    x[..., 0] = 1e-6
    for hw in (0.5 / 9, 0.0):
        k = WarpKernel(y, mask, hw, Priors(), SamplerConfig(chains=C), rng, (alpha, beta, x))
        obs = M.Observations.make(y[:, None], mask[:, None], hw)
        ref = obs.loglik(x[..., None, :], M.inv_sd(alpha[..., :, None], beta[..., None, :]))
        got = k.ll.numpy().reshape(B, C, R, Q)
        np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-9)
