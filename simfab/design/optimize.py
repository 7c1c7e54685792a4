"""The rest-shape optimization loop (thesis, "Rest Shape Optimization").

    minimize_h  E(h) = E_L(X'(h)) + W sum_c max(0, c(h) / scale_c)^2      (or a target-profile error)

over the handle parameters h (per active handle: a translation and per-axis scales, within the
problem's bounds). Simulated annealing (:mod:`simfab.design.anneal`) proposes designs; each is
evaluated by :func:`simfab.design.problem.evaluate` (validity, one insertion simulation, the
objective; stopped early once it provably exceeds the annealer's acceptance threshold). The
optimization stops after ``iterations`` or once the best design satisfies every constraint and
has not improved by PATIENCE_REL for ``patience`` iterations.

With several workers the annealer's speculative proposals are evaluated on worker processes
(:mod:`simfab.design.parallel`); the decisions, hence the result, are those of one worker.
The best design's insertion is finally run again without the seeded refinement
(``EvaluationConfig.refined``), as ``couple simulate`` runs it, so that its reported figures
are those of the plain simulation.
"""

from __future__ import annotations

import contextlib
import math
import time
from dataclasses import dataclass

import numpy as np

from simfab.design.anneal import AnnealConfig, anneal
from simfab.design.parallel import EvaluationPool, Workers
from simfab.design.problem import DesignEvaluation, DesignProblem, evaluate, initial_evaluation
from simfab.errors import ConvergenceError
from simfab.progress import progress

#: Early stop: an improvement of the best objective smaller than this fraction does not count.
PATIENCE_REL = 1e-3


@dataclass(kw_only=True)
class OptimizationResult:
    """Outcome of an optimizer run (:func:`optimize_anneal`, :func:`simfab.design.gradient.optimize_gradient`).

    Args:
        problem: the :class:`DesignProblem` optimized.
        initial, best: :class:`DesignEvaluation` (with their InsertionResults).
        history: the optimizer's log, one dict per iteration (typed: :func:`history_rows`).
        accepted: [(iteration, rest (n, d) [m], objective)] of every accepted design, in order.
        simulations: insertion simulations run to the end.
        stopped_simulations: simulations stopped early (their candidate provably rejected).
        rejected: {reason: count} of invalid candidates.
        seconds: wall time [s].
        sim_seconds: time inside the simulator, summed over the evaluations used (with several
            workers it may exceed the wall time) [s].
        iterations: optimizer iterations run.
        stopped_early: the run stopped before its iteration budget.
        speculative: insertion simulations run ahead on a worker and not needed (a proposal before
            them was accepted, or an acceptance branch's head rejected).
        workers: processes that evaluated candidates.
        branches: the annealer's acceptance branches (drawn, adopted).
        method: "anneal" (:func:`optimize_anneal`) or "gradient" (:func:`simfab.design.gradient.optimize_gradient`).
        gradient_evaluations: insertions that also gave the figures' gradients.
        message: the optimizer's own closing message ("" for annealing).
        events: the gradient method's count of non-smooth events between consecutive simulated designs
            (:func:`simfab.design.gradient.nonsmooth_events`), None for annealing.
        resume: the gradient method's simulation of its best design with its gradients (held steps),
            which a correction round started from that design reuses instead of simulating it again;
            None for annealing.
    """

    problem: DesignProblem
    initial: DesignEvaluation
    best: DesignEvaluation
    history: list
    accepted: list
    simulations: int
    stopped_simulations: int
    rejected: dict
    seconds: float
    sim_seconds: float
    iterations: int
    stopped_early: bool
    speculative: int = 0
    workers: int = 1
    branches: tuple = (0, 0)
    method: str = "anneal"
    gradient_evaluations: int = 0
    message: str = ""
    events: object = None  # a simfab.design.gradient.NonsmoothEvents (gradient method)
    resume: object = None


def optimize_anneal(problem: DesignProblem, *, iterations: int | None = None, seed: int = 0, quiet: bool = True,
             callback=None, workers=1, start=None, until=None) -> OptimizationResult:
    """Run simulated annealing on ``problem`` (see the module docstring) with random ``seed``;
    ``iterations`` defaults to the brief's. ``workers`` > 1 evaluates that many proposals at once
    (:mod:`simfab.design.parallel`; needs ``problem.source``): the same result, sooner; running
    :class:`simfab.design.parallel.Workers` (started early by the caller) may be passed instead. ``start``:
    the design vector to start from (default: the unmodified shape; the initial evaluation is
    always of that shape, a start's is the annealer's first). Raises
    ConvergenceError if the initial shape itself cannot be simulated (there is nothing to start
    from)."""
    t0 = time.perf_counter()
    brief = problem.brief
    K = brief.iterations if iterations is None else int(iterations)
    counts = {"simulations": 0, "stopped": 0, "sim_seconds": 0.0}
    rejected: dict[str, int] = {}
    accepted: list = []
    history_evals: list[DesignEvaluation] = []

    def f(h, threshold):
        if start is None and not history_evals:  # the annealer's start: the initial shape, evaluated below
            return initial.objective, initial
        ev = evaluate(problem, h, keep_result=True, threshold=threshold)
        return ev.objective, ev

    bar = iter(progress(range(K + 1), total=K + 1, desc=f"optimize {problem.base.name}", quiet=quiet))

    kept = {"best": None}

    def on_iteration(rec):
        next(bar, None)
        ev = rec["info"]
        history_evals.append(ev)
        if ev.status == "ok" or ev.reason.startswith("simulation"):
            counts["simulations"] += 1
        elif ev.status == "stopped" and ev.sim_seconds > 0:
            counts["stopped"] += 1
        counts["sim_seconds"] += ev.sim_seconds
        if ev.status == "rejected":
            key = ev.reason.split(":")[0]
            rejected[key] = rejected.get(key, 0) + 1
        if rec["accepted"]:
            accepted.append((rec["k"], ev.rest, rec["value"]))
        # only the initial and the best design keep their insertion results (memory)
        if rec["k"] > 0 and ev.status == "ok" and rec["accepted"] and rec["value"] <= rec["best"]:
            if kept["best"] is not None:
                kept["best"].result = None
            kept["best"] = ev
        elif rec["k"] > 0:
            ev.result = None
        if callback is not None:
            callback(rec)

    def stop(best_info, best_value, k, k_best):
        # the best value counts as improved when it fell by more than PATIENCE_REL
        if best_value < progress_ref["value"] * (1.0 - PATIENCE_REL) or not math.isfinite(progress_ref["value"]):
            progress_ref.update(value=best_value, k=k)
        if until is not None and until(best_info):
            return True
        return best_info.feasible and k - progress_ref["k"] >= brief.patience

    progress_ref = {"value": math.inf, "k": 0}
    blocks = np.repeat(np.arange(problem.handles.n_active), 2 * problem.handles.dim)  # one block per handle
    opts = AnnealConfig(iterations=K, sigma0=problem.sigma0, lower=problem.lower, upper=problem.upper, blocks=blocks,
                         seed=seed)
    procs = workers if isinstance(workers, Workers) else None
    workers = max(1, min(procs.n if procs is not None else int(workers), K))
    x0 = problem.handles.identity() if start is None else np.asarray(start, float)
    with contextlib.ExitStack() as stack:
        # workers start first: they rebuild the problem while this process evaluates the initial shape
        pool = stack.enter_context(EvaluationPool(problem, procs or workers)) if workers > 1 else None
        # the unmodified shape's insertion gives the facets every candidate's run starts refined
        # with (problem.settings.refined; the pool sends the settings with each candidate)
        initial = initial_evaluation(problem)
        if initial.status != "ok":
            raise ConvergenceError(f"the initial shape cannot be simulated ({initial.reason}); nothing to "
                                   "optimize from")
        if not problem.settings.refined and initial.result.refined_facets:
            problem = problem.with_settings(refined=tuple(int(i) for i in initial.result.refined_facets))
            if pool is not None:
                pool.problem = problem
        out = anneal(f, x0, opts, stop=stop, callback=on_iteration, evaluator=pool)
    best = out.info
    if best.status == "ok" and (best.result is None or problem.settings.refined):
        # the best design's insertion again, here (it may have run on a worker) and as `couple
        # simulate` runs it: without the seeded refinement, whose figures differ by the contact
        # discretization
        plain = evaluate(problem.with_settings(refined=()), best.h, keep_result=True)
        if plain.status == "ok":
            best = plain
        elif best.result is None:  # (should the plain run fail where the seeded one converged)
            best.result = evaluate(problem, best.h, keep_result=True).result
    history = [dict(rec, evaluation=history_evals[i]) for i, rec in enumerate(out.history)]
    speculative = sum(1 for ev in out.discarded if ev.sim_seconds > 0)
    return OptimizationResult(problem=problem, initial=initial, best=best, history=history, accepted=accepted,
                        simulations=counts["simulations"], stopped_simulations=counts["stopped"], rejected=rejected,
                        seconds=time.perf_counter() - t0, sim_seconds=counts["sim_seconds"], iterations=out.iterations,
                        stopped_early=out.stopped_early, speculative=speculative, workers=workers,
                        branches=tuple(out.branches))


@dataclass(frozen=True, kw_only=True)
class HistoryRow:
    """One iteration of an optimization.

    Args:
        iteration: the iteration (0: the start design).
        evaluation: the design evaluated (:class:`simfab.design.problem.DesignEvaluation`: status, objective,
            E_L, figures, seconds).
        accepted: whether the optimizer moved to it.
        current_objective: the objective of the design the optimizer stands on after it [-].
        best_objective: the best objective so far [-].
    """

    iteration: int
    evaluation: DesignEvaluation
    accepted: bool
    current_objective: float
    best_objective: float


@dataclass(frozen=True, kw_only=True)
class AnnealRow(HistoryRow):
    """One iteration of simulated annealing: a :class:`HistoryRow` and the annealer's state.

    Args:
        temperature: the acceptance temperature [-] (None at the start design, before the first proposal).
        sigma_rel: the proposal step relative to its initial value, averaged over the parameters [-].
    """

    temperature: float | None
    sigma_rel: float


def history_rows(res: OptimizationResult) -> tuple[HistoryRow, ...]:
    """The typed history of an optimizer run: :class:`AnnealRow` per iteration of annealing,
    :class:`HistoryRow` (no annealing state) per iteration of the gradient method.

    Args:
        res: an :class:`OptimizationResult`.

    Returns:
        One row per iteration, in order.
    """
    rows = []
    for rec in res.history:
        common = dict(iteration=int(rec["k"]), evaluation=rec["evaluation"], accepted=bool(rec["accepted"]),
                      current_objective=float(rec["current"]), best_objective=float(rec["best"]))
        if res.method == "anneal":
            t = float(rec["temperature"])
            rows.append(AnnealRow(**common, temperature=t if math.isfinite(t) else None,
                                  sigma_rel=float(rec["sigma"])))
        else:
            rows.append(HistoryRow(**common))
    return tuple(rows)
