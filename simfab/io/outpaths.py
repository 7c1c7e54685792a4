"""Where outputs may go: file names taken from inputs are sanitized, output folders are checked
before any computation, and every file written is confined to the folders the user named.

- :func:`safe_name` turns a name read from a file (scene, body, model, label) into one path
  component: no separators, no ``..``, no leading dot, nothing outside ``[A-Za-z0-9._-]``.
- :func:`require_nonempty` refuses an empty path (``--out "$UNSET"``), which would otherwise
  mean the working folder or fail late.
- :func:`check_out_dir` raises :class:`~simfab.errors.InputError` when a folder cannot receive
  outputs (an existing file, an unwritable or non-folder ancestor); it creates nothing.
- :func:`confine` makes every :func:`simfab.io.atomic.atomic_path` inside its block refuse a
  path that does not lie in one of the given folders (symbolic links resolved), so a name that
  slipped through unsanitized can never write outside ``--out``.
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import re
from pathlib import Path
from typing import Iterator

from simfab.errors import InputError

_ROOTS: contextvars.ContextVar[tuple[Path, ...] | None] = contextvars.ContextVar("simfab_output_roots", default=None)
_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")


def safe_name(name, *, default: str = "unnamed") -> str:
    """One file-name component from an arbitrary string: runs of characters other than letters,
    digits, ``.``, ``_`` and ``-`` become ``_``; leading dots and underscores are stripped (no
    hidden files, no ``..``); an empty result becomes ``default``. At most 100 characters."""
    s = _UNSAFE.sub("_", str(name)).lstrip("._")[:100]
    return s or default


def _resolved(p: str | os.PathLike) -> Path:
    return Path(os.path.abspath(os.path.realpath(p)))


def check_out_dir(out: str | os.PathLike, *, where: str = "--out") -> Path:
    """Check that ``out`` is (or can be created as) a writable folder; create nothing.

    Raises InputError naming ``where`` and the path when ``out`` is empty (an unset shell
    variable: ``--out "$DIR"``; it would silently mean the working folder), an existing file,
    when an ancestor is a file, or when the nearest existing ancestor is not writable.
    """
    require_nonempty(out, where)
    p = Path(os.path.abspath(out))
    if p.exists() and not p.is_dir():
        raise InputError(f"{out} exists and is not a folder", where=where)
    q = p
    while not q.exists():
        if q.parent == q:
            break
        q = q.parent
    if not q.is_dir():
        raise InputError(f"{out}: {q} is a file, not a folder", where=where)
    if not os.access(q, os.W_OK | os.X_OK):
        raise InputError(f"{out}: no permission to write in {q}", where=where)
    return p


def require_nonempty(path, where: str) -> None:
    """InputError naming ``where`` when ``path`` is empty or blank."""
    if not str(path).strip():
        raise InputError(f"is an empty path ({str(path)!r}: an unset shell variable?); name a folder or leave "
                         "the option out", where=where)


def make_out_dir(out: str | os.PathLike, *, where: str = "--out") -> Path:
    """:func:`check_out_dir`, then create the folder (InputError if that fails)."""
    p = check_out_dir(out, where=where)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InputError(f"{out}: cannot create the output folder: {e.strerror}", where=where) from None
    return p


def check_out_file(path: str | os.PathLike, *, where: str, suffixes: tuple[str, ...] = ()) -> Path:
    """Check an explicit output file: not empty, not an existing folder, allowed suffix, writable folder."""
    require_nonempty(path, where)
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{path} is a folder; give a file name", where=where)
    if suffixes and p.suffix.lower() not in suffixes:
        raise InputError(f"{path}: must end in {' or '.join(suffixes)}", where=where)
    check_out_dir(p.parent if str(p.parent) else ".", where=where)
    return p


@contextlib.contextmanager
def confine(roots) -> Iterator[None]:
    """Inside this block, :func:`check_inside` (called by every atomic write) refuses paths
    outside ``roots`` (folders; resolved once here)."""
    token = _ROOTS.set(tuple(_resolved(r) for r in roots))
    try:
        yield
    finally:
        _ROOTS.reset(token)


def check_inside(path: str | os.PathLike) -> None:
    """InputError when a confinement is active and ``path`` lies outside every allowed folder."""
    roots = _ROOTS.get()
    if roots is None:
        return
    p = _resolved(path)
    if any(p == r or r in p.parents for r in roots):
        return
    raise InputError(f"refusing to write outside the output folder ({', '.join(map(str, roots))}): a name taken "
                     "from an input file points elsewhere", where=str(path))
