"""Atomic file writes: write to a temporary name in the same folder, then rename.

An interrupted run never leaves a half-written output: either the old file (or none)
or the complete new one exists. Inside :func:`simfab.io.outpaths.published_on_success` (every CLI
run) each write is journaled, so a run that fails takes all its files back.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path
from typing import Iterator

from simfab.io.outpaths import check_inside, journal_mkdir, journal_replace, journal_temporary


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; rename it onto ``path`` on success.

    The temporary keeps the final suffix (``suffix`` overrides it) so that writers that
    dispatch on the extension (trimesh, USD, matplotlib) pick the right format.
    On an exception the temporary is removed and ``path`` is untouched.
    """

    path = Path(path)
    check_inside(path)  # inside simfab's CLI, outputs stay in the folders the user named
    journal_mkdir(path.parent)
    path.parent.mkdir(parents=True, exist_ok=True)
    suffix = path.suffix if suffix is None else suffix
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=".tmp" + suffix, dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    journal_temporary(tmp_path)
    try:
        yield tmp_path
        # mkstemp creates 0600 files; give the result the permissions a plain open() would.
        os.chmod(tmp_path, 0o666 & ~_umask())
        journal_replace(path)  # a failing run removes the file again (or restores the one it replaced)
        os.replace(tmp_path, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()
        raise


@contextlib.contextmanager
def atomic_paths(paths: dict) -> Iterator[dict]:
    """Like :func:`atomic_path` for a set of files that belong together (one run's outputs):
    yields ``{key: temporary path}``; the temporaries are renamed onto ``paths`` only when the
    whole block succeeds, and all removed otherwise, so a failure halfway leaves none of them."""
    with contextlib.ExitStack() as stack:
        tmps = {k: stack.enter_context(atomic_path(v)) for k, v in paths.items()}
        yield tmps
        # leaving the stack renames every temporary (in reverse order); an exception above
        # removes them all instead


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Atomically write ``text`` (UTF-8) to ``path``; return the path."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def write_json(path: str | os.PathLike, obj) -> Path:
    """Atomically write ``obj`` as indented JSON (numpy scalars/arrays converted)."""
    return write_text(path, json.dumps(to_jsonable(obj), indent=2) + "\n")


def write_csv(path: str | os.PathLike, header: list[str], rows) -> Path:
    """Atomically write a CSV with ``header`` and an iterable of row sequences."""
    import csv
    import io

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for r in rows:
        w.writerow([_fmt(v) for v in r])
    return write_text(path, buf.getvalue())


def save_figure(fig, path: str | os.PathLike, *, close: bool = False, **kw) -> Path:
    """Atomically save a matplotlib figure (format from the suffix of ``path``); ``close`` closes
    the figure afterwards, also when saving fails."""
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, **kw)
    finally:
        if close:
            import matplotlib.pyplot as plt

            plt.close(fig)
    return Path(path)


def _fmt(v):
    if isinstance(v, float):
        return repr(v)
    return v


def to_jsonable(obj):
    """Convert numpy types, Paths, dataclasses and tuples into plain JSON values.

    Non-finite floats become ``None`` so that the JSON stays standard (no NaN leaves simfab).
    """
    import dataclasses
    import math

    import numpy as np

    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        obj = dataclasses.asdict(obj)
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        f = float(obj)
        return f if math.isfinite(f) else None
    if isinstance(obj, os.PathLike):
        return str(obj)
    return obj
