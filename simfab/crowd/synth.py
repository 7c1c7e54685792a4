"""Synthetic crowds drawn from the expertise/difficulty model.

A crowd is a :class:`~simfab.crowd.config.CrowdMix` (honest raters' expertise distribution
plus a fraction of malicious raters). Ratings are drawn on the unit scale from the model's
truncated normal and rounded to the nearest integer point of the survey scale, as a survey
respondent would answer.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from simfab.crowd import model as M
from simfab.crowd.config import CrowdMix
from simfab.crowd.data import Ratings, Scale, from_matrix
from simfab.errors import InputError


@dataclasses.dataclass(frozen=True, kw_only=True)
class SyntheticCrowd:
    """Ratings plus the planted parameters that generated them.

    truth: (Q,) scale units; x: (Q,) unit scale; alpha: (R,); beta: (Q,);
    malicious: (R,) bool.
    """

    ratings: Ratings
    truth: np.ndarray
    x: np.ndarray
    alpha: np.ndarray
    beta: np.ndarray
    malicious: np.ndarray


def draw_alpha(mix: CrowdMix, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Expertise of ``mix.size`` raters and which of them are malicious."""
    if mix.size < 1:
        raise InputError(f"crowd size must be >= 1, got {mix.size}")
    if not 0.0 <= mix.malicious_fraction <= 1.0:
        raise InputError(f"malicious fraction must be in [0, 1], got {mix.malicious_fraction}")
    n_bad = int(round(mix.malicious_fraction * mix.size))
    bad = np.zeros(mix.size, bool)
    bad[rng.permutation(mix.size)[:n_bad]] = True
    alpha = np.where(bad, rng.normal(mix.malicious_mean, mix.malicious_sd, mix.size),
                     rng.normal(mix.alpha_mean, mix.alpha_sd, mix.size))
    return alpha, bad


def simulate_crowd(
    mixes: list[CrowdMix] | CrowdMix,
    *,
    scale: Scale,
    truth=None,
    n_tasks: int | None = None,
    beta=None,
    seed: int = 0,
    worker_prefix: str = "w",
) -> SyntheticCrowd:
    """Draw a crowd's integer ratings of Q questions.

    truth: (Q,) scale units (default: uniform on the scale); beta: (Q,) difficulties
    (default: 1, an ordinary question); ``n_tasks`` sets Q when truth is not given.
    """
    rng = np.random.default_rng(seed)
    if truth is None:
        if not n_tasks or n_tasks < 1:
            raise InputError("give the truth or a positive number of tasks")
        truth = rng.uniform(scale.lo, scale.hi, n_tasks)
    truth = np.asarray(truth, float)
    if np.any((truth < scale.lo) | (truth > scale.hi)):
        raise InputError(f"truth values must lie on the scale [{scale.lo:g}, {scale.hi:g}]")
    Q = truth.size
    beta = np.ones(Q) if beta is None else np.broadcast_to(np.asarray(beta, float), (Q,)).copy()
    if np.any(beta <= 0):
        raise InputError("question difficulties beta must be positive")
    mixes = [mixes] if isinstance(mixes, CrowdMix) else list(mixes)
    parts = [draw_alpha(m, rng) for m in mixes]
    alpha = np.concatenate([a for a, _ in parts])
    bad = np.concatenate([b for _, b in parts])
    x = scale.to_unit(truth)
    y = M.sample_ratings(x, alpha, beta, rng)
    labels = scale.round(scale.from_unit(y))
    ratings = from_matrix(labels, scale, workers=[f"{worker_prefix}{i:03d}" for i in range(alpha.size)],
                          tasks=[f"q{j + 1}" for j in range(Q)])
    return SyntheticCrowd(ratings=ratings, truth=truth, x=x, alpha=alpha, beta=beta, malicious=bad)
