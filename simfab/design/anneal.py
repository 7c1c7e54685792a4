"""Simulated annealing (Kirkpatrick et al. 1983) over a bounded design vector, seeded.

Per iteration k (thesis, Algorithm "Rest Shape Optimization"):

1. proposal  x_i = clip(x_cur + sigma_k * N(0, I) * mask, lower, upper)   (Gaussian around the current
   state; with ``blocks`` (one per handle) the mask moves mostly one handle at a time)
2. temperature  T_k = tau_k * |E_cur|,  tau_k = tau_0 (tau_end / tau_0)^(k / K)   (exponential cooling,
   relative to the current objective: scale-free Metropolis)
3. Metropolis: accept if E_i < E_cur - T_k ln u, u drawn before E_i is evaluated, so ``f`` receives
   that threshold and may stop at a lower bound that exceeds it; the best state seen is returned.
4. adaptive, decaying step: sigma_{k+1} = sigma_k * GROW after an accepted proposal, * SHRINK
   after a rejected one, within [SIGMA_MIN_REL sigma_0, sigma_0].

A candidate whose value is +inf (rejected: invalid shape, failed simulation) is never accepted.
Stops after K iterations or when ``stop(best_info, k)`` says so.

With an ``evaluator``, proposals k+1, k+2, ... are drawn before k is decided (each assuming the
pending ones rejected) and evaluated concurrently; while most proposals are accepted a free slot
runs the acceptance branch (the proposals after the head as if it were accepted). Every decision,
hence the result, is exactly that of the serial loop with the same seed.

The reasoning (relative temperature, speculative evaluation, acceptance branch): docs/methods.md,
"simfab.design.anneal".
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np

#: Speculative evaluation: how often the loop checks whether the head's evaluation or a slot is done [s].
POLL_SECONDS = 0.002
GROW = 1.10
SHRINK = 0.97
SIGMA_MIN_REL = 0.05


@dataclass(frozen=True, kw_only=True)
class AnnealConfig:
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


@dataclass(kw_only=True, eq=False)
class _Proposal:
    """A drawn proposal: iteration k, design x, uniform u and temperature factor c of its test,
    acceptance threshold thr and temperature T (from the state it was drawn from), the random
    stream's state after its draws, and its evaluation: (value, info), or a submitted one."""

    k: int
    x: np.ndarray
    u: float
    c: float
    thr: float
    T: float
    st: dict
    out: object = None
    thr_exact: float = math.nan

    @property
    def running(self) -> bool:
        return not isinstance(self.out, tuple)


def _live(q) -> bool:
    """Whether proposal q (or None) has an evaluation still running."""
    return q is not None and q.running and not q.out.done()


@dataclass(kw_only=True, eq=False)
class _Branch:
    """Proposals drawn after ``head`` assuming it is accepted; sig and k_next continue the draws."""

    head: _Proposal
    props: list
    sig: np.ndarray
    k_next: int


class _Restricted:
    """A submitted evaluation run with a looser threshold, read as if run with ``threshold``
    (``evaluator.restrict``)."""

    def __init__(self, pending, evaluator, threshold: float):
        self.pending, self.evaluator, self.threshold = pending, evaluator, threshold

    def done(self) -> bool:
        return self.pending.done()

    def cancel(self) -> None:
        if hasattr(self.pending, "cancel"):
            self.pending.cancel()

    def result(self):
        return self.evaluator.restrict(self.pending.result(), self.threshold)


@dataclass(kw_only=True)
class AnnealResult:
    """Outcome of :func:`anneal`.

    Args:
        x: (n,) the best point.
        value: f(x) [units of f].
        info: what f returned with it.
        history: one dict per iteration (k, value, accepted, current, best, temperature, sigma, info).
        iterations: iterations run.
        stopped_early: ``stop`` ended the run.
        discarded: infos of speculative evaluations that were not needed (a proposal before them was
            accepted, or the one an acceptance branch assumed accepted was rejected).
        branches: acceptance branches [drawn, adopted].
    """

    x: np.ndarray
    value: float
    info: object
    history: list = field(default_factory=list)
    iterations: int = 0
    stopped_early: bool = False
    discarded: list = field(default_factory=list)
    branches: list = field(default_factory=lambda: [0, 0])  # acceptance branches drawn, adopted


def anneal(f, x0: np.ndarray, options: AnnealConfig, *, stop=None, callback=None, evaluator=None) -> AnnealResult:
    """Minimize ``f`` by simulated annealing from ``x0``.

    f : callable (x, threshold) -> (value, info); value may be +inf for a rejected candidate, or
        any lower bound of the value larger than ``threshold`` (the acceptance threshold)
    stop : optional callable (best_info, best_value, k, k_best) -> bool, asked after every iteration
        (k_best: iteration at which the best value was found)
    callback : optional callable(record dict) after every iteration
    evaluator : optional speculative evaluator (see the module docstring) with ``slots`` (int),
        ``screen(x, threshold) -> (value, info) | None`` (None: needs the full evaluation) and
        ``submit(x, threshold)`` returning an object with ``result()`` (= ``f(x, threshold)``),
        ``done()`` and optionally ``cancel()`` (called when the evaluation is no longer needed: it
        may stop early); optionally ``restrict((value, info), threshold) -> (value, info)``, the
        evaluation of a looser threshold read as ``f`` with ``threshold`` would have returned it,
        which enables the acceptance branch. The result does not depend on the evaluator.
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

    def draw(gen, x_base, k, sig):
        """Proposal k around x_base with step sigma ``sig`` from generator ``gen``: (x_i, u, c),
        c = tau_k (the temperature is c |E| of the state it is drawn from)."""
        step = sig * gen.standard_normal(x_base.shape)
        if blocks is not None:
            pick = gen.random(n_blocks) < 1.0 / n_blocks
            pick[gen.integers(n_blocks)] = True
            step *= pick[blocks]
        x_i = np.clip(x_base + step, lower, upper)
        u = 1.0 - gen.random()  # in (0, 1]; drawn every iteration: the stream does not depend on the values
        return x_i, u, options.tau0 * ratio ** ((k - 1) / max(K, 1))

    def threshold(e_base, u, c):
        """(threshold, T) of a proposal drawn from a state of value e_base: accept iff E_i < E_base,
        or u < exp(-(E_i - E_base) / T)  <=>  E_i < E_base - T ln u."""
        if not math.isfinite(e_base):
            return math.inf, math.inf
        T = c * abs(e_base)
        return (e_base - T * math.log(u) if T > 0 else e_base), T

    pending: list[_Proposal] = []  # drawn, undecided, in order; each assumes the ones before it rejected
    branch = None  # _Branch: proposals drawn assuming pending[0] is accepted
    draining: list = []  # discarded evaluations still running (they hold a slot until they finish or stop)
    unused: list = []  # every discarded evaluation that was running
    sig_next, k_next = sigma, 1
    slots = 1 if evaluator is None else max(int(evaluator.slots), 1)
    max_pending = 1 if evaluator is None else 8 * slots  # screened proposals are cheap; bound the queue
    can_branch = slots > 1 and hasattr(evaluator, "restrict")
    sims = [0, 0]  # submitted proposals decided, accepted (the acceptance rate chooses the branch)

    def drop(props):
        for q in props:
            if q.running:
                if hasattr(q.out, "cancel"):
                    q.out.cancel()
                draining.append(q.out)
                unused.append(q.out)
            else:
                best.discarded.append(q.out[1])

    def grow_branch(head):
        """Proposals after ``head`` assuming it is accepted, up to the first that needs its full
        evaluation (submitted). Their thresholds depend on head's unknown value E_h; with E >= 0
        (the design objective), E_h < head.thr and the threshold grows with E_h, so each is
        screened and submitted with the threshold head.thr would give, an upper bound
        (``adopt`` checks it and tightens each to its exact threshold)."""
        gen = np.random.default_rng()
        gen.bit_generator.state = head.st
        b = _Branch(head=head, props=[], sig=shrunk(sigma, True), k_next=head.k + 1)
        while b.k_next <= K and len(b.props) < max_pending:
            x_j, u, c = draw(gen, head.x, b.k_next, b.sig)
            thr_up, _ = threshold(head.thr, u, c)
            q = _Proposal(k=b.k_next, x=x_j, u=u, c=c, thr=thr_up, T=math.nan, st=gen.bit_generator.state)
            q.out = evaluator.screen(x_j, thr_up)
            b.props.append(q)
            b.sig, b.k_next = shrunk(b.sig, False), b.k_next + 1
            if q.out is None:
                q.out = evaluator.submit(x_j, thr_up)
                break
        return b

    def adopt(b, e_h):
        """The branch's proposals with their exact thresholds from the accepted head's value e_h, or
        None when one exceeds the bound it was screened with (then they are redrawn)."""
        for q in b.props:
            thr, q.T = threshold(e_h, q.u, q.c)
            if not thr <= q.thr:
                return None
            q.thr_exact = thr
        for q in b.props:  # as the serial loop: screened with the exact threshold, else evaluated with it
            out = evaluator.screen(q.x, q.thr_exact)
            if out is not None:
                if q.running:  # its evaluation with the bound is not needed
                    drop([dataclasses.replace(q)])
                q.out = out
            elif q.running:
                q.out = _Restricted(q.out, evaluator, q.thr_exact)
            else:
                q.out = evaluator.submit(q.x, q.thr_exact)
            q.thr = q.thr_exact
        return b.props

    k = 1
    while k <= K:
        while True:
            draining = [d for d in draining if not d.done()]
            used = sum(map(_live, pending)) + len(draining) + (0 if branch is None else sum(map(_live, branch.props)))
            head = pending[0] if pending else None
            if (can_branch and branch is None and head is not None and head.running and head.k < K and used < slots
                    and head.thr >= 0 and math.isfinite(head.thr) and (sims[1] + 1) / (sims[0] + 2) > 0.5):
                # acceptance is the likelier outcome: the free slot evaluates the next proposal as if
                # the head were accepted rather than the one after it as if rejected
                branch = grow_branch(head)
                best.branches[0] += 1
                continue
            if k_next > K or len(pending) >= max_pending or (pending and used >= slots):
                if not _live(head):
                    break
                time.sleep(POLL_SECONDS)  # the head is running: wait for it, or for a slot to free
                continue
            x_i, u, c = draw(rng, x_cur, k_next, sig_next)
            thr, T = threshold(e_cur, u, c)
            q = _Proposal(k=k_next, x=x_i, u=u, c=c, thr=thr, T=T, st=rng.bit_generator.state)
            if evaluator is None:
                q.out = f(x_i, thr)
            else:
                q.out = evaluator.screen(x_i, thr)
                if q.out is None:
                    q.out = evaluator.submit(x_i, thr)
            pending.append(q)
            sig_next, k_next = shrunk(sig_next, False), k_next + 1
        head = pending.pop(0)
        submitted = head.running
        e_i, info_i = head.out.result() if submitted else head.out
        accepted = math.isfinite(e_i) and (e_i < e_cur or e_i < head.thr or not math.isfinite(e_cur))
        if submitted:
            sims[0], sims[1] = sims[0] + 1, sims[1] + int(accepted)
        if accepted:
            x_cur, e_cur = head.x, e_i
            if e_i < best.value:
                best.x, best.value, best.info, k_best = head.x.copy(), e_i, info_i, k
        sigma = shrunk(sigma, accepted)
        rec = dict(k=k, value=e_i, accepted=accepted, current=e_cur, best=best.value, temperature=head.T,
                   sigma=float(np.mean(sigma / np.where(sigma0 > 0, sigma0, 1.0))), info=info_i)
        best.history.append(rec)
        best.iterations = k
        if callback is not None:
            callback(rec)
        done = stop is not None and stop(best.info, best.value, k, k_best)
        b, branch = branch, None
        if accepted or done:  # the later proposals assumed a rejection: drop them
            drop(pending)
            pending = adopt(b, e_i) if b is not None and accepted and not done else None
            if pending:  # continue from the branch drawn for this acceptance
                best.branches[1] += 1
                rng.bit_generator.state = b.props[-1].st
                sig_next, k_next = b.sig, b.k_next
            else:  # redraw from here
                if b is not None:
                    drop(b.props)
                pending = []
                rng.bit_generator.state = head.st
                sig_next, k_next = sigma, k + 1
        elif b is not None:  # the branch assumed an acceptance
            drop(b.props)
        if done:
            best.stopped_early = k < K
            break
        k += 1
    best.discarded += [u.result()[1] for u in unused]  # once the running ones are done
    return best
