"""Warp kernel of the blocked Metropolis-within-Gibbs sampler (private; see sampler.py).

One thread runs one chain of one crowd through many sweeps inside a single launch, so the
per-launch cost (~25 us on CPU) is paid once per chunk of sweeps, not per block update.
Each sweep does exactly what :class:`simfab.crowd.sampler._NumpyKernel` does (alpha block,
log-beta block, logit-x block, joint rescaling move), with the same model as
:mod:`simfab.crowd.model`; tests compare the two. Everything is float64.

Arrays (T = crowds x chains threads, R raters, Q questions):
  lo, hi, w: (B, R, Q) rating cell edges on the unit scale (``lo`` is the rating itself when
      ``rounded == 0``) and weights (1 rated, 0 missing)
  alpha, step_a, cnt_a: (T, R); beta, x, step_b, step_x, cnt_b, cnt_x: (T, Q);
  step_s, cnt_s, n_adapt: (T,)
  ll, inv_s, ll_tmp, is_tmp: (T, R, Q) cached log-likelihood terms and 1/sqrt(delta)
  out_x: (T, S, Q), out_a: (T, S, R), out_b: (T, S, Q) recorded draws when ``record == 1``
"""

from __future__ import annotations

from simfab._warp import wp  # quiet Warp initialization
from simfab.crowd.config import TOL
from simfab.crowd.model import Observations

_F = wp.float64


@wp.func
def _log_ndtr(z: wp.float64) -> wp.float64:
    # log Phi(z); below z = -20 erfc underflows soon, use the asymptotic series
    # log Phi(z) = -z^2/2 - log(-z) - log(2 pi)/2 + log(1 - z^-2 + 3 z^-4 - 15 z^-6 + 105 z^-8)
    # (truncation error < 1e-10 relative there).
    if z > _F(-20.0):
        return wp.log(_F(0.5) * wp.erfc(-z * _F(0.7071067811865476)))
    z2 = z * z
    t = _F(1.0) / z2
    series = _F(1.0) - t + _F(3.0) * t * t - _F(15.0) * t * t * t + _F(105.0) * t * t * t * t
    return _F(-0.5) * z2 - wp.log(-z) - _F(0.9189385332046728) + wp.log(series)


@wp.func
def _ndtr(z: wp.float64) -> wp.float64:
    return _F(0.5) * wp.erfc(-z * _F(0.7071067811865476))


@wp.func
def _log_mass(a: wp.float64, b: wp.float64) -> wp.float64:
    # log(Phi(b) - Phi(a)), a <= b; mirrored so the lower end is <= 0 (see model.log_normal_mass)
    lo = a
    hi = b
    if a > _F(0.0):
        lo = -b
        hi = -a
    if hi > _F(-30.0):
        # Phi(lo) and Phi(hi) are far from underflow and relatively exact (erfc of a
        # positive argument); their difference loses at most the ratio Phi(hi)/mass,
        # which is small for cells of width >= 1/(scale span) in units of s <= 1.
        return wp.log(_ndtr(hi) - _ndtr(lo))
    la = _log_ndtr(lo)
    lb = _log_ndtr(hi)
    return lb + wp.log(_F(1.0) - wp.exp(la - lb))


@wp.func
def _inv_sd(a: wp.float64, b: wp.float64, cap: wp.float64) -> wp.float64:
    return wp.sqrt(_F(1.0) + wp.exp(wp.min(a / b, cap)))


@wp.func
def _loglik(lo: wp.float64, hi: wp.float64, x: wp.float64, inv_s: wp.float64, rounded: int) -> wp.float64:
    # Beyond 8.3 standard deviations Phi's tail (< 5e-17) vanishes against 1 in double
    # precision, so skipping the erfc calls there is exact, and frequent: accurate raters.
    unit = _F(0.0)
    if wp.min(x, _F(1.0) - x) * inv_s < _F(8.3):
        unit = wp.log(_F(1.0) - _ndtr(-x * inv_s) - _ndtr((x - _F(1.0)) * inv_s))
    if rounded == 1:
        a = (lo - x) * inv_s
        b = (hi - x) * inv_s
        if a < _F(-8.3) and b > _F(8.3):
            return -unit
        return _log_mass(a, b) - unit
    z = (lo - x) * inv_s
    return _F(-0.9189385332046728) + wp.log(inv_s) - _F(0.5) * z * z - unit


@wp.func
def _jump(u: float, z: float) -> wp.float64:
    # standard normal z times a random scale 1/3, 1 or 3 (u uniform: probabilities 1/4,
    # 1/2, 1/4): a symmetric mixture proposal (see sampler._jump). The random numbers are
    # drawn in the kernel: a wp.func gets a copy of the RNG state, whose advance would be lost.
    m = _F(1.0)
    if u < 0.25:
        m = _F(1.0 / 3.0)
    elif u >= 0.75:
        m = _F(3.0)
    return m * _F(z)


@wp.func
def _stage(
    lo: wp.array3d(dtype=wp.float64),
    hi: wp.array3d(dtype=wp.float64),
    w: wp.array3d(dtype=wp.float64),
    rounded: int,
    cap: wp.float64,
    c: int,
    t: int,
    i: int,
    j: int,
    a: wp.float64,
    b: wp.float64,
    xj: wp.float64,
    ll: wp.array3d(dtype=wp.float64),
    is_tmp: wp.array3d(dtype=wp.float64),
    ll_tmp: wp.array3d(dtype=wp.float64),
) -> wp.float64:
    # rating (i, j) of chain t under a proposed expertise a or difficulty b: stage its
    # 1/sqrt(delta) and log-likelihood term, return the term's change
    s_new = _inv_sd(a, b, cap)
    l_new = w[c, i, j] * _loglik(lo[c, i, j], hi[c, i, j], xj, s_new, rounded)
    is_tmp[t, i, j] = s_new
    ll_tmp[t, i, j] = l_new
    return l_new - ll[t, i, j]


@wp.func
def _keep(
    t: int,
    i: int,
    j: int,
    inv_s: wp.array3d(dtype=wp.float64),
    ll: wp.array3d(dtype=wp.float64),
    is_tmp: wp.array3d(dtype=wp.float64),
    ll_tmp: wp.array3d(dtype=wp.float64),
):
    # accepted: the staged terms of rating (i, j) become the cached ones
    inv_s[t, i, j] = is_tmp[t, i, j]
    ll[t, i, j] = ll_tmp[t, i, j]


@wp.kernel
def _mwg_sweeps(
    lo: wp.array3d(dtype=wp.float64),
    hi: wp.array3d(dtype=wp.float64),
    w: wp.array3d(dtype=wp.float64),
    rounded: int,
    chains: int,
    n_sweeps: int,
    record: int,
    adapt: int,
    adapt_every: int,
    target: wp.float64,
    scale_move: int,
    seed: int,
    prior: wp.array(dtype=wp.float64),  # a_mean, a_prec, b_mean, b_prec, b_min, x_mean, x_prec, ratio_cap
    alpha: wp.array2d(dtype=wp.float64),
    beta: wp.array2d(dtype=wp.float64),
    x: wp.array2d(dtype=wp.float64),
    step_a: wp.array2d(dtype=wp.float64),
    step_b: wp.array2d(dtype=wp.float64),
    step_x: wp.array2d(dtype=wp.float64),
    step_s: wp.array(dtype=wp.float64),
    cnt_a: wp.array2d(dtype=wp.float64),
    cnt_b: wp.array2d(dtype=wp.float64),
    cnt_x: wp.array2d(dtype=wp.float64),
    cnt_s: wp.array(dtype=wp.float64),
    n_adapt: wp.array(dtype=wp.float64),
    ll: wp.array3d(dtype=wp.float64),
    inv_s: wp.array3d(dtype=wp.float64),
    ll_tmp: wp.array3d(dtype=wp.float64),
    is_tmp: wp.array3d(dtype=wp.float64),
    out_x: wp.array3d(dtype=wp.float64),
    out_a: wp.array3d(dtype=wp.float64),
    out_b: wp.array3d(dtype=wp.float64),
    active: wp.array(dtype=wp.int32),
):
    t = wp.tid()
    c = t // chains
    if active[c] == 0:  # this crowd has converged: leave its chains where they are
        return
    R = alpha.shape[1]
    Q = beta.shape[1]
    rng = wp.rand_init(seed, t)
    a_mu = prior[0]
    a_pr = prior[1]
    b_mu = prior[2]
    b_pr = prior[3]
    b_min = prior[4]
    x_mu = prior[5]
    x_pr = prior[6]
    cap = prior[7]
    zero = _F(0.0)
    for sweep in range(n_sweeps):
        # ---- alpha block: row i depends on alpha_i only
        for i in range(R):
            a_old = alpha[t, i]
            a_new = a_old + step_a[t, i] * _jump(wp.randf(rng), wp.randn(rng))
            d = _F(0.5) * a_pr * ((a_old - a_mu) * (a_old - a_mu) - (a_new - a_mu) * (a_new - a_mu))
            for j in range(Q):
                d += _stage(lo, hi, w, rounded, cap, c, t, i, j, a_new, beta[t, j], x[t, j], ll, is_tmp, ll_tmp)
            if wp.log(_F(wp.randf(rng))) < d:
                alpha[t, i] = a_new
                cnt_a[t, i] = cnt_a[t, i] + _F(1.0)
                for j in range(Q):
                    _keep(t, i, j, inv_s, ll, is_tmp, ll_tmp)
        # ---- log-beta block: column j depends on beta_j only (Jacobian + du)
        for j in range(Q):
            b_old = beta[t, j]
            du = step_b[t, j] * _jump(wp.randf(rng), wp.randn(rng))
            b_new = b_old * wp.exp(du)
            if b_new > b_min:
                d = du + _F(0.5) * b_pr * ((b_old - b_mu) * (b_old - b_mu) - (b_new - b_mu) * (b_new - b_mu))
                for i in range(R):
                    d += _stage(lo, hi, w, rounded, cap, c, t, i, j, alpha[t, i], b_new, x[t, j], ll, is_tmp, ll_tmp)
                if wp.log(_F(wp.randf(rng))) < d:
                    beta[t, j] = b_new
                    cnt_b[t, j] = cnt_b[t, j] + _F(1.0)
                    for i in range(R):
                        _keep(t, i, j, inv_s, ll, is_tmp, ll_tmp)
        # ---- logit-x block: column j depends on x_j only (Jacobian x (1 - x))
        for j in range(Q):
            x_old = x[t, j]
            u = wp.log(x_old) - wp.log(_F(1.0) - x_old) + step_x[t, j] * _jump(wp.randf(rng), wp.randn(rng))
            x_new = _F(1.0) / (_F(1.0) + wp.exp(-u))
            if x_new > zero and x_new < _F(1.0):
                d = wp.log(x_new * (_F(1.0) - x_new)) - wp.log(x_old * (_F(1.0) - x_old))
                d += _F(0.5) * x_pr * ((x_old - x_mu) * (x_old - x_mu) - (x_new - x_mu) * (x_new - x_mu))
                for i in range(R):
                    l_new = w[c, i, j] * _loglik(lo[c, i, j], hi[c, i, j], x_new, inv_s[t, i, j], rounded)
                    ll_tmp[t, i, j] = l_new
                    d += l_new - ll[t, i, j]
                if wp.log(_F(wp.randf(rng))) < d:
                    x[t, j] = x_new
                    cnt_x[t, j] = cnt_x[t, j] + _F(1.0)
                    for i in range(R):
                        ll[t, i, j] = ll_tmp[t, i, j]
        # ---- joint rescaling (alpha, beta) -> c (alpha, beta): likelihood unchanged
        if scale_move == 1:
            lc = step_s[t] * _jump(wp.randf(rng), wp.randn(rng))
            cc = wp.exp(lc)
            d = _F(R + Q) * lc
            ok = int(1)
            for i in range(R):
                a_old = alpha[t, i]
                a_new = a_old * cc
                d += _F(0.5) * a_pr * ((a_old - a_mu) * (a_old - a_mu) - (a_new - a_mu) * (a_new - a_mu))
            for j in range(Q):
                b_old = beta[t, j]
                b_new = b_old * cc
                if b_new <= b_min:
                    ok = 0
                d += _F(0.5) * b_pr * ((b_old - b_mu) * (b_old - b_mu) - (b_new - b_mu) * (b_new - b_mu))
            if ok == 1 and wp.log(_F(wp.randf(rng))) < d:
                for i in range(R):
                    alpha[t, i] = alpha[t, i] * cc
                for j in range(Q):
                    beta[t, j] = beta[t, j] * cc
                cnt_s[t] = cnt_s[t] + _F(1.0)
        if record == 1:
            for j in range(Q):
                out_x[t, sweep, j] = x[t, j]
                out_b[t, sweep, j] = beta[t, j]
            for i in range(R):
                out_a[t, sweep, i] = alpha[t, i]
        # ---- Robbins-Monro adaptation of log step toward the target acceptance
        if adapt == 1 and (sweep + 1) % adapt_every == 0:
            n_adapt[t] = n_adapt[t] + _F(1.0)
            gain = _F(3.0) / wp.sqrt(n_adapt[t])
            inv_n = _F(1.0) / _F(adapt_every)
            for i in range(R):
                step_a[t, i] = step_a[t, i] * wp.exp(gain * (cnt_a[t, i] * inv_n - target))
                cnt_a[t, i] = zero
            for j in range(Q):
                step_b[t, j] = step_b[t, j] * wp.exp(gain * (cnt_b[t, j] * inv_n - target))
                step_x[t, j] = step_x[t, j] * wp.exp(gain * (cnt_x[t, j] * inv_n - target))
                cnt_b[t, j] = zero
                cnt_x[t, j] = zero
            step_s[t] = step_s[t] * wp.exp(gain * (cnt_s[t] * inv_n - target))
            cnt_s[t] = zero


@wp.kernel
def _init_cache(
    lo: wp.array3d(dtype=wp.float64),
    hi: wp.array3d(dtype=wp.float64),
    w: wp.array3d(dtype=wp.float64),
    rounded: int,
    chains: int,
    cap: wp.float64,
    alpha: wp.array2d(dtype=wp.float64),
    beta: wp.array2d(dtype=wp.float64),
    x: wp.array2d(dtype=wp.float64),
    ll: wp.array3d(dtype=wp.float64),
    inv_s: wp.array3d(dtype=wp.float64),
):
    t, i, j = wp.tid()
    c = t // chains
    s = _inv_sd(alpha[t, i], beta[t, j], cap)
    inv_s[t, i, j] = s
    ll[t, i, j] = w[c, i, j] * _loglik(lo[c, i, j], hi[c, i, j], x[t, j], s, rounded)


class WarpKernel:
    """Chains of a batch of crowds on a Warp device; same interface as the numpy kernel.

    y, mask: (B, R, Q) unit-scale ratings (any value, e.g. NaN, where missing) and presence; init: (alpha, beta, x) arrays of
    shape (B, C, R), (B, C, Q), (B, C, Q). Launch seeds come from ``rng`` (reproducible).
    """

    def __init__(self, y, mask, half_width, priors, cfg, rng, init, device="cpu"):
        import numpy as np


        self.np, self.cfg, self.rng, self.device = np, cfg, rng, device
        B, R, Q = y.shape
        C = cfg.chains
        self.B, self.C, self.R, self.Q, self.T = B, C, R, Q, B * C
        obs = Observations.make(y, mask, half_width)  # the numpy model's cells and weights
        self.rounded = 1 if obs.lo is not None else 0
        arr = lambda a: wp.array(np.ascontiguousarray(a, dtype=np.float64), dtype=wp.float64, device=device)  # noqa: E731
        # the density likelihood reads the rating itself from ``lo`` (see _loglik)
        lo, hi = (obs.y, obs.y) if obs.lo is None else (obs.lo, obs.hi)
        self.lo, self.hi, self.w = arr(lo), arr(hi), arr(obs.weight)
        self.cap = float(_ratio_cap())
        self.prior = arr([priors.alpha_mean, priors.alpha_precision, priors.beta_mean, priors.beta_precision, priors.beta_min, priors.x_mean, priors.x_precision, self.cap])
        T = self.T
        alpha, beta, x = (np.asarray(v, float).reshape(T, -1) for v in init)
        self.alpha, self.beta, self.x = arr(alpha), arr(beta), arr(x)
        self.step = {
            "alpha": arr(np.full((T, R), cfg.init_step_alpha)),
            "beta": arr(np.full((T, Q), cfg.init_step_log_beta)),
            "x": arr(np.full((T, Q), cfg.init_step_logit_x)),
            "scale": arr(np.full(T, cfg.init_step_log_scale)),
        }
        self.n_adapt = arr(np.zeros(T))
        self.ll, self.inv_s, self.ll_tmp, self.is_tmp = (arr(np.zeros((T, R, Q))) for _ in range(4))
        self.reset_counts()
        wp.launch(_init_cache, dim=(T, R, Q), inputs=[self.lo, self.hi, self.w, self.rounded, C, self.cap, self.alpha, self.beta, self.x, self.ll, self.inv_s], device=device)

    def reset_counts(self):
        np = self.np
        self.count = {k: wp.array(np.zeros(v.shape), dtype=wp.float64, device=self.device) for k, v in self.step.items()}
        self.sweeps = 0

    def accept_rates(self) -> dict:
        return {k: float(v.numpy().mean() / max(self.sweeps, 1)) for k, v in self.count.items()}

    def run(self, n: int, *, adapt: bool, record: tuple, quiet: bool = True, active=None) -> dict:
        """n sweeps in one launch; returns {name: (n, B, C, K)} for the recorded names.
        ``active`` (B,) bool: crowds to advance (default all); others are left untouched."""
        np = self.np
        act = np.ones(self.B, np.int32) if active is None else np.asarray(active, np.int32)
        T, R, Q = self.T, self.R, self.Q
        rec = bool(record)
        shape = lambda k: (T, n if rec else 0, k)  # noqa: E731
        out_x = wp.zeros(shape(Q), dtype=wp.float64, device=self.device)
        out_a = wp.zeros(shape(R), dtype=wp.float64, device=self.device)
        out_b = wp.zeros(shape(Q), dtype=wp.float64, device=self.device)
        seed = int(self.rng.integers(0, 2**31 - 1))
        c = self.count
        wp.launch(
            _mwg_sweeps,
            dim=T,
            inputs=[
                self.lo, self.hi, self.w, self.rounded, self.C, n, int(rec), int(adapt), self.cfg.adapt_every,
                float(self.cfg.target_accept), int(self.cfg.scale_move), seed, self.prior,
                self.alpha, self.beta, self.x,
                self.step["alpha"], self.step["beta"], self.step["x"], self.step["scale"],
                c["alpha"], c["beta"], c["x"], c["scale"], self.n_adapt,
                self.ll, self.inv_s, self.ll_tmp, self.is_tmp, out_x, out_a, out_b,
                wp.array(act, dtype=wp.int32, device=self.device),
            ],
            device=self.device,
        )
        self.sweeps += n
        if not rec:
            return {}
        got = {"x": out_x, "alpha": out_a, "beta": out_b}
        # (T, n, K) -> (n, B, C, K)
        return {k: np.moveaxis(got[k].numpy().reshape(self.B, self.C, n, -1), 2, 0) for k in record}


def _ratio_cap():

    return TOL.ratio_cap
