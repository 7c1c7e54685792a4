"""Micro-crowd study: how the Bayesian crowd estimate fares as the crowd shrinks.

From a crowd of N raters, for every size k = min_size .. N-1 take ``n_sub`` sub-crowds
(all C(N, k) of them when there are no more than ``n_sub``; otherwise random k-subsets,
drawn independently), aggregate each with the Bayesian model (all sub-crowds of one size
in one batched sampler run), and record per sub-crowd

- the percentile rank of its estimate among its own members (continuous errors), and
- its population bias: the RMS error of the aggregated estimate on the unit scale.

Reported per size: mean and standard deviation of both, and the share of fits whose
chains disagree (R-hat above the study sampler's target).
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from simfab.crowd import metrics
from simfab.crowd.analysis import half_width
from simfab.crowd.config import STUDY_SAMPLER, Priors, SamplerConfig
from simfab.crowd.data import Ratings
from simfab.crowd.sampler import sample
from simfab.errors import ConvergenceError, InputError
from simfab.sweep.tasks import run_tasks


@dataclasses.dataclass(frozen=True, kw_only=True)
class MicrocrowdStudy:
    """Per crowd size (K sizes): sizes (K,) int; n_subcrowds (K,) int; percentile_mean/sd (K,)
    in percent; bias_mean/sd (K,) unit-scale RMS; unconverged (K,) fraction of fits with
    R-hat above the study sampler's target; rhat_median (K,) median worst R-hat of the fits.

    The study's short runs (2 chains) leave a few percent Monte Carlo error in each fit's
    posterior mean, far below the spread over sub-crowds that the study measures.
    """

    sizes: np.ndarray
    n_subcrowds: np.ndarray
    percentile_mean: np.ndarray
    percentile_sd: np.ndarray
    bias_mean: np.ndarray
    bias_sd: np.ndarray
    unconverged: np.ndarray
    rhat_median: np.ndarray
    seconds: float

    def rows(self) -> list[dict]:
        return [
            {
                "size": int(k),
                "subcrowds": int(n),
                "percentile_mean": float(pm),
                "percentile_sd": float(ps),
                "bias_mean": float(bm),
                "bias_sd": float(bs),
                "unconverged_fraction": float(u),
                "rhat_median": float(rm),
            }
            for k, n, pm, ps, bm, bs, u, rm in zip(self.sizes, self.n_subcrowds, self.percentile_mean,
                                                   self.percentile_sd, self.bias_mean, self.bias_sd,
                                                   self.unconverged, self.rhat_median)
        ]


def subcrowds(n: int, k: int, n_sub: int, rng: np.random.Generator) -> np.ndarray:
    """(S, k) sorted member indices: all k-subsets of range(n) if there are <= n_sub,
    else ``n_sub`` independent uniformly random k-subsets."""
    import itertools

    if math.comb(n, k) <= n_sub:
        return np.array(list(itertools.combinations(range(n), k)), dtype=np.int64)
    return np.sort(np.argsort(rng.random((n_sub, n)), axis=1)[:, :k], axis=1)


def micro_crowd_study(
    ratings: Ratings,
    truth,
    *,
    n_sub: int = 500,
    min_size: int = 5,
    config: SamplerConfig = STUDY_SAMPLER,
    priors: Priors = Priors(),
    seed: int = 0,
    quiet: bool = True,
    device: str = "cpu",
    scheduler=None,
) -> MicrocrowdStudy:
    """Run the study on ``ratings`` with ``truth`` ((Q,) scale units). See module docstring.

    Each crowd size is one task of :func:`simfab.sweep.run_tasks` (``scheduler``: None for a
    local Dask cluster sized to this machine, "HOST:PORT" for an existing one, "serial" for
    this process). The sub-crowds and sampler seeds of all sizes are drawn here, in order,
    from one generator seeded with ``seed``, so the result does not depend on where or in
    which order the sizes run.
    """

    t0 = time.perf_counter()
    N = len(ratings.workers)
    if min_size < 2:
        raise InputError(f"minimum sub-crowd size must be >= 2, got {min_size}", where="--min-size")
    if N - 1 < min_size:
        raise InputError(f"a crowd of {N} raters has no sub-crowds of sizes {min_size}..{N - 1}; "
                         f"need at least {min_size + 1} raters", where=ratings.source)
    if n_sub < 2:
        raise InputError(f"need at least 2 sub-crowds per size, got {n_sub}", where="--subcrowds")
    rng = np.random.default_rng(seed)
    sc = ratings.scale
    truth = np.asarray(truth, float)
    common = {"unit": ratings.unit, "truth_unit": sc.to_unit(truth),
              "individual": metrics.individual_errors(ratings.labels, truth, sc),
              "config": config, "priors": priors, "half_width": half_width(ratings, config), "device": device}
    tasks = []
    for k in range(min_size, N):
        idx = subcrowds(N, k, n_sub, rng)
        tasks.append(dict(common, members=idx, seed=int(rng.integers(2**31 - 1))))
    results = run_tasks(study_size, tasks, scheduler=scheduler, quiet=quiet, desc="micro-crowd study")
    for k, r in zip(range(min_size, N), results):
        if r.status == "not_converged":
            raise ConvergenceError(f"micro-crowd study, size {k}: {r.message}")
        if r.status == "bad_input":
            raise InputError(f"micro-crowd study, size {k}: {r.message}")
        if not r.ok:
            raise RuntimeError(f"micro-crowd study, size {k}: {r.message}")
    cols = {key: np.array([r.value[key] for r in results]) for key in ("n", "pm", "ps", "bm", "bs", "u", "rm")}
    return MicrocrowdStudy(
        sizes=np.arange(min_size, N), n_subcrowds=cols["n"], percentile_mean=cols["pm"], percentile_sd=cols["ps"],
        bias_mean=cols["bm"], bias_sd=cols["bs"], unconverged=cols["u"], rhat_median=cols["rm"],
        seconds=time.perf_counter() - t0,
    )


def study_size(*, unit, truth_unit, individual, members, config: SamplerConfig, priors: Priors, seed: int, half_width,
               device: str = "cpu") -> dict:
    """One crowd size of the study (a Dask task): all S sub-crowds in one batched sampler run.

    unit (R, Q) ratings on the unit scale (NaN: missing); truth_unit (Q,); individual (R,)
    each rater's RMS error; members (S, k) sub-crowd member indices. Returns n (S), mean and
    sd over sub-crowds of the percentile rank pm/ps [%] and of the population bias bm/bs
    (unit-scale RMS), u the fraction of fits with R-hat above the target and rm their median
    worst R-hat.
    """

    post = sample(unit[members], config=config, priors=priors, seed=seed, half_width=half_width, keep_latent=False,
                  device=device)
    est = post.mean("x")  # (S, Q) unit scale
    bias = np.sqrt(np.mean((est - truth_unit[None]) ** 2, axis=1))
    pct = np.array([metrics.percentile_rank(b, individual[m]) for b, m in zip(bias, members)])
    return {"n": len(members), "pm": float(pct.mean()), "ps": float(pct.std(ddof=1)), "bm": float(bias.mean()),
            "bs": float(bias.std(ddof=1)),
            "u": float(np.mean(post.rhat_max > config.rhat_target)), "rm": float(np.median(post.rhat_max))}
