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
on the number of workers. Starting a worker (spawned Python, NumPy/SciPy, Warp, simfab) takes
about 2 s, so :class:`Workers` can be started before the problem exists (``couple optimize``
starts them before the initial insertion and the handle placement, ~1.5-2.5 s on the stand side)
and serve several optimizations (the correction rounds).

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
    (placed once, by the caller), the seed, the mesh corrections of the figures with the margin
    the penalties aim inside the bounds, and the facets every candidate's insertion starts refined
    with (``DesignProblem.refined``)."""

    scene: str
    design: dict = field(default_factory=dict)
    simulation: dict = field(default_factory=dict)
    device: str = "cpu"
    handle_vertices: tuple = ()
    seed: int = 0
    corrections: dict = field(default_factory=dict)
    margin: float = 0.0
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
    return dataclasses.replace(p, corrections=dict(source.corrections), margin=source.margin,
                               refined=tuple(source.refined))


_WORKER = None  # (source without its refined facets, the DesignProblem it rebuilds to) in a worker
_CANCEL = None  # shared flags: _CANCEL[ticket % CANCEL_SLOTS] set when submission `ticket` is not needed
CANCEL_SLOTS = 1024  # more than the submissions ever in flight (the annealer bounds them)


def _init_worker(cancel) -> None:
    """A worker's start: the modules an evaluation needs (Python, NumPy/SciPy, Warp, simfab's
    coupling and design: most of a worker's ~2 s start-up), before any problem is known."""
    global _CANCEL
    _CANCEL = cancel
    import simfab.coupling.simulate  # noqa: F401
    import simfab.design.optimize  # noqa: F401
    from simfab._warp import device

    device("cpu")


def _problem(source: ProblemSource):
    """This worker's problem for ``source``, rebuilt when the source (facets aside) changed; the
    facets a candidate's run starts refined with are set without a rebuild (optimize() sets them
    after the initial insertion)."""
    global _WORKER
    key = dataclasses.replace(source, refined=())
    if _WORKER is None or _WORKER[0] != key:
        _WORKER = (key, rebuild(key))
    if tuple(source.refined) != _WORKER[1].refined:
        _WORKER = (key, dataclasses.replace(_WORKER[1], refined=tuple(source.refined)))
    return _WORKER[1]


def _ready(source: ProblemSource | None = None) -> bool:
    if source is not None:
        _problem(source)
    return True


def _evaluate_remote(source: ProblemSource, h: np.ndarray, threshold: float, ticket: int):
    from simfab.design.optimize import evaluate

    # without its InsertionResult (not sent back); aborted once the annealer cancels it
    slot = ticket % CANCEL_SLOTS
    return evaluate(_problem(source), h, threshold=threshold, abort=lambda: _CANCEL[slot] != 0)


class Workers:
    """``n`` worker processes for :class:`EvaluationPool`, started before the problem they will
    evaluate is known: their start-up (spawned Python, NumPy/SciPy, Warp, simfab; ~2 s) then
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

    def __init__(self, problem, workers):
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
        from simfab.design.optimize import screen

        ev = screen(self.problem, h, threshold)
        return (ev.objective, ev) if ev.reason else None

    def submit(self, h, threshold):
        w = self.workers
        t, w.tickets = w.tickets, w.tickets + 1
        w.cancel[t % CANCEL_SLOTS] = 0
        src = dataclasses.replace(self.problem.source, refined=tuple(self.problem.refined))
        return _Pending(w.executor.submit(_evaluate_remote, src, h, threshold, t), w.cancel, t % CANCEL_SLOTS)

    def restrict(self, out, threshold):
        """An evaluation run with a looser threshold, as if run with ``threshold``."""
        from simfab.design.optimize import restricted

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
