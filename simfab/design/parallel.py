"""Parallel evaluation of the annealer's speculative proposals (:mod:`simfab.design.anneal`)
on worker processes.

One optimization is a chain of decisions, but most proposals are rejected, so the annealer can
draw the next proposals before the current one is decided. This module screens each in this
process (shape validity and E_L against the threshold decide most of them at once) and runs the
insertion simulations of the others on worker processes, as many at a time as there are
workers. Each worker holds its own :class:`~simfab.design.optimize.DesignProblem`, rebuilt from a
:class:`ProblemSource` (the scene file, the overrides and the placed handles): the problem's
Warp arrays and caches do not cross process boundaries, and workers are spawned, not forked
(Warp's runtime is not fork-safe). Rebuilding is deterministic, so a worker evaluates a design
to exactly the figures this process would (tested); the optimization's result does not depend
on the number of workers.

Measured on the stand side (300 iterations, 2-core machine at load 1.2-1.5, whose speed drifts by
up to 30 % within minutes, so compare runs made back to back): ``python tools/bench.py optimize
--no-mesh-check`` (2 workers) 32.7 s against 42.4 s with ``--workers 1``. 61 % of the simulated
candidates are accepted, so the free slot mostly serves the annealer's acceptance branch (49 drawn,
32 adopted); discarded runs are cancelled at their next step instead of holding their worker. The
same run before the acceptance branch and the cancellation: 37.1 s.
"""

from __future__ import annotations

import dataclasses
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True, kw_only=True)
class ProblemSource:
    """What rebuilds a design problem in another process: the scene (MJCF path), the overrides of
    its ``[design]`` and ``[simulation]`` tables, the Warp device, the active handle vertices
    (placed once, by the caller), the seed, the mesh corrections of the figures and the facets
    every candidate's insertion starts refined with (``DesignProblem.refined``)."""

    scene: str
    design: dict = field(default_factory=dict)
    simulation: dict = field(default_factory=dict)
    device: str = "cpu"
    handle_vertices: tuple = ()
    seed: int = 0
    corrections: dict = field(default_factory=dict)
    refined: tuple = ()


def rebuild(source: ProblemSource):
    """The :class:`~simfab.design.optimize.DesignProblem` that ``source`` describes."""
    from simfab._warp import device as check_device
    from simfab.design.optimize import make_problem
    from simfab.design.scene import load_design_scene

    ds = load_design_scene(source.scene, design=source.design, simulation=source.simulation,
                           device=check_device(source.device))
    p = make_problem(ds.cm, ds.brief, kept_regions=ds.kept_regions, target=ds.target,
                     handle_vertices=list(source.handle_vertices), seed=source.seed, source=source)
    return dataclasses.replace(p, corrections=dict(source.corrections), refined=tuple(source.refined))


_WORKER_PROBLEM = None
_CANCEL = None  # shared flags: _CANCEL[ticket % CANCEL_SLOTS] set when submission `ticket` is not needed
CANCEL_SLOTS = 1024  # more than the submissions ever in flight (the annealer bounds them)


def _init_worker(source: ProblemSource, cancel) -> None:
    global _WORKER_PROBLEM, _CANCEL
    _WORKER_PROBLEM = rebuild(source)
    _CANCEL = cancel


def _ready() -> bool:
    return _WORKER_PROBLEM is not None


def _evaluate_remote(h: np.ndarray, threshold: float, refined: tuple, ticket: int):
    global _WORKER_PROBLEM
    from simfab.design.optimize import evaluate

    if refined != _WORKER_PROBLEM.refined:  # set by optimize() after the initial insertion
        _WORKER_PROBLEM = dataclasses.replace(_WORKER_PROBLEM, refined=refined)
    # without its InsertionResult (not sent back); aborted once the annealer cancels it
    slot = ticket % CANCEL_SLOTS
    return evaluate(_WORKER_PROBLEM, h, threshold=threshold, abort=lambda: _CANCEL[slot] != 0)


class EvaluationPool:
    """The annealer's speculative evaluator (:func:`simfab.design.anneal.anneal`, ``evaluator``):
    ``screen`` runs the cheap checks here (shape validity, E_L against the threshold), ``submit``
    sends a candidate's insertion simulation to one of ``workers`` worker processes (``slots``).
    A context manager (shuts the workers down)."""

    def __init__(self, problem, workers: int):
        if problem.source is None:
            raise ValueError("parallel evaluation needs a problem built from a scene file (problem.source)")
        self.problem, self.slots = problem, int(workers)
        ctx = multiprocessing.get_context("spawn")
        self._cancel = ctx.Array("b", CANCEL_SLOTS, lock=False)  # written here only; workers read it
        self._tickets = 0
        self._ex = ProcessPoolExecutor(max_workers=self.slots, mp_context=ctx, initializer=_init_worker,
                                       initargs=(problem.source, self._cancel))
        # start the workers now (they rebuild the problem while this process evaluates the start)
        for _ in range(self.slots):
            self._ex.submit(_ready)

    def screen(self, h, threshold):
        from simfab.design.optimize import screen

        ev = screen(self.problem, h, threshold)
        return (ev.objective, ev) if ev.reason else None

    def submit(self, h, threshold):
        t, self._tickets = self._tickets, self._tickets + 1
        self._cancel[t % CANCEL_SLOTS] = 0
        return _Pending(self._ex.submit(_evaluate_remote, h, threshold, self.problem.refined, t), self._cancel,
                        t % CANCEL_SLOTS)

    def restrict(self, out, threshold):
        """An evaluation run with a looser threshold, as if run with ``threshold``."""
        from simfab.design.optimize import restricted

        ev = restricted(self.problem, out[1], threshold)
        return ev.objective, ev

    def close(self) -> None:
        self._ex.shutdown(wait=True, cancel_futures=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class _Pending:
    """A submitted evaluation: ``result()`` -> (objective, Evaluation)."""

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
