"""Configuration of the crowd module: model priors, sampler settings, tolerances.

All numbers that steer the method live here (one place per area), as keyword-only
frozen dataclasses that scene files (TOML) and the CLI override field by field.
"""

from __future__ import annotations

import dataclasses


@dataclasses.dataclass(frozen=True, kw_only=True)
class Priors:
    """Priors of the expertise/difficulty model (thesis values). Unit rating scale [0, 1].

    alpha_i ~ N(alpha_mean, 1/alpha_precision)                     rater expertise (unitless)
    beta_j  ~ N(beta_mean, 1/beta_precision) truncated to (beta_min, inf)   question difficulty
    x_j     ~ N(x_mean, 1/x_precision) truncated to [0, 1]            true score (unit scale)
    """

    alpha_mean: float = 1.0
    alpha_precision: float = 1.0
    beta_mean: float = 1.0
    beta_precision: float = 1.0
    beta_min: float = 1e-3  #: the epsilon lower bound of the difficulty
    x_mean: float = 0.5
    x_precision: float = 0.1


@dataclasses.dataclass(frozen=True, kw_only=True)
class SamplerConfig:
    """Blocked Metropolis-within-Gibbs settings.

    The sampler runs ``burn_in`` adaptive iterations (proposal scales tuned toward
    ``target_accept`` every ``adapt_every`` iterations, then frozen), then ``draws``
    iterations per chain; while the worst R-hat exceeds ``rhat_target`` or the smallest
    bulk ESS is below ``ess_target`` it extends the run by half (at least ``draws``), up to
    ``max_draws``. Whatever
    remains unconverged is reported as a warning (chains disagree), never hidden.
    """

    chains: int = 4
    burn_in: int = 1000
    draws: int = 500
    max_draws: int = 16000
    adapt_every: int = 25
    target_accept: float = 0.44  #: optimal one-dimensional random-walk acceptance rate
    rhat_target: float = 1.01
    ess_target: float = 400.0
    scale_move: bool = True  #: likelihood-free joint rescaling of (alpha, beta); alpha/beta is invariant
    init_step_alpha: float = 0.5
    init_step_log_beta: float = 0.3
    init_step_logit_x: float = 0.3
    init_step_log_scale: float = 0.1
    credible_mass: float = 0.90  #: central credible interval reported
    #: "rounded": probability of each integer answer's rounding cell (default); "density":
    #: the thesis' truncated-normal density at the answer (degenerate for tied integer
    #: answers: expect chains to disagree; meant for continuous ratings)
    likelihood: str = "rounded"


#: Sampler used per sub-crowd in the micro-crowd study (many small fits; fixed length).
#: 1000 draws keep the fits' median R-hat near 1.03 on the bundled practitioners (~1.08 with
#: ``--draws 400``, which moves the study's mean percentile ranks by less than 1 point).
STUDY_SAMPLER = SamplerConfig(chains=2, burn_in=400, draws=1000, max_draws=1000, ess_target=0.0, rhat_target=1.05)


@dataclasses.dataclass(frozen=True, kw_only=True)
class CrowdMix:
    """A synthetic crowd: expertise alpha ~ N(mean, sd) for honest raters; a fraction of
    malicious raters with alpha ~ N(malicious_mean, malicious_sd) (negative alpha: error
    variance near its maximum, answers close to random)."""

    size: int
    alpha_mean: float
    alpha_sd: float
    malicious_fraction: float = 0.0
    malicious_mean: float = -3.0
    malicious_sd: float = 0.5


#: 15 practitioners: base familiarity with the domain, uneven skill.
PRACTITIONERS = CrowdMix(size=15, alpha_mean=3.0, alpha_sd=1.0)
#: 100 members of the general public, 10 % of them malicious.
GENERAL_PUBLIC = CrowdMix(size=100, alpha_mean=0.5, alpha_sd=1.0, malicious_fraction=0.1)


@dataclasses.dataclass(frozen=True, kw_only=True)
class Tolerances:
    """Geometric and numeric tolerances of the crowd module."""

    #: a triangle faces down when its unit normal has n_z < -downward_nz (zero overhang angle)
    downward_nz: float = 1e-6
    #: a triangle lies on the build plate when its highest vertex is within this fraction of
    #: the bounding-box diagonal above z_min (it needs no support and is no overhang)
    plate_rel: float = 1e-9
    #: ray-cast grid: rays per unit length along the longer side of the footprint
    ray_grid: int = 600
    #: cap of alpha/beta in the likelihood: delta >= e^-200 (see model.inv_sd)
    ratio_cap: float = 200.0
    #: equal-error tolerance when ranking the crowd among individuals
    tie: float = 1e-12
    #: a bracket node lies on the wall (x = 0) or on the loaded end face (x = L) when within
    #: this fraction of L of it (mesh nodes there are exact up to rounding)
    span_rel: float = 1e-9


TOL = Tolerances()
