"""Parallel evaluation of the annealer's speculative proposals (:mod:`simfab.design.anneal`)
on worker processes.

One optimization is a chain of decisions, but most proposals are rejected, so the annealer can
draw the next proposals before the current one is decided. :class:`EvaluationPool` screens each
in this process (shape validity and E_L against the threshold decide most of them at once,
:func:`simfab.design.problem.screen`) and runs the insertion simulations of the others on worker
processes, as many at a time as there are workers; a run that is no longer needed (a proposal
before it was accepted) is cancelled at its next step instead of holding its worker.

Each worker holds its own :class:`~simfab.design.problem.DesignProblem`, rebuilt from the
problem's :class:`~simfab.design.problem.ProblemSource` (:func:`simfab.design.problem.rebuild`),
and receives the problem's :class:`~simfab.design.problem.EvaluationConfig` with every task:
the problem's Warp arrays and caches do not cross process boundaries, and workers are spawned,
not forked, because Warp's runtime is not fork-safe. Rebuilding is deterministic, so a worker
evaluates a design to exactly the figures this process would (tested), and the optimization's
result does not depend on the number of workers.

Starting a worker (spawned Python, NumPy/SciPy, Warp, simfab) costs seconds, so :class:`Workers`
can be started before the problem exists (``couple optimize`` starts them before the initial
insertion and the handle placement, which their start-up then overlaps) and serve several
optimizations (the correction rounds). Measured speed-ups: ``python tools/bench.py optimize``
with ``--workers 1`` and ``2``.
"""

from __future__ import annotations

import dataclasses
import multiprocessing
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from simfab._warp import device
from simfab.design.problem import (
    DesignEvaluation,
    DesignProblem,
    EvaluationConfig,
    ProblemSource,
    evaluate,
    rebuild,
    restricted,
    screen,
)

#: In a worker: the source of the problem it holds (None before its first task) and that problem.
_WORKER: tuple[ProblemSource, DesignProblem] | None = None
_CANCEL = None  # shared flags: _CANCEL[ticket % CANCEL_SLOTS] set when submission `ticket` is not needed
CANCEL_SLOTS = 1024  # more than the submissions ever in flight (the annealer bounds them)


def _init_worker(cancel) -> None:
    """A worker's start, before any problem is known: the shared cancel flags and the Warp device
    (importing this module has already loaded what an evaluation needs: NumPy/SciPy, Warp, simfab's
    coupling and design, most of a worker's start-up)."""
    global _CANCEL
    _CANCEL = cancel
    device("cpu")


def _problem(source: ProblemSource, settings: EvaluationConfig | None = None) -> DesignProblem:
    """This worker's problem for ``source``, rebuilt when the source changed, with ``settings``
    (set without a rebuild: they change between the rounds of one optimization)."""
    global _WORKER
    if _WORKER is None or _WORKER[0] != source:
        _WORKER = (source, rebuild(source))
    if settings is not None and settings != _WORKER[1].settings:
        _WORKER = (source, dataclasses.replace(_WORKER[1], settings=settings))
    return _WORKER[1]


def _ready(source: ProblemSource | None = None) -> bool:
    if source is not None:
        _problem(source)
    return True


def _evaluate_remote(source: ProblemSource, settings: EvaluationConfig, h: np.ndarray, threshold: float,
                     ticket: int) -> DesignEvaluation:
    # without its InsertionResult (not sent back); aborted once the annealer cancels it
    slot = ticket % CANCEL_SLOTS
    return evaluate(_problem(source, settings), h, threshold=threshold, abort=lambda: _CANCEL[slot] != 0)


class Workers:
    """``n`` worker processes for :class:`EvaluationPool`, started before the problem they will
    evaluate is known: their start-up (spawned Python, NumPy/SciPy, Warp, simfab: seconds) then
    overlaps the caller's own work (the initial insertion, the handle placement) instead of
    delaying the annealing's first simulations. Each builds a problem on its first task for it and
    keeps it while the tasks' :class:`ProblemSource` stays the same, so one set of workers serves
    several optimizations (e.g. ``couple optimize``'s correction rounds). A context manager (shuts
    the processes down)."""

    def __init__(self, n: int):
        self.n = int(n)
        ctx = multiprocessing.get_context("spawn")  # Warp's runtime is not fork-safe
        self.cancel = ctx.Array("b", CANCEL_SLOTS, lock=False)  # written here only; workers read it
        self.tickets = 0
        self.executor = ProcessPoolExecutor(max_workers=self.n, mp_context=ctx, initializer=_init_worker,
                                            initargs=(self.cancel,))
        for _ in range(self.n):  # start the processes now
            self.executor.submit(_ready)

    def close(self) -> None:
        self.executor.shutdown(wait=True, cancel_futures=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class EvaluationPool:
    """The annealer's speculative evaluator (:func:`simfab.design.anneal.anneal`, ``evaluator``):
    ``screen`` runs the cheap checks here (shape validity, E_L against the threshold), ``submit``
    sends a candidate's insertion simulation to one of the worker processes (``slots``).
    ``workers``: a number of processes to start (and shut down on exit), or running
    :class:`Workers` (left running). A context manager."""

    def __init__(self, problem: DesignProblem, workers: int | Workers):
        if problem.source is None:
            raise ValueError("parallel evaluation needs a problem built from a scene file (problem.source)")
        self.problem = problem
        self._own = not isinstance(workers, Workers)
        self.workers = Workers(workers) if self._own else workers
        self.slots = self.workers.n
        # the workers build the problem while this process evaluates the start
        for _ in range(self.slots):
            self.workers.executor.submit(_ready, problem.source)

    def screen(self, h, threshold):
        ev = screen(self.problem, h, threshold)
        return (ev.objective, ev) if ev.reason else None

    def submit(self, h, threshold):
        w = self.workers
        t, w.tickets = w.tickets, w.tickets + 1
        w.cancel[t % CANCEL_SLOTS] = 0
        p = self.problem
        return _Pending(w.executor.submit(_evaluate_remote, p.source, p.settings, h, threshold, t), w.cancel,
                        t % CANCEL_SLOTS)

    def restrict(self, out, threshold):
        """An evaluation run with a looser threshold, as if run with ``threshold``."""
        ev = restricted(self.problem, out[1], threshold)
        return ev.objective, ev

    def close(self) -> None:
        if self._own:
            self.workers.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class _Pending:
    """A submitted evaluation: ``result()`` -> (objective, DesignEvaluation)."""

    def __init__(self, future, flags, slot: int):
        self._f, self._flags, self._slot = future, flags, slot

    def done(self) -> bool:
        return self._f.done()

    def cancel(self) -> None:
        """Not needed any more: a running simulation stops at its next step (it would otherwise
        hold its worker until it ends)."""
        self._flags[self._slot] = 1

    def result(self):
        ev = self._f.result()
        return ev.objective, ev
