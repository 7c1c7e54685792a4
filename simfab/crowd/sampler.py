"""Vectorized blocked Metropolis-within-Gibbs for the expertise/difficulty model.

Given the rest, the expertises alpha_i are conditionally independent (rater i only touches row i
of the likelihood), as are the difficulties beta_j and the true scores x_j (column j). One sweep
is three block updates, each proposing every scalar at once with its own random-walk step and
accepting each independently from row or column sums of one (crowds, chains, raters, questions)
likelihood evaluation, plus a likelihood-free move that rescales all alpha and beta of a chain by
a common factor c (only priors and the Jacobian c^(R+Q) enter), crossing the alpha-beta ridge.

beta is sampled as log beta and x as logit x (with their Jacobians); increments are normal with a
random scale (1/3, 1 or 3 times the step, :func:`_jump`). Steps adapt during burn-in toward the
0.44 acceptance rate (Robbins-Monro on log step, gain 1/sqrt(k)) and are frozen after.

Several chains start from over-dispersed points; R-hat and ESS (:mod:`simfab.crowd.diagnostics`)
decide whether to extend the run. Two implementations of the identical sweep: a Warp kernel
(default; one thread per chain, :mod:`simfab.crowd._kernels`) and numpy broadcasting
(:class:`_NumpyKernel`, the reference the tests compare the kernel against).

The likelihood is the probability of each integer answer's rounding cell
(:func:`simfab.crowd.model.loglik_rounded`), not the thesis' density at the rounded value, which
makes the posterior unbounded when raters give the identical answer. Full notes: docs/methods.md,
"simfab.crowd.sampler".
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from simfab.crowd import model as M
from simfab.crowd._kernels import WarpKernel
from simfab.crowd.config import Priors, SamplerConfig
from simfab.crowd.diagnostics import diagnose
from simfab.progress import progress


@dataclasses.dataclass(frozen=True, kw_only=True)
class Posterior:
    """Posterior draws of a batch of B crowds.

    x: (B, C, D, Q) true scores, unit scale; alpha: (B, C, D, R) or None; beta: (B, C, D, Q)
    or None (dropped when ``keep_latent=False``). A crowd that converged in an earlier round
    stops there: its draws beyond ``n_draws[b]`` are NaN (summaries below skip them).
    rhat/ess: (B, P) per parameter, P = Q + R + Q (x, alpha, beta) or Q when latents are
    dropped. converged: (B,) R-hat and ESS targets met.
    """

    x: np.ndarray
    alpha: np.ndarray | None
    beta: np.ndarray | None
    rhat: np.ndarray
    ess: np.ndarray
    converged: np.ndarray
    n_draws: np.ndarray  #: (B,) recorded draws per chain of each crowd
    iterations: int  #: per chain, burn-in included, of the longest-running crowd
    seconds: float
    accept: dict  #: mean post-burn-in acceptance rate per block
    config: SamplerConfig

    def mean(self, name: str = "x") -> np.ndarray:
        """Posterior mean, (B, K)."""
        return np.nanmean(getattr(self, name), axis=(1, 2))

    def interval(self, name: str = "x", mass: float | None = None) -> np.ndarray:
        """Central credible interval, (B, K, 2)."""
        mass = self.config.credible_mass if mass is None else mass
        d = getattr(self, name)
        d = d.reshape(d.shape[0], -1, d.shape[-1])
        q = np.nanquantile(d, [(1 - mass) / 2, (1 + mass) / 2], axis=1)  # (2, B, K)
        return np.moveaxis(q, 0, -1)

    @property
    def rhat_max(self) -> np.ndarray:
        return self.rhat.max(axis=-1)

    @property
    def ess_min(self) -> np.ndarray:
        return self.ess.min(axis=-1)


def _jump(rng: np.random.Generator, shape) -> np.ndarray:
    """Random-walk increments: N(0, 1) times a scale drawn from {1/3, 1, 3} with
    probabilities 1/4, 1/2, 1/4. The mixture is still symmetric (the Metropolis ratio is
    unchanged); the long jumps cross the heavy right tails of difficulty posteriors that a
    single step tuned to 44 % acceptance crawls through, the short ones help narrow modes."""
    u = rng.random(shape)
    return np.where(u < 0.25, 1.0 / 3.0, np.where(u >= 0.75, 3.0, 1.0)) * rng.standard_normal(shape)


def _logit(x):
    with np.errstate(divide="ignore"):
        return np.log(x) - np.log1p(-x)


def _expit(u):
    from scipy.special import expit

    return expit(u)


@dataclasses.dataclass
class _State:
    alpha: np.ndarray  # (B, C, R)
    beta: np.ndarray  # (B, C, Q)
    x: np.ndarray  # (B, C, Q)
    inv_s: np.ndarray  # (B, C, R, Q) 1/sqrt(delta)
    ll: np.ndarray  # (B, C, R, Q) masked log-likelihood terms


def _initial_state(B, C, R, Q, p: Priors, rng: np.random.Generator):
    """Over-dispersed starting points: alpha from its prior, beta log-normal around 1,
    x uniform on [0.05, 0.95]. (B, C, R), (B, C, Q), (B, C, Q)."""
    alpha = rng.normal(p.alpha_mean, p.alpha_precision**-0.5, (B, C, R))
    beta = np.maximum(np.exp(rng.normal(0.0, 0.5, (B, C, Q))), 10 * p.beta_min)
    x = rng.uniform(0.05, 0.95, (B, C, Q))
    return alpha, beta, x


class _NumpyKernel:
    """The sweep in numpy: every block one broadcast (B, C, R, Q) evaluation.

    The reference implementation (and the fallback where Warp is unavailable); the Warp
    kernel in :mod:`simfab.crowd._kernels` does the same arithmetic per chain.
    """

    def __init__(self, obs: M.Observations, priors: Priors, cfg: SamplerConfig, rng: np.random.Generator, init):
        self.obs, self.p, self.cfg, self.rng = obs, priors, cfg, rng
        B, _, R, Q = obs.weight.shape
        C = cfg.chains
        self.R, self.Q = R, Q
        self.step = {
            "alpha": np.full((B, C, R), cfg.init_step_alpha),
            "beta": np.full((B, C, Q), cfg.init_step_log_beta),
            "x": np.full((B, C, Q), cfg.init_step_logit_x),
            "scale": np.full((B, C), cfg.init_step_log_scale),
        }
        self.reset_counts()
        self.adaptations = 0
        alpha, beta, x = init
        inv_s = M.inv_sd(alpha[..., :, None], beta[..., None, :])
        self.state = _State(alpha, beta, x, inv_s, self._ll(x, inv_s))

    def reset_counts(self):
        self.count = {k: np.zeros_like(v) for k, v in self.step.items()}
        self.sweeps = 0

    def accept_rates(self) -> dict:
        return {k: float(v.mean() / max(self.sweeps, 1)) for k, v in self.count.items()}

    def run(self, n: int, *, adapt: bool, record: tuple[str, ...], quiet: bool = True, active=None) -> dict:
        """n sweeps; adapt steps every cfg.adapt_every sweeps if ``adapt``; return the
        recorded draws {name: (n, B, C, K)}. ``active`` is accepted for interface parity:
        the numpy reference advances every crowd (the caller ignores finished ones)."""

        s = self.state
        buf = {k: np.empty((n,) + getattr(s, k).shape) for k in record}
        for t in progress(range(n), desc="sampling", quiet=quiet):
            self.sweep(s)
            for k, b in buf.items():
                b[t] = getattr(s, k)
            if adapt and (t + 1) % self.cfg.adapt_every == 0:
                self.adapt()
        return buf

    def _ll(self, x, inv_s):
        return self.obs.loglik(x[..., None, :], inv_s)

    def _accept(self, logr, name):
        ok = np.log(self.rng.random(logr.shape)) < logr
        self.count[name] += ok
        return ok

    def sweep(self, s: _State) -> None:
        """One sweep: alpha block, log-beta block, logit-x block, joint rescaling."""
        p, rng = self.p, self.rng
        # alpha block: rows are independent given beta, x
        a_new = s.alpha + self.step["alpha"] * _jump(rng, s.alpha.shape)
        is_new = M.inv_sd(a_new[..., :, None], s.beta[..., None, :])
        ll_new = self._ll(s.x, is_new)
        logr = (ll_new - s.ll).sum(-1) + M.log_prior_alpha(a_new, p) - M.log_prior_alpha(s.alpha, p)
        ok = self._accept(logr, "alpha")
        s.alpha = np.where(ok, a_new, s.alpha)
        s.inv_s = np.where(ok[..., None], is_new, s.inv_s)
        s.ll = np.where(ok[..., None], ll_new, s.ll)
        # beta block (random walk on log beta): columns are independent given alpha, x
        du = self.step["beta"] * _jump(rng, s.beta.shape)
        b_new = s.beta * np.exp(du)
        is_new = M.inv_sd(s.alpha[..., :, None], b_new[..., None, :])
        ll_new = self._ll(s.x, is_new)
        with np.errstate(invalid="ignore"):
            logr = (ll_new - s.ll).sum(-2) + M.log_prior_beta(b_new, p) - M.log_prior_beta(s.beta, p) + du
        ok = self._accept(logr, "beta")
        s.beta = np.where(ok, b_new, s.beta)
        s.inv_s = np.where(ok[..., None, :], is_new, s.inv_s)
        s.ll = np.where(ok[..., None, :], ll_new, s.ll)
        # x block (random walk on logit x, Jacobian x (1 - x)): columns independent given
        # alpha, beta (delta unchanged). The logit keeps proposals inside [0, 1] and
        # stretches the skewed posteriors of scores near the ends of the scale.
        u_new = _logit(s.x) + self.step["x"] * _jump(rng, s.x.shape)
        x_new = _expit(u_new)
        ll_new = self._ll(x_new, s.inv_s)
        with np.errstate(divide="ignore"):
            jac = np.log(x_new * (1.0 - x_new)) - np.log(s.x * (1.0 - s.x))
        logr = (ll_new - s.ll).sum(-2) + M.log_prior_x(x_new, p) - M.log_prior_x(s.x, p) + jac
        ok = self._accept(logr, "x")
        s.x = np.where(ok, x_new, s.x)
        s.ll = np.where(ok[..., None, :], ll_new, s.ll)
        # joint rescaling alpha -> c alpha, beta -> c beta: likelihood invariant
        if self.cfg.scale_move:
            lc = self.step["scale"] * _jump(rng, self.step["scale"].shape)
            c = np.exp(lc)[..., None]
            a_new, b_new = s.alpha * c, s.beta * c
            with np.errstate(invalid="ignore"):
                logr = (
                    (M.log_prior_alpha(a_new, p) - M.log_prior_alpha(s.alpha, p)).sum(-1)
                    + (M.log_prior_beta(b_new, p) - M.log_prior_beta(s.beta, p)).sum(-1)
                    + (self.R + self.Q) * lc
                )
            ok = self._accept(logr, "scale")
            s.alpha = np.where(ok[..., None], a_new, s.alpha)
            s.beta = np.where(ok[..., None], b_new, s.beta)
        self.sweeps += 1

    def adapt(self) -> None:
        """Robbins-Monro step on log(step) toward the target acceptance, then reset counts."""
        self.adaptations += 1
        gain = 3.0 / np.sqrt(self.adaptations)
        for k, st in self.step.items():
            rate = self.count[k] / max(self.sweeps, 1)
            st *= np.exp(gain * (rate - self.cfg.target_accept))
        self.reset_counts()


def sample(
    y: np.ndarray,
    mask: np.ndarray | None = None,
    *,
    priors: Priors = Priors(),
    config: SamplerConfig = SamplerConfig(),
    seed: int = 0,
    half_width: float = 0.0,
    keep_latent: bool = True,
    backend: str = "warp",
    device: str = "cpu",
    quiet: bool = True,
) -> Posterior:
    """Sample the posterior of (x, alpha, beta) for one crowd or a batch of crowds.

    y: (R, Q) or (B, R, Q) ratings on the unit scale [0, 1]; NaN or ``mask == False`` marks
    a missing rating. All crowds of a batch share R and Q (pad with missing ratings).
    half_width: for integer survey answers, half the distance between scale points on the
    unit scale (0.5 / (hi - lo)); the likelihood then is the probability of the answer's
    rounding cell (:func:`~simfab.crowd.model.loglik_rounded`). 0 uses the density.
    Runs ``config.chains`` chains per crowd; see :class:`SamplerConfig` for the schedule.
    backend: "warp" (compiled kernel, one thread per chain, on Warp ``device``) or "numpy"
    (same algorithm, broadcast arrays; the reference the tests compare against).
    """
    t0 = time.perf_counter()
    y = np.asarray(y, float)
    if y.ndim == 2:
        y = y[None]
        mask = None if mask is None else np.asarray(mask)[None]
    m = np.isfinite(y) if mask is None else (np.asarray(mask, bool) & np.isfinite(y))
    B, R, Q = y.shape
    rng = np.random.default_rng(seed)
    init = _initial_state(B, config.chains, R, Q, priors, rng)
    if backend == "warp":

        kern = WarpKernel(y, m, half_width, priors, config, rng, init, device=device)
    elif backend == "numpy":
        obs = M.Observations.make(y[:, None], m[:, None], half_width)  # missing ratings -> weight 0
        kern = _NumpyKernel(obs, priors, config, rng, init)
    else:
        raise ValueError(f"unknown backend {backend!r}")

    kern.run(config.burn_in, adapt=True, record=(), quiet=quiet)
    kern.reset_counts()

    record = ("x", "alpha", "beta") if keep_latent else ("x",)
    chunks = {k: [] for k in record}
    done = np.zeros(B, bool)  # converged in an earlier round: no more sweeps
    n_draws = np.zeros(B, np.int64)
    n_params = {"x": Q, "alpha": R, "beta": Q}
    P = sum(n_params[k] for k in record)  # diagnosed parameters per crowd, in record order
    rh, es = np.full((B, P), np.inf), np.zeros((B, P))
    total, target = 0, config.draws
    while True:
        n = target - total
        got = kern.run(n, adapt=False, record=record, quiet=quiet, active=~done)
        for k in record:
            g = got[k]
            g[:, done] = np.nan
            chunks[k].append(g)
        n_draws[~done] += n
        total = target
        draws = {k: np.concatenate(v, axis=0) for k, v in chunks.items()}
        live = np.flatnonzero(~done)  # these share the full length `total`
        params = np.concatenate([np.moveaxis(d[:, live], 0, -1) for d in draws.values()], axis=-2)  # (b, C, P, D)
        r_live, e_live = diagnose(np.swapaxes(params, 1, 2))  # (b, P)
        rh[live], es[live] = r_live, e_live
        done = (rh.max(-1) < config.rhat_target) & (es.min(-1) >= config.ess_target)
        if done.all() or target >= config.max_draws:
            break
        target = min(target + max(config.draws, target // 2), config.max_draws)  # 1.5x: few re-diagnoses

    def per_batch(k):  # (D, B, C, K) -> (B, C, D, K)
        return np.ascontiguousarray(np.moveaxis(draws[k], 0, 2)) if k in draws else None

    accept = kern.accept_rates()
    return Posterior(
        x=per_batch("x"),
        alpha=per_batch("alpha"),
        beta=per_batch("beta"),
        rhat=rh,
        ess=es,
        converged=done,
        n_draws=n_draws,
        iterations=config.burn_in + int(n_draws.max()),
        seconds=time.perf_counter() - t0,
        accept=accept,
        config=config,
    )
