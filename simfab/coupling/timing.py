"""Wall-time accounting of an insertion run: per resource (assembly, factorization, contact) and per
phase of the loop."""

from __future__ import annotations

import time


class Timer:
    """Accumulates wall time per category (assembly, factorization, contact, ...)."""

    def __init__(self):
        self.t: dict[str, float] = {}

    def add(self, key: str, dt: float) -> None:
        self.t[key] = self.t.get(key, 0.0) + dt

    def timed(self, key: str) -> "Span":
        """Book the wall time of a ``with`` block under ``key``."""
        return Span(self, key)


class Span:
    """``with`` block timed into a :class:`Timer` (a plain class: it runs on every objective
    evaluation, where a generator-based context manager costs a few times more)."""

    __slots__ = ("timer", "key", "t0")

    def __init__(self, timer: Timer, key: str):
        self.timer, self.key = timer, key

    def __enter__(self):
        self.t0 = time.perf_counter()

    def __exit__(self, *exc):
        self.timer.add(self.key, time.perf_counter() - self.t0)


class TimedSolver:
    """SPDSolver wrapper that books factorization + solve time."""

    def __init__(self, solver, timer):
        self.solver, self.timer = solver, timer

    def solve(self, A, b):
        return self._timed(self.solver.solve, A, b)

    def solve_free(self, A, free, b):
        return self._timed(self.solver.solve_free, A, free, b)

    def _timed(self, fn, *args):
        with self.timer.timed("factorization"):
            return fn(*args)
