"""Error measures on the unit scale: RMS of a crowd estimate, individual errors, percentile rank.

Continuous measures compare real values with the real truth; discrete measures round both
the estimate (or the individual's rating, already a scale point) and the truth to the nearest
scale point first (halves up), as the thesis does for median and majority vote.
"""

from __future__ import annotations

import numpy as np

from simfab.crowd.config import TOL
from simfab.crowd.data import Scale


def rms(estimate, truth) -> float:
    """sqrt(mean_j (estimate_j - truth_j)^2) over the questions (any consistent units)."""
    d = np.asarray(estimate, float) - np.asarray(truth, float)
    return float(np.sqrt(np.mean(d * d)))


def rms_unit(estimate, truth, scale: Scale, *, discrete: bool = False) -> float:
    """RMS error on the unit scale; ``discrete`` rounds estimate and truth to scale points."""
    if discrete:
        estimate, truth = scale.round(estimate), scale.round(truth)
    return rms(scale.to_unit(estimate), scale.to_unit(truth))


def individual_errors(labels, truth, scale: Scale, *, discrete: bool = False) -> np.ndarray:
    """(R,) RMS error of each rater over the questions they rated, unit scale.

    labels (R, Q) scale units with NaN for missing; truth (Q,) scale units.
    """
    t = scale.round(truth) if discrete else np.asarray(truth, float)
    d = scale.to_unit(labels) - scale.to_unit(t)[None, :]
    return np.sqrt(np.nanmean(d * d, axis=1))


def percentile_rank(crowd_error: float, individual: np.ndarray) -> float:
    """Percent of individuals the crowd outperforms: 100 (n_worse + n_tied / 2) / n.

    ``n_worse`` counts individuals whose error exceeds the crowd's; equal errors (within
    TOL.tie) count half (the usual mid-rank convention).
    """
    e = np.asarray(individual, float)
    worse = np.sum(e > crowd_error + TOL.tie)
    tied = np.sum(np.abs(e - crowd_error) <= TOL.tie)
    return float(100.0 * (worse + 0.5 * tied) / e.size)


def score(estimate, labels, truth, scale: Scale, *, discrete_method: bool) -> dict:
    """Table row for one aggregate: continuous and discrete RMS and percentile ranks.

    ``rms`` is the error the thesis reports for this method: continuous methods against the
    real truth, discrete methods (median, majority) against the rounded truth.
    """
    rc = rms_unit(estimate, truth, scale)
    rd = rms_unit(estimate, truth, scale, discrete=True)
    pc = percentile_rank(rc, individual_errors(labels, truth, scale))
    pd_ = percentile_rank(rd, individual_errors(labels, truth, scale, discrete=True))
    return {
        "rms": rd if discrete_method else rc,
        "rms_continuous": rc,
        "rms_discrete": rd,
        "percentile": pd_ if discrete_method else pc,
        "percentile_continuous": pc,
        "percentile_discrete": pd_,
    }
