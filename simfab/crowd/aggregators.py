"""Classical aggregators of a crowd's ratings (per question, over the raters who rated it).

All take ``labels`` (R, Q) on the survey scale with NaN for missing ratings and return (Q,)
estimates on the same scale. Arithmetic mean, geometric mean and the Bayesian model give
real numbers; median and majority vote stay on (or halfway between) scale points.
"""

from __future__ import annotations

import numpy as np

from simfab.errors import InputError


def arithmetic_mean(labels: np.ndarray) -> np.ndarray:
    """(1/n) sum_i y_ij per question j."""
    return np.nanmean(labels, axis=0)


def geometric_mean(labels: np.ndarray) -> np.ndarray:
    """exp((1/n) sum_i ln y_ij) per question; needs positive ratings (scales starting at 1)."""
    fin = np.isfinite(labels)
    if np.any(labels[fin] <= 0):
        raise InputError("geometric mean needs positive ratings; the scale must start at 1 or above", where="--scale")
    return np.exp(np.nanmean(np.log(labels), axis=0))


def median(labels: np.ndarray) -> np.ndarray:
    """Median per question (midpoint of the two middle ratings for an even count)."""
    return np.nanmedian(labels, axis=0)


def majority(labels: np.ndarray) -> np.ndarray:
    """Mode per question.

    Tie rule: among the most frequent ratings, take the one closest to the question's
    median rating; if two are equally close, the lower one. (Deterministic, and the
    choice a consensus would make between two camps of equal size.)
    """
    out = np.empty(labels.shape[1])
    for j in range(labels.shape[1]):
        col = labels[np.isfinite(labels[:, j]), j]
        vals, counts = np.unique(col, return_counts=True)  # vals ascending
        top = vals[counts == counts.max()]
        med = np.median(col)
        out[j] = top[np.argmin(np.abs(top - med))]  # argmin returns the first (lowest) on ties
    return out


#: Classical aggregators by the names used in tables and JSON.
CLASSICAL = {
    "arithmetic_mean": arithmetic_mean,
    "geometric_mean": geometric_mean,
    "median": median,
    "majority": majority,
}

#: Aggregators whose output stays on the discrete scale: scored against rounded truth.
DISCRETE = frozenset({"median", "majority"})
