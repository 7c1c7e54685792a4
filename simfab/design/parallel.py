"""Parallel evaluation of the annealer's speculative proposals (:mod:`simfab.design.anneal`,
``lookahead``) on worker processes.

One optimization is a chain of decisions, but most proposals are rejected, so the annealer can
draw the next P proposals from the same state and have them evaluated at once. This module
evaluates the first of a round in this process and the others on P - 1 worker processes. Each
worker holds its own :class:`~simfab.design.optimize.DesignProblem`, rebuilt from a
:class:`ProblemSource` (the scene file, the overrides and the placed handles): the problem's
Warp arrays and caches do not cross process boundaries, and workers are spawned, not forked
(Warp's runtime is not fork-safe). Rebuilding is deterministic, so a worker evaluates a design
to exactly the figures this process would (tested); the optimization's result does not depend
on the number of workers.

Measured (``python tools/bench.py optimize``, stand side, 2 cores): see the benchmark's output
``workers`` / ``speedup_vs_serial``; a worker costs ~3 s to start (imports, scene, weights).
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
    (placed once, by the caller), the seed and the mesh corrections of the figures."""

    scene: str
    design: dict = field(default_factory=dict)
    simulation: dict = field(default_factory=dict)
    device: str = "cpu"
    handle_vertices: tuple = ()
    seed: int = 0
    corrections: dict = field(default_factory=dict)


def rebuild(source: ProblemSource):
    """The :class:`~simfab.design.optimize.DesignProblem` that ``source`` describes."""
    from simfab._warp import device as check_device
    from simfab.design.optimize import make_problem
    from simfab.design.scene import load_design_scene

    ds = load_design_scene(source.scene, design=source.design, simulation=source.simulation,
                           device=check_device(source.device))
    p = make_problem(ds.cm, ds.brief, kept_regions=ds.kept_regions, target=ds.target,
                     handle_vertices=list(source.handle_vertices), seed=source.seed, source=source)
    return dataclasses.replace(p, corrections=dict(source.corrections))


_WORKER_PROBLEM = None


def _init_worker(source: ProblemSource) -> None:
    global _WORKER_PROBLEM
    _WORKER_PROBLEM = rebuild(source)


def _ready() -> bool:
    return _WORKER_PROBLEM is not None


def _evaluate_remote(h: np.ndarray, threshold: float):
    from simfab.design.optimize import evaluate

    return evaluate(_WORKER_PROBLEM, h, threshold=threshold)  # without its InsertionResult (not sent back)


class EvaluationPool:
    """``pool(items)`` evaluates ``[(h, threshold), ...]``: the first here (with its
    InsertionResult), the others on the workers; a context manager (shuts the workers down)."""

    def __init__(self, problem, workers: int):
        if problem.source is None:
            raise ValueError("parallel evaluation needs a problem built from a scene file (problem.source)")
        self.problem, self.workers = problem, int(workers)
        ctx = multiprocessing.get_context("spawn")
        self._ex = ProcessPoolExecutor(max_workers=self.workers - 1, mp_context=ctx, initializer=_init_worker,
                                       initargs=(problem.source,))
        # start the workers now (they rebuild the problem while this process evaluates the start)
        for _ in range(self.workers - 1):
            self._ex.submit(_ready)

    def __call__(self, items):
        from simfab.design.optimize import evaluate

        futures = [self._ex.submit(_evaluate_remote, h, t) for h, t in items[1:]]
        h, t = items[0]
        first = evaluate(self.problem, h, keep_result=True, threshold=t)
        return [first] + [f.result() for f in futures]

    def close(self) -> None:
        self._ex.shutdown(wait=True, cancel_futures=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
