"""The expertise/difficulty model (thesis Ch. "Wisdom of Micro-Crowds"), unit rating scale.

    alpha_i ~ N(1, 1)                     expertise of rater i (negative: malicious)
    beta_j  ~ N(1, 1) truncated (eps, inf)   difficulty of question j
    x_j     ~ N(0.5, 1/0.1) truncated [0, 1]  true score of question j
    delta_ij = sigmoid(-alpha_i / beta_j)      error variance, in (0, 1)
    y_ij    ~ N(x_j, delta_ij) truncated [0, 1]

Everything here is elementwise and broadcasts, so the sampler evaluates all raters,
questions, chains and crowds of a batch in one call. 1/sqrt(delta) = sqrt(1 + e^(alpha/beta))
is exact (the ratio capped where it no longer changes any value, so nothing overflows);
log delta = -softplus(alpha/beta) for reporting. The truncated-normal likelihood carries its
normalizing constant Phi((1-x)/s) - Phi(-x/s), s = sqrt(delta), computed as a stable
difference of log Phi values.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.special import log_ndtr, ndtr

from simfab.crowd.config import TOL, Priors

_HALF_LOG_2PI = 0.5 * np.log(2.0 * np.pi)


def log_normal_mass(a, b):
    """log(Phi(b) - Phi(a)) for a <= b, stable in both tails.

    Mirror so that the lower end is <= 0 (Phi(b) - Phi(a) = Phi(-a) - Phi(-b)); then
    log Phi(b) + log1p(-exp(log Phi(a) - log Phi(b))) loses nothing: the ratio
    Phi(a)/Phi(b) stays away from 1 unless the interval itself is tiny.
    """
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    flip = a > 0
    lo = np.where(flip, -b, a)
    hi = np.where(flip, -a, b)
    la = log_ndtr(lo)
    lb = log_ndtr(hi)
    return lb + np.log1p(-np.exp(la - lb))


def log_delta(alpha, beta):
    """log delta = log sigmoid(-alpha/beta) = -softplus(alpha/beta)."""
    return -np.logaddexp(0.0, alpha / beta)


def inv_sd(alpha, beta):
    """1/s = 1/sqrt(delta) = sqrt(1 + exp(alpha/beta)), the form the likelihood uses.

    The ratio is capped at TOL.ratio_cap (delta >= e^-200, s >= e^-100): below that the
    rounded likelihood's cell probabilities are 0 or 1 to double precision, so the cap
    changes no value and keeps every quantity finite.
    """
    return np.sqrt(1.0 + np.exp(np.minimum(alpha / beta, TOL.ratio_cap)))


def loglik(y, x, inv_s):
    """log N_[0,1](y | x, s^2) for y, x in [0, 1] (broadcasting): the thesis' density.

    = -log(2 pi)/2 - log s - (y-x)^2 / (2 s^2) - log(Phi((1-x)/s) - Phi(-x/s))
    """
    z = (y - x) * inv_s
    return -_HALF_LOG_2PI + np.log(inv_s) - 0.5 * z * z - log_unit_mass(x, inv_s)


def log_unit_mass(x, inv_s):
    """log(Phi((1-x)/s) - Phi(-x/s)), the truncation normalizer, for x in [0, 1].

    The interval [-x/s, (1-x)/s] contains 0, so the mass is 1 - Phi(-x/s) - Phi(-(1-x)/s)
    with both tail terms <= 1/2: log1p of their sum is exact to rounding (the general
    :func:`log_normal_mass` gives the same value at twice the cost).
    """
    return np.log1p(-ndtr(-x * inv_s) - ndtr((x - 1.0) * inv_s))


def loglik_rounded(lo_edge, hi_edge, x, inv_s):
    """log P(rating | x, s) when the latent opinion y ~ N_[0,1](x, s^2) is reported as the
    nearest scale point, i.e. y fell in the rating's cell [lo_edge, hi_edge] (unit scale):

        log(Phi((hi_edge-x)/s) - Phi((lo_edge-x)/s)) - log(Phi((1-x)/s) - Phi(-x/s))

    Bounded above by 0, unlike the density, which grows without bound as s -> 0 when
    several raters give the identical integer answer.
    """
    return log_normal_mass((lo_edge - x) * inv_s, (hi_edge - x) * inv_s) - log_unit_mass(x, inv_s)


def log_prior_alpha(alpha, p: Priors):
    """log N(alpha | mean, 1/precision) up to a constant."""
    return -0.5 * p.alpha_precision * (alpha - p.alpha_mean) ** 2


def log_prior_beta(beta, p: Priors):
    """Truncated normal up to its (constant) normalizer; -inf at or below beta_min."""
    return np.where(beta > p.beta_min, -0.5 * p.beta_precision * (beta - p.beta_mean) ** 2, -np.inf)


def log_prior_x(x, p: Priors):
    """Truncated normal on [0, 1] up to its (constant) normalizer; -inf outside."""
    inside = (x >= 0.0) & (x <= 1.0)
    return np.where(inside, -0.5 * p.x_precision * (x - p.x_mean) ** 2, -np.inf)


@dataclasses.dataclass(frozen=True)
class Observations:
    """Observed ratings of a batch, ready for broadcasting against (..., R, Q) parameters.

    weight: (..., R, Q) 1.0 where rated, 0.0 where missing. For ``half_width > 0`` the ratings
    are survey answers rounded to scale points (cells [y - h, y + h] clipped to [0, 1]) and
    :func:`loglik_rounded` applies; for ``half_width == 0`` they are continuous values and the
    thesis' density :func:`loglik` applies.
    """

    weight: np.ndarray
    y: np.ndarray
    lo: np.ndarray | None
    hi: np.ndarray | None

    @classmethod
    def make(cls, y, mask, half_width: float) -> "Observations":
        y = np.where(mask, y, 0.5)
        w = np.asarray(mask, float)
        if half_width > 0:
            return cls(w, y, np.clip(y - half_width, 0.0, 1.0), np.clip(y + half_width, 0.0, 1.0))
        return cls(w, y, None, None)

    def loglik(self, x, inv_s):
        """Masked per-rating log-likelihood terms, broadcast shape of x and inv_s (1/s)."""
        if self.lo is not None:
            return self.weight * loglik_rounded(self.lo, self.hi, x, inv_s)
        return self.weight * loglik(self.y, x, inv_s)


def log_posterior(obs: Observations, alpha, beta, x, p: Priors):
    """Unnormalized log posterior of one crowd (used by tests and the reference sampler).

    obs arrays: (R, Q); alpha: (..., R); beta, x: (..., Q). Returns (...,).
    """
    lp = log_prior_alpha(alpha, p).sum(-1) + log_prior_beta(beta, p).sum(-1) + log_prior_x(x, p).sum(-1)
    inv_s = inv_sd(alpha[..., :, None], np.maximum(beta, p.beta_min)[..., None, :])
    with np.errstate(invalid="ignore", divide="ignore"):
        ll = obs.loglik(np.clip(x, 0.0, 1.0)[..., None, :], inv_s).sum((-2, -1))
        return np.where(np.isfinite(lp), ll + lp, -np.inf)


def sample_ratings(x, alpha, beta, rng: np.random.Generator):
    """Draw y_ij ~ N(x_j, delta_ij) truncated to [0, 1] (unit scale). (R, Q)

    Inverse-CDF sampling on the truncated interval: u ~ U(Phi(a), Phi(b)),
    y = x + s Phi^-1(u); done in log space with scipy's truncnorm for tail safety.
    """
    from scipy.stats import truncnorm

    s = 1.0 / inv_sd(np.asarray(alpha, float)[:, None], np.asarray(beta, float)[None, :])
    xx = np.broadcast_to(np.asarray(x)[None, :], s.shape)
    return truncnorm.rvs(-xx / s, (1.0 - xx) / s, loc=xx, scale=s, random_state=rng)
