"""One crowd, every aggregator: estimates, errors against truth, and Bayesian diagnostics."""

from __future__ import annotations

import dataclasses

import numpy as np

from simfab.crowd import aggregators as A
from simfab.crowd import metrics
from simfab.crowd.config import Priors, SamplerConfig
from simfab.crowd.data import Ratings
from simfab.crowd.sampler import sample
from simfab.errors import InputError

#: Method names in table order (the thesis' columns).
METHODS = ("arithmetic_mean", "geometric_mean", "median", "majority", "bayesian")


@dataclasses.dataclass(frozen=True, kw_only=True)
class BayesResult:
    """Posterior summary of one crowd, scale units for x, model units for alpha and beta.

    Args:
        estimate: (Q,) posterior mean true score [scale units].
        x_interval: (Q, 2) its central credible interval [scale units].
        alpha_mean, alpha_interval: (R,) rater expertise means and (R, 2) intervals [model units].
        beta_mean, beta_interval: (Q,) question difficulty means and (Q, 2) intervals [model units].
        rhat_max: the largest rank-normalized split R-hat over the parameters [-].
        ess_min: the smallest bulk effective sample size [draws].
        converged: R-hat and ESS within the sampler's thresholds.
        iterations: iterations per chain.
        seconds: the sampler's wall time [s].
        warnings: one line each.
    """

    estimate: np.ndarray
    x_interval: np.ndarray
    alpha_mean: np.ndarray
    alpha_interval: np.ndarray
    beta_mean: np.ndarray
    beta_interval: np.ndarray
    rhat_max: float
    ess_min: float
    converged: bool
    iterations: int
    seconds: float
    warnings: tuple[str, ...]


def half_width(ratings: Ratings, config: SamplerConfig = SamplerConfig()) -> float:
    """Half the spacing of scale points on the unit scale (answers are rounded to them);
    0 selects the density likelihood."""
    if config.likelihood not in ("rounded", "density"):
        raise InputError(f"unknown likelihood {config.likelihood!r} (rounded or density)", where="--likelihood")
    return 0.5 / ratings.scale.span if config.likelihood == "rounded" else 0.0


def bayesian(ratings: Ratings, *, config: SamplerConfig = SamplerConfig(), priors: Priors = Priors(), seed: int = 0,
             quiet: bool = True, device: str = "cpu") -> BayesResult:
    """Fit the expertise/difficulty model to one crowd (several chains, R-hat/ESS checked)."""

    post = sample(ratings.unit, priors=priors, config=config, seed=seed, half_width=half_width(ratings, config),
                  quiet=quiet, device=device)
    sc = ratings.scale
    rh, es = float(post.rhat_max[0]), float(post.ess_min[0])
    warnings = []
    if not post.converged[0]:
        warnings.append(
            f"Bayesian model: chains disagree after {post.iterations} iterations per chain "
            f"(R-hat max {rh:.3f}, target < {config.rhat_target}; "
            f"bulk ESS min {es:.0f}, target >= {config.ess_target:.0f}); "
            "treat its estimates as unreliable or rerun with more --draws"
        )
    return BayesResult(
        estimate=sc.from_unit(post.mean("x")[0]),
        x_interval=sc.from_unit(post.interval("x")[0]),
        alpha_mean=post.mean("alpha")[0],
        alpha_interval=post.interval("alpha")[0],
        beta_mean=post.mean("beta")[0],
        beta_interval=post.interval("beta")[0],
        rhat_max=rh,
        ess_min=es,
        converged=bool(post.converged[0]),
        iterations=post.iterations,
        seconds=post.seconds,
        warnings=tuple(warnings),
    )


def classical(ratings: Ratings) -> dict[str, np.ndarray]:
    """Classical aggregates, (Q,) scale units each; geometric mean omitted for scales with 0."""
    out = {}
    for name, fn in A.CLASSICAL.items():
        if name == "geometric_mean" and ratings.scale.lo <= 0:
            continue
        out[name] = fn(ratings.labels)
    return out


def aggregate_all(ratings: Ratings, truth=None, *, config: SamplerConfig = SamplerConfig(), priors: Priors = Priors(),
                  seed: int = 0, quiet: bool = True, device: str = "cpu") -> dict:
    """Every aggregate of one crowd, scored against ``truth`` ((Q,) scale units) when given.

    Returns ``{"methods": {name: {"estimates": {task: value}, "rms", "rms_discrete",
    "percentile", ...}}, "bayes": {...diagnostics, intervals...}, "warnings": [...],
    "individual_errors": {...}}``. RMS figures are on the unit scale [0, 1].
    """
    est = classical(ratings)
    bres = bayesian(ratings, config=config, priors=priors, seed=seed, quiet=quiet, device=device)
    est["bayesian"] = bres.estimate
    methods = {}
    for name in METHODS:
        if name not in est:
            continue
        row = {"estimates": dict(zip(ratings.tasks, est[name].tolist()))}
        if truth is not None:
            row.update(metrics.score(est[name], ratings.labels, truth, ratings.scale,
                                     discrete_method=name in A.DISCRETE))
        else:
            row.update({k: None for k in ("rms", "rms_continuous", "rms_discrete", "percentile",
                                          "percentile_continuous", "percentile_discrete")})
        methods[name] = row
    bayes = {
        "rhat_max": bres.rhat_max,
        "ess_min": bres.ess_min,
        "seconds": bres.seconds,
        "converged": bres.converged,
        "iterations_per_chain": bres.iterations,
        "chains": config.chains,
        "credible_mass": config.credible_mass,
        "x_interval": {t: bres.x_interval[j].tolist() for j, t in enumerate(ratings.tasks)},
        "beta": {t: {"mean": float(bres.beta_mean[j]), "interval": bres.beta_interval[j].tolist()}
                 for j, t in enumerate(ratings.tasks)},
        "alpha": {w: {"mean": float(bres.alpha_mean[i]), "interval": bres.alpha_interval[i].tolist()}
                  for i, w in enumerate(ratings.workers)},
    }
    out = {"methods": methods, "bayes": bayes, "warnings": list(bres.warnings)}
    if truth is not None:
        errors = metrics.individual_errors(ratings.labels, truth, ratings.scale)
        out["individual_errors"] = dict(zip(ratings.workers, errors.tolist()))
    return out
