"""Simulated annealing (Kirkpatrick et al. 1983) over a bounded design vector, seeded.

Per iteration k (thesis, Algorithm "Rest Shape Optimization"):

1. proposal  x_i = clip(x_cur + sigma_k * N(0, I) * mask, lower, upper)   (Gaussian around the current
   state; with ``blocks`` (one block per handle) the mask selects each block with probability
   1 / n_blocks, at least one: mostly one handle moves at a time, a local edit whose effect the
   acceptance test can judge, instead of every handle at once)
2. temperature  T_k = tau_k * |E_cur|,  tau_k = tau_0 (tau_end / tau_0)^(k / K)   (exponential cooling)
3. Metropolis: accept if E_i < E_cur, else with probability exp(-(E_i - E_cur) / T_k); the best
   state seen is kept and returned. The uniform number u of the test is drawn before E_i is
   evaluated, so the test is the threshold E_i < E_cur - T_k ln u; ``f`` receives that threshold
   and may stop computing as soon as a lower bound of E_i exceeds it (returning the bound: the
   proposal is rejected exactly as it would have been).
4. adaptive, decaying step: sigma_{k+1} = sigma_k * GROW after an accepted proposal, * SHRINK
   after a rejected one, within [SIGMA_MIN_REL sigma_0, sigma_0].

The temperature is relative to the current objective (scale-free Metropolis): the objective of a
rest-shape design spans orders of magnitude (penalties of violated constraints ~1e6, a feasible
design's modification energy ~1), and a fixed temperature would either freeze the start or let
a feasible design wander back into violation. With T_k = tau_k |E_cur| an uphill move by the
fraction tau_k of the current value is accepted with probability 1/e at every scale.

A candidate whose value is +inf (rejected: invalid shape, failed simulation) is never accepted
and counts as a rejection. Stops after K iterations or when ``stop(best_info, k)`` says so.

**Speculative evaluation** (``evaluator``). Most proposals are rejected, and a rejection leaves
the current state unchanged, so proposals k+1, k+2, ... can be drawn before k is decided, each
assuming every pending one before it is rejected (sigma shrunk accordingly). Each is first
screened cheaply (e.g. its modification energy alone exceeds its threshold: decided at once);
those that need the expensive evaluation run concurrently on the evaluator's ``slots``.
Decisions are still taken in order; at the first acceptance the later proposals are discarded
(running ones finish unused) and the random stream is rewound to where the accepted proposal's
draws ended. Every decision, hence the result, is exactly that of the serial loop with the same
seed; only the wall time changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

GROW = 1.10
SHRINK = 0.97
SIGMA_MIN_REL = 0.05


@dataclass(frozen=True, kw_only=True)
class AnnealOptions:
    """iterations K; tau_0, tau_end: relative temperatures at the first and last iteration;
    sigma0 (n,): initial proposal standard deviations; lower, upper (n,): bounds; blocks (n,) int:
    block id per variable (None: every variable moves in every proposal); seed."""

    iterations: int
    sigma0: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    blocks: np.ndarray | None = None
    tau0: float = 0.05
    tau_end: float = 1e-4
    seed: int = 0


@dataclass(kw_only=True)
class AnnealResult:
    """best x (n,), its value and info; history: one dict per iteration (k, value, accepted,
    current, best, temperature, sigma, info); iterations run; stopped_early; discarded: infos of
    speculative evaluations that were not needed (a proposal before them was accepted)."""

    x: np.ndarray
    value: float
    info: object
    history: list = field(default_factory=list)
    iterations: int = 0
    stopped_early: bool = False
    discarded: list = field(default_factory=list)


def anneal(f, x0: np.ndarray, options: AnnealOptions, *, stop=None, callback=None, evaluator=None) -> AnnealResult:
    """Minimize ``f`` by simulated annealing from ``x0``.

    f : callable (x, threshold) -> (value, info); value may be +inf for a rejected candidate, or
        any lower bound of the value larger than ``threshold`` (the acceptance threshold)
    stop : optional callable (best_info, best_value, k, k_best) -> bool, asked after every iteration
        (k_best: iteration at which the best value was found)
    callback : optional callable(record dict) after every iteration
    evaluator : optional speculative evaluator (see the module docstring) with ``slots`` (int),
        ``screen(x, threshold) -> (value, info) | None`` (None: needs the full evaluation) and
        ``submit(x, threshold)`` returning an object whose ``result()`` is ``f(x, threshold)``;
        the result does not depend on it
    """
    rng = np.random.default_rng(options.seed)
    lower, upper = np.asarray(options.lower, float), np.asarray(options.upper, float)
    sigma0 = np.asarray(options.sigma0, float)
    x_cur = np.clip(np.asarray(x0, float), lower, upper)
    e_cur, info_cur = f(x_cur, math.inf)
    best = AnnealResult(x=x_cur.copy(), value=e_cur, info=info_cur)
    k_best = 0
    best.history.append(dict(k=0, value=e_cur, accepted=math.isfinite(e_cur), current=e_cur, best=e_cur,
                             temperature=float("nan"), sigma=float(np.mean(sigma0)), info=info_cur))
    if callback is not None:
        callback(best.history[-1])
    sigma = sigma0.copy()
    blocks = None if options.blocks is None else np.unique(np.asarray(options.blocks), return_inverse=True)[1]
    n_blocks = 0 if blocks is None else int(blocks.max()) + 1
    K = int(options.iterations)
    ratio = options.tau_end / options.tau0

    def shrunk(s, accepted):
        return np.clip(s * (GROW if accepted else SHRINK), SIGMA_MIN_REL * sigma0, sigma0)

    def propose(k, sig):
        """Proposal k from the current state with step sigma ``sig``: (x_i, threshold, T)."""
        step = sig * rng.standard_normal(x_cur.shape)
        if blocks is not None:
            pick = rng.random(n_blocks) < 1.0 / n_blocks
            pick[rng.integers(n_blocks)] = True
            step *= pick[blocks]
        x_i = np.clip(x_cur + step, lower, upper)
        u = 1.0 - rng.random()  # in (0, 1]; drawn every iteration: the stream does not depend on the values
        T = options.tau0 * ratio ** ((k - 1) / max(K, 1)) * abs(e_cur) if math.isfinite(e_cur) else math.inf
        # accept iff E_i < E_cur, or u < exp(-(E_i - E_cur) / T)  <=>  E_i < E_cur - T ln u
        threshold = e_cur - T * math.log(u) if math.isfinite(e_cur) and T > 0 else (e_cur if math.isfinite(e_cur) else math.inf)
        return x_i, threshold, T

    # pending proposals in order: [k, x, threshold, T, rng state after its draws, (value, info) or a future]
    pending: list = []
    draining: list = []  # discarded evaluations still running (they hold a slot until they finish)
    unused: list = []  # every discarded evaluation that was running
    sig_next, k_next, busy = sigma, 1, 0
    slots = 1 if evaluator is None else max(int(evaluator.slots), 1)
    max_pending = 1 if evaluator is None else 8 * slots  # screened proposals are cheap; bound the queue
    k = 1
    while k <= K:
        while k_next <= K and len(pending) < max_pending and (busy < slots or not pending):
            draining = [d for d in draining if not d.done()]
            if pending and busy + len(draining) >= slots:
                break
            x_i, thr, T = propose(k_next, sig_next)
            st = rng.bit_generator.state
            if evaluator is None:
                out = f(x_i, thr)
            else:
                out = evaluator.screen(x_i, thr)
                if out is None:
                    out, busy = evaluator.submit(x_i, thr), busy + 1
            pending.append([k_next, x_i, thr, T, st, out])
            sig_next, k_next = shrunk(sig_next, False), k_next + 1
        _, x_i, threshold, T, st, out = pending.pop(0)
        if not isinstance(out, tuple):
            out, busy = out.result(), busy - 1
        e_i, info_i = out
        accepted = math.isfinite(e_i) and (e_i < e_cur or e_i < threshold or not math.isfinite(e_cur))
        if accepted:
            x_cur, e_cur = x_i, e_i
            if e_i < best.value:
                best.x, best.value, best.info, k_best = x_i.copy(), e_i, info_i, k
        sigma = shrunk(sigma, accepted)
        rec = dict(k=k, value=e_i, accepted=accepted, current=e_cur, best=best.value, temperature=T,
                   sigma=float(np.mean(sigma / np.where(sigma0 > 0, sigma0, 1.0))), info=info_i)
        best.history.append(rec)
        best.iterations = k
        if callback is not None:
            callback(rec)
        done = stop is not None and stop(best.info, best.value, k, k_best)
        if accepted or done:  # the later proposals assumed a rejection: drop them, redraw from here
            for p in pending:
                if isinstance(p[5], tuple):
                    best.discarded.append(p[5][1])
                else:  # a running evaluation finishes unused
                    draining.append(p[5])
                    unused.append(p[5])
            pending, busy = [], 0
            rng.bit_generator.state = st
            sig_next, k_next = sigma, k + 1
        if done:
            best.stopped_early = k < K
            break
        k += 1
    best.discarded += [u.result()[1] for u in unused]  # once the running ones are done
    return best
