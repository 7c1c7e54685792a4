"""Wall-time accounting of an insertion run: per stage (assembly, factorization, solves, contact
field, barrier, line search, predictor) and per phase of the loop (warm_start, newton, facet_check,
record, rigid_check).

Each :class:`Timer` books a ``with`` block's time *exclusively*: a block opened inside another block
of the same timer pauses the outer one, so a timer's figures add up to at most the wall time and
never count a second twice (e.g. the triangular solves inside a solve that also factorizes book
under "solves", the factorization under "factorization"). Within :meth:`Timer.into` every block of
the timer books under one key (e.g. the predictor's assembly and solves under "predictor").
"""

from __future__ import annotations

import time

_clock = time.perf_counter


class Timer:
    """Accumulates exclusive wall time per category in ``t`` (seconds) and the number of blocks
    timed per category in ``n``."""

    def __init__(self):
        self.t: dict[str, float] = {}
        self.n: dict[str, int] = {}
        self._open: list = []  # the open spans, innermost last
        self._into: str | None = None

    def add(self, key: str, dt: float) -> None:
        self.t[key] = self.t.get(key, 0.0) + dt

    def timed(self, key: str) -> "Span":
        """Book the wall time of a ``with`` block under ``key`` (exclusive of blocks nested in it)."""
        return _NULL if self._into is not None else Span(self, key)

    def into(self, key: str) -> "Into":
        """A ``with`` block whose whole time, blocks nested in it included, books under ``key``."""
        return Into(self, key)


class Span:
    """``with`` block timed into a :class:`Timer` (a plain class: it runs on every objective
    evaluation, where a generator-based context manager costs a few times more)."""

    __slots__ = ("timer", "key", "t0")

    def __init__(self, timer: Timer, key: str):
        self.timer, self.key = timer, key

    def __enter__(self):
        timer = self.timer
        now = _clock()
        opened = timer._open
        if opened:  # pause the enclosing span
            outer = opened[-1]
            t = timer.t
            t[outer.key] = t.get(outer.key, 0.0) + (now - outer.t0)
        self.t0 = now
        opened.append(self)

    def __exit__(self, *exc):
        timer = self.timer
        now = _clock()
        key, t, n = self.key, timer.t, timer.n
        t[key] = t.get(key, 0.0) + (now - self.t0)
        n[key] = n.get(key, 0) + 1
        opened = timer._open
        opened.pop()
        if opened:  # resume the enclosing span
            opened[-1].t0 = now


class _Null:
    __slots__ = ()

    def __enter__(self):
        pass

    def __exit__(self, *exc):
        pass


_NULL = _Null()


class Into:
    """See :meth:`Timer.into`."""

    __slots__ = ("timer", "span", "saved")

    def __init__(self, timer: Timer, key: str):
        self.timer, self.span = timer, Span(timer, key)

    def __enter__(self):
        self.saved = self.timer._into
        if self.saved is None:
            self.span.__enter__()
            self.timer._into = self.span.key

    def __exit__(self, *exc):
        if self.saved is None:
            self.timer._into = None
            self.span.__exit__(*exc)


class TimedSolver:
    """Solver wrapper (``solve``, ``solve_free``) that books its calls under "solves" and hands the
    timer to the wrapped :class:`simfab.solve.linear.SPDSolver` (found through ``.solver`` of
    wrappers such as :class:`simfab.coupling.rigid.PinnedSolver`), which books its numeric
    factorizations under "factorization"."""

    def __init__(self, solver, timer):
        self.solver, self.timer = solver, timer
        inner = solver
        while hasattr(inner, "solver"):
            inner = inner.solver
        if hasattr(inner, "timer"):
            inner.timer = timer

    def solve(self, A, b):
        return self._timed(self.solver.solve, A, b)

    def solve_free(self, A, free, b):
        return self._timed(self.solver.solve_free, A, free, b)

    def _timed(self, fn, *args):
        with self.timer.timed("solves"):
            return fn(*args)
