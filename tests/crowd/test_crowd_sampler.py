"""Convergence diagnostics and the blocked Metropolis-within-Gibbs sampler."""

import numpy as np
import pytest

from simfab.crowd import diagnostics, synth
from simfab.crowd.config import PRACTITIONERS, SamplerConfig
from simfab.crowd.data import Scale
from simfab.crowd.sampler import sample

SCALE = Scale(lo=1, hi=10)
HW = 0.5 / SCALE.span


def _ar1(phi, shape, rng):
    e = rng.standard_normal(shape)
    x = np.empty(shape)
    x[..., 0] = e[..., 0] / np.sqrt(1 - phi**2)
    for t in range(1, shape[-1]):
        x[..., t] = phi * x[..., t - 1] + e[..., t]
    return x


def test_rhat_near_one_for_mixed_chains_and_large_for_disagreeing_chains():
    rng = np.random.default_rng(1)
    good = rng.standard_normal((5, 4, 2000))
    assert np.all(diagnostics.rhat(good) < 1.01)
    bad = good + np.array([0, 0, 0, 1.0])[None, :, None]  # one chain sits elsewhere
    assert np.all(diagnostics.rhat(bad) > 1.05)
    scale_bad = good * np.array([1, 1, 1, 4.0])[None, :, None]  # same mean, wider chain: tail R-hat
    assert np.all(diagnostics.rhat(scale_bad) > 1.05)


def test_ess_of_ar1_matches_closed_form():
    # AR(1): integrated autocorrelation time (1 + phi) / (1 - phi)  ->  ESS = N (1 - phi) / (1 + phi)
    rng = np.random.default_rng(2)
    phi, C, N = 0.8, 4, 4000
    x = _ar1(phi, (20, C, N), rng)
    expected = C * N * (1 - phi) / (1 + phi)
    ess = diagnostics.ess(x)
    assert np.mean(ess) == pytest.approx(expected, rel=0.1)
    iid = diagnostics.ess(rng.standard_normal((20, C, N)))
    assert np.mean(iid) == pytest.approx(C * N, rel=0.1)


@pytest.mark.parametrize("backend", ["warp", "numpy"])
def test_sampler_reproduces_the_prior_without_data(backend):
    """No ratings: the posterior is the prior. Checks the proposal Jacobians (log beta,
    logit x), the truncations and the joint rescaling move. Prior moments:
    alpha ~ N(1, 1); beta ~ N(1, 1) truncated to (eps, inf): mean 1 + phi(1)/Phi(1) = 1.2876;
    x ~ N(0.5, 10) truncated to [0, 1]: mean 0.5, variance 0.08292 (nearly uniform's 1/12)."""
    from scipy.stats import norm, truncnorm

    n = 6000 if backend == "warp" else 3000
    cfg = SamplerConfig(chains=4, burn_in=500, draws=n, max_draws=n, ess_target=0)
    y = np.full((3, 2), np.nan)
    post = sample(y, config=cfg, seed=5, backend=backend)
    beta_mean = 1 + norm.pdf(1) / norm.cdf(1)
    sd10 = np.sqrt(10)
    x_var = truncnorm(-0.5 / sd10, 0.5 / sd10, loc=0.5, scale=sd10).var()
    beta_var = truncnorm(-1 + 1e-3, np.inf, loc=1).var()
    for name, mean, var in (("alpha", 1.0, 1.0), ("beta", beta_mean, beta_var), ("x", 0.5, x_var)):
        d = getattr(post, name)[0]  # (C, D, K)
        m = d.mean(axis=(0, 1))
        ess = diagnostics.ess(np.moveaxis(d, -1, 0))
        se = np.sqrt(var / ess)
        assert np.all(np.abs(m - mean) < 4.5 * se), (name, m, mean, se)
        assert d.var(axis=(0, 1)) == pytest.approx(np.full(d.shape[-1], var), rel=0.15)


def test_warp_and_numpy_backends_agree_on_a_crowd():
    c = synth.simulate_crowd(PRACTITIONERS, scale=SCALE, n_tasks=4, seed=11)
    cfg = SamplerConfig(burn_in=500, draws=3000, max_draws=3000, ess_target=0)
    a = sample(c.ratings.unit, config=cfg, seed=1, half_width=HW, backend="warp")
    b = sample(c.ratings.unit, config=cfg, seed=2, half_width=HW, backend="numpy")
    sd = a.x[0].std(axis=(0, 1))
    # posterior means agree within Monte Carlo error (ESS >= ~300 each: se <= sd/17)
    np.testing.assert_array_less(np.abs(a.mean("x")[0] - b.mean("x")[0]), 0.25 * sd + 1e-3)


def test_same_seed_same_draws():
    c = synth.simulate_crowd(PRACTITIONERS, scale=SCALE, n_tasks=4, seed=3)
    cfg = SamplerConfig(burn_in=50, draws=100, max_draws=100)
    a = sample(c.ratings.unit, config=cfg, seed=9, half_width=HW)
    b = sample(c.ratings.unit, config=cfg, seed=9, half_width=HW)
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.alpha, b.alpha)
