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
from simfab.crowd.config import STUDY_SAMPLER, Priors, SamplerConfig
from simfab.crowd.data import Ratings
from simfab.errors import InputError


@dataclasses.dataclass(frozen=True, kw_only=True)
class StudyResult:
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
            for k, n, pm, ps, bm, bs, u, rm in zip(self.sizes, self.n_subcrowds, self.percentile_mean, self.percentile_sd, self.bias_mean, self.bias_sd, self.unconverged, self.rhat_median)
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
) -> StudyResult:
    """Run the study on ``ratings`` with ``truth`` ((Q,) scale units). See module docstring."""
    from simfab.crowd.analysis import half_width
    from simfab.crowd.sampler import sample
    from simfab.progress import log

    t0 = time.perf_counter()
    N = len(ratings.workers)
    if min_size < 2:
        raise InputError(f"minimum sub-crowd size must be >= 2, got {min_size}", where="--min-size")
    if N - 1 < min_size:
        raise InputError(f"a crowd of {N} raters has no sub-crowds of sizes {min_size}..{N - 1}; need at least {min_size + 1} raters", where=ratings.source)
    if n_sub < 2:
        raise InputError(f"need at least 2 sub-crowds per size, got {n_sub}", where="--subcrowds")
    rng = np.random.default_rng(seed)
    sc = ratings.scale
    truth = np.asarray(truth, float)
    indiv = metrics.individual_errors(ratings.labels, truth, sc)
    unit, truth_unit, hw = ratings.unit, sc.to_unit(truth), half_width(ratings, config)
    cols = {k: [] for k in ("k", "n", "pm", "ps", "bm", "bs", "u", "rm")}
    for k in range(min_size, N):
        idx = subcrowds(N, k, n_sub, rng)
        log(f"micro-crowd study: size {k}, {len(idx)} sub-crowds", quiet=quiet)
        post = sample(unit[idx], config=config, priors=priors, seed=int(rng.integers(2**31 - 1)), half_width=hw, keep_latent=False, device=device)
        est = post.mean("x")  # (S, Q) unit scale
        bias = np.sqrt(np.mean((est - truth_unit[None]) ** 2, axis=1))
        pct = np.array([metrics.percentile_rank(b, indiv[members]) for b, members in zip(bias, idx)])
        cols["k"].append(k)
        cols["n"].append(len(idx))
        cols["pm"].append(pct.mean())
        cols["ps"].append(pct.std(ddof=1))
        cols["bm"].append(bias.mean())
        cols["bs"].append(bias.std(ddof=1))
        cols["u"].append(float(np.mean(post.rhat_max > config.rhat_target)))
        cols["rm"].append(float(np.median(post.rhat_max)))
    a = {k: np.array(v) for k, v in cols.items()}
    return StudyResult(
        sizes=a["k"], n_subcrowds=a["n"], percentile_mean=a["pm"], percentile_sd=a["ps"],
        bias_mean=a["bm"], bias_sd=a["bs"], unconverged=a["u"], rhat_median=a["rm"], seconds=time.perf_counter() - t0,
    )
