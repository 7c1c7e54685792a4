"""Ratings and truth tables: loading, validation, and the dense rating matrix.

Ratings are long-form, as crowd-kit uses them: one row per rating with columns
``worker, task, label``. Labels are integers on the survey scale ``[lo, hi]``. A rater may
skip questions (missing entries are NaN in the dense matrix). Truth is a CSV with columns
``task, truth`` (real values on the same scale, e.g. computed benchmarks).

Every problem raises :class:`~simfab.errors.InputError` naming the file, the row (the
line number in the file, header = line 1) or column, and what is wrong.
"""

from __future__ import annotations

import dataclasses
import math
import os

import numpy as np

from simfab.errors import InputError


@dataclasses.dataclass(frozen=True, kw_only=True)
class Scale:
    """An integer rating scale ``lo..hi`` (``lo < hi``)."""

    lo: float
    hi: float

    def __post_init__(self):
        for name, v in (("lo", self.lo), ("hi", self.hi)):
            if not math.isfinite(v) or v != round(v):
                raise InputError(f"scale {name}={v!r} must be a finite integer", where="--scale")
        if not self.lo < self.hi:
            raise InputError(f"scale must have lo < hi, got {self.lo:g} {self.hi:g}", where="--scale")

    @property
    def span(self) -> float:
        return self.hi - self.lo

    def to_unit(self, v):
        """Map scale values to [0, 1]."""
        return (np.asarray(v, dtype=float) - self.lo) / self.span

    def from_unit(self, u):
        """Map [0, 1] values back to the scale."""
        return self.lo + np.asarray(u, dtype=float) * self.span

    def round(self, v):
        """Nearest scale point; halves round up (``floor(v + 0.5)``), clipped to the scale."""
        return np.clip(np.floor(np.asarray(v, dtype=float) + 0.5), self.lo, self.hi)


@dataclasses.dataclass(frozen=True, kw_only=True)
class Ratings:
    """A crowd's ratings as a dense matrix.

    labels: (R, Q) float, scale units; NaN where rater i did not rate question j.
    workers: R rater ids; tasks: Q question ids (order of first appearance in the file).
    """

    labels: np.ndarray
    workers: tuple[str, ...]
    tasks: tuple[str, ...]
    scale: Scale
    source: str = "<memory>"

    @property
    def unit(self) -> np.ndarray:
        """(R, Q) ratings on the unit scale (NaN where missing)."""
        return self.scale.to_unit(self.labels)

    def to_long(self) -> list[tuple[str, str, int]]:
        """Long-form rows ``(worker, task, label)``."""
        out = []
        for i, w in enumerate(self.workers):
            for j, t in enumerate(self.tasks):
                v = self.labels[i, j]
                if np.isfinite(v):
                    out.append((w, t, int(v)))
        return out


def from_matrix(labels, scale: Scale, *, workers=None, tasks=None, source="<memory>") -> Ratings:
    """Build :class:`Ratings` from an (R, Q) array (NaN = missing), validating it."""
    labels = np.array(labels, dtype=float)
    if labels.ndim != 2 or labels.size == 0:
        raise InputError(f"ratings must be a non-empty (raters, questions) matrix, got shape {labels.shape}",
                         where=source)
    R, Q = labels.shape
    workers = tuple(str(w) for w in (workers if workers is not None else (f"w{i}" for i in range(R))))
    tasks = tuple(str(t) for t in (tasks if tasks is not None else (f"q{j}" for j in range(Q))))
    fin = np.isfinite(labels)
    bad = fin & ((labels < scale.lo) | (labels > scale.hi) | (labels != np.round(labels)))
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise InputError(f"label {labels[i, j]:g} of worker {workers[i]!r} on task {tasks[j]!r} is not an integer "
                         f"on the scale [{scale.lo:g}, {scale.hi:g}]", where=source)
    _check_coverage(fin, workers, tasks, source)
    return Ratings(labels=labels, workers=workers, tasks=tasks, scale=scale, source=source)


def _check_coverage(fin, workers, tasks, source):
    if not fin.any():
        raise InputError("no ratings (empty crowd)", where=source)
    empty_rows = np.flatnonzero(~fin.any(axis=1))
    if empty_rows.size:
        raise InputError(f"worker {workers[empty_rows[0]]!r} rated nothing", where=source)
    empty_cols = np.flatnonzero(~fin.any(axis=0))
    if empty_cols.size:
        raise InputError(f"task {tasks[empty_cols[0]]!r} has no ratings", where=source)


def _read_csv(path, required: tuple[str, ...]):
    import pandas as pd

    path = os.fspath(path)
    if not os.path.isfile(path):
        raise InputError("file not found", where=path)
    try:
        df = pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True)
    except pd.errors.EmptyDataError:
        raise InputError("empty file (no header, no rows)", where=path) from None
    except (pd.errors.ParserError, UnicodeDecodeError) as e:
        raise InputError(f"not a readable CSV ({' '.join(str(e).split())})", where=path) from None
    df.columns = [str(c).strip() for c in df.columns]
    missing = [c for c in required if c not in df.columns]
    if missing:
        raise InputError(f"missing column {missing[0]!r} (columns are {list(df.columns)}; need {list(required)})",
                         where=path)
    for c in required:
        df[c] = df[c].str.strip()
    return df


def _numbers(df, column, path):
    """Parse column as floats; InputError at the first non-numeric cell (line = index + 2)."""
    import pandas as pd

    vals = pd.to_numeric(df[column], errors="coerce").to_numpy(dtype=float)
    bad = ~np.isfinite(vals)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise InputError(f"line {k + 2}, column {column!r}: {df[column].iloc[k]!r} is not a finite number", where=path)
    return vals


def _ids(df, column, path):
    empty = (df[column] == "").to_numpy()
    if empty.any():
        k = int(np.flatnonzero(empty)[0])
        raise InputError(f"line {k + 2}, column {column!r}: empty", where=path)
    return df[column].tolist()


def load_ratings(path, scale: Scale) -> Ratings:
    """Read a long-form ratings CSV (``worker, task, label``) into :class:`Ratings`.

    Raises InputError on: missing file/columns, no rows, empty ids, non-numeric or
    non-integer labels, labels off the scale, duplicate (worker, task) pairs.
    """
    path = os.fspath(path)
    df = _read_csv(path, ("worker", "task", "label"))
    if len(df) == 0:
        raise InputError("no ratings (empty crowd)", where=path)
    workers = _ids(df, "worker", path)
    tasks = _ids(df, "task", path)
    labels = _numbers(df, "label", path)
    off = (labels < scale.lo) | (labels > scale.hi) | (labels != np.round(labels))
    if off.any():
        k = int(np.flatnonzero(off)[0])
        raise InputError(f"line {k + 2}, column 'label': {labels[k]:g} is not an integer on the scale "
                         f"[{scale.lo:g}, {scale.hi:g}]", where=path)
    w_ids = list(dict.fromkeys(workers))
    t_ids = list(dict.fromkeys(tasks))
    wi = {w: i for i, w in enumerate(w_ids)}
    ti = {t: j for j, t in enumerate(t_ids)}
    mat = np.full((len(w_ids), len(t_ids)), np.nan)
    first = {}
    for k, (w, t, v) in enumerate(zip(workers, tasks, labels)):
        key = (wi[w], ti[t])
        if key in first:
            raise InputError(f"line {k + 2}: duplicate rating of task {t!r} by worker {w!r} "
                             f"(first at line {first[key] + 2})", where=path)
        first[key] = k
        mat[key] = v
    return Ratings(labels=mat, workers=tuple(w_ids), tasks=tuple(t_ids), scale=scale, source=path)


def read_truth(path, scale: Scale) -> tuple[list[str], np.ndarray]:
    """Read ``task, truth`` (real values within the scale): task ids and (Q,) values."""
    path = os.fspath(path)
    df = _read_csv(path, ("task", "truth"))
    if len(df) == 0:
        raise InputError("no rows", where=path)
    tasks = _ids(df, "task", path)
    vals = _numbers(df, "truth", path)
    seen = {}
    for k, (t, v) in enumerate(zip(tasks, vals)):
        if t in seen:
            raise InputError(f"line {k + 2}: duplicate truth for task {t!r} (first at line {seen[t] + 2})", where=path)
        seen[t] = k
        if not scale.lo <= v <= scale.hi:
            raise InputError(f"line {k + 2}, column 'truth': {v:g} is outside the scale "
                             f"[{scale.lo:g}, {scale.hi:g}]", where=path)
    return tasks, vals


def load_truth(path, ratings: Ratings) -> np.ndarray:
    """Read ``task, truth`` and return truth (Q,) in the order of ``ratings.tasks``.

    Truth values are real numbers within the scale. Every rated task needs a truth and every
    truth row must name a rated task (a typo would otherwise silently drop a question).
    """
    path = os.fspath(path)
    tasks, vals = read_truth(path, ratings.scale)
    for k, t in enumerate(tasks):
        if t not in ratings.tasks:
            raise InputError(f"line {k + 2}: task {t!r} has a truth but no ratings in {ratings.source}", where=path)
    index = {t: k for k, t in enumerate(tasks)}
    missing = [t for t in ratings.tasks if t not in index]
    if missing:
        raise InputError(f"no truth for rated task {missing[0]!r}", where=path)
    return np.array([vals[index[t]] for t in ratings.tasks], dtype=float)
