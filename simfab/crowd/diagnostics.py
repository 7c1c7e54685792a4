"""Convergence diagnostics of Vehtari, Gelman, Simpson, Carpenter & Buerkner (2021),
"Rank-normalization, folding, and localization: an improved R-hat", written compactly and
vectorized over any leading axes (arviz implements the same formulas but costs seconds to
import; these are a few array lines).

Input ``draws`` has shape (..., C, N): C chains of N draws for every parameter in ``...``.
Chains are split in halves (2C chains of N//2 draws) so that within-chain trends show.
"""

from __future__ import annotations

import numpy as np
from scipy.special import ndtri
from scipy.stats import rankdata


def _split(draws: np.ndarray) -> np.ndarray:
    n = draws.shape[-1] // 2
    return np.concatenate([draws[..., :n], draws[..., -n:]], axis=-2)


def _rank_normalize(draws: np.ndarray) -> np.ndarray:
    """z = Phi^-1((r - 3/8) / (S + 1/4)), r = average rank over all chains pooled."""
    shape = draws.shape
    flat = draws.reshape(shape[:-2] + (-1,))
    r = rankdata(flat, axis=-1)  # average ranks of ties (rejected Metropolis steps repeat values)
    return ndtri((r - 0.375) / (flat.shape[-1] + 0.25)).reshape(shape)


def _rhat_basic(chains: np.ndarray) -> np.ndarray:
    n = chains.shape[-1]
    w = chains.var(axis=-1, ddof=1).mean(axis=-1)
    b = n * chains.mean(axis=-1).var(axis=-1, ddof=1)
    var_plus = (n - 1) / n * w + b / n
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.sqrt(var_plus / w)
    # a parameter that never moved in any chain cannot be judged converged
    return np.where(np.isfinite(r), r, np.inf)


def rhat(draws: np.ndarray) -> np.ndarray:
    """Rank-normalized split R-hat: max of the bulk and the folded (tail) versions. (...,)"""
    return diagnose(draws)[0]


def diagnose(draws: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R-hat, bulk ESS), sharing the rank normalization of the split chains. (...,) each."""
    s = _split(np.asarray(draws, float))
    z = _rank_normalize(s)
    folded = np.abs(s - np.median(s, axis=(-2, -1), keepdims=True))
    r = np.maximum(_rhat_basic(z), _rhat_basic(_rank_normalize(folded)))
    return r, _ess_split(z)


def _autocorr_fft(chains: np.ndarray) -> np.ndarray:
    """Autocovariance of every chain for lags 0..N-1 (biased estimator, as in Stan). (..., C, N)"""
    n = chains.shape[-1]
    x = chains - chains.mean(axis=-1, keepdims=True)
    m = 1 << (2 * n - 1).bit_length()
    f = np.fft.rfft(x, n=m, axis=-1)
    return np.fft.irfft(f * np.conj(f), n=m, axis=-1)[..., :n] / n


def ess(draws: np.ndarray, *, rank_normalize: bool = True) -> np.ndarray:
    """Bulk effective sample size (rank-normalized split chains, Geyer's initial monotone
    sequence estimator). (...,) in units of draws over all chains."""
    s = _split(np.asarray(draws, float))
    return _ess_split(_rank_normalize(s) if rank_normalize else s)


def _ess_split(s: np.ndarray) -> np.ndarray:
    c, n = s.shape[-2:]
    acov = _autocorr_fft(s)
    w = s.var(axis=-1, ddof=1).mean(axis=-1)
    var_plus = w * (n - 1) / n + s.mean(axis=-1).var(axis=-1, ddof=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = 1.0 - (w[..., None] - acov.mean(axis=-2)) / var_plus[..., None]  # (..., N)
    rho[..., 0] = 1.0
    k = n // 2
    pairs = rho[..., 0 : 2 * k : 2] + rho[..., 1 : 2 * k : 2]  # Gamma_k = rho_2k + rho_2k+1
    keep = np.cumprod(pairs > 0, axis=-1).astype(bool)  # initial positive sequence
    mono = np.minimum.accumulate(np.where(keep, pairs, np.inf), axis=-1)  # initial monotone
    tau = -1.0 + 2.0 * np.sum(np.where(keep, mono, 0.0), axis=-1)
    tau = np.maximum(tau, 1.0 / np.log10(c * n))  # Stan's cap against antithetic blow-up
    out = c * n / tau
    return np.where(np.isfinite(out), out, 0.0)
