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
- :func:`published_on_success` makes one run's outputs all-or-nothing: every file an atomic write
  creates or replaces inside the block is journaled (a replaced file kept as a hidden hard link
  next to it); when the block raises (also ``KeyboardInterrupt``) the new files are removed, the
  replaced ones restored and the folders the run created removed, so ``--out`` is as before.
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import Iterator

from simfab.errors import InputError

_ROOTS: contextvars.ContextVar[tuple[Path, ...] | None] = contextvars.ContextVar("simfab_output_roots", default=None)
_JOURNAL: contextvars.ContextVar[_Journal | None] = contextvars.ContextVar("simfab_output_journal", default=None)
_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")


def safe_name(name, *, default: str = "unnamed") -> str:
    """One file-name component from an arbitrary string: runs of characters other than letters,
    digits, ``.``, ``_`` and ``-`` become ``_``; leading dots and underscores are stripped (no
    hidden files, no ``..``); an empty result becomes ``default``. At most 100 characters."""
    s = _UNSAFE.sub("_", str(name)).lstrip("._")[:100]
    return s or default


def name_from_stem(path: str | os.PathLike) -> str:
    """A scene or body name from a file's stem: characters other than letters, digits, ``_`` and ``-``
    become ``_`` (``clip_v1.2.stl`` -> ``clip_v1_2``)."""
    return "".join(c if c.isalnum() or c in "_-" else "_" for c in Path(path).stem)


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
    _probe(q, out, where)
    return p


def _probe(folder: Path, out, where: str) -> None:
    """InputError unless a folder can be created (and is removed again) in ``folder``: ``os.access``
    answers yes to root everywhere, also where nothing can be created (``/proc``, a read-only
    mount), and the run would fail only when it writes its first output."""
    try:
        tmp = tempfile.mkdtemp(prefix=".simfab-probe-", dir=folder)
    except OSError as e:
        raise InputError(f"{out}: cannot create anything in {folder}: {e.strerror}", where=where) from None
    os.rmdir(tmp)


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


class _Journal:
    """What one run wrote: files it created or replaced (with the hidden hard link keeping a replaced
    file's old content) and folders it created."""

    def __init__(self, roots) -> None:
        self.roots = [Path(os.path.abspath(r)) for r in roots]
        self.new_roots = [r for r in self.roots if not r.exists()]
        self.root_ancestors = {r: _missing_ancestors(r) for r in self.new_roots}
        self.files: dict[Path, Path | None] = {}  # written file -> backup of its previous content
        self.dirs: list[Path] = []  # folders created by atomic writes, outermost first

    def before_mkdir(self, folder: Path) -> None:
        self.dirs += [d for d in _missing_ancestors(folder) if d not in self.dirs]

    def made(self, path: Path) -> None:
        """``path`` was created by the run (an atomic write's temporary, which a nested atomic write
        may replace): removed on rollback if still there, never backed up."""
        self.files.setdefault(Path(os.path.abspath(path)), None)

    def before_replace(self, path: Path) -> None:
        path = Path(os.path.abspath(path))
        if path in self.files:
            return
        backup = None
        if path.is_file():
            backup = path.with_name(f".{path.name}.simfab-undo-{os.getpid()}")
            with contextlib.suppress(FileNotFoundError):
                backup.unlink()
            try:
                os.link(path, backup)
            except OSError:  # no hard links here (some network or FAT folders): a copy
                shutil.copy2(path, backup)
        self.files[path] = backup

    def commit(self) -> None:
        for backup in self.files.values():
            if backup is not None:
                with contextlib.suppress(FileNotFoundError):
                    backup.unlink()

    def rollback(self) -> None:
        for path, backup in self.files.items():
            with contextlib.suppress(OSError):
                if backup is None:
                    path.unlink()
                else:
                    os.replace(backup, path)
        for root in self.new_roots:  # a folder the run created: its (now empty) sub-folders and itself
            for folder, _, _ in sorted(os.walk(root), key=lambda w: -len(w[0])):
                with contextlib.suppress(OSError):
                    os.rmdir(folder)  # only when empty: never a file someone else put there
        for d in [*reversed(self.dirs), *(a for r in self.new_roots for a in reversed(self.root_ancestors[r]))]:
            with contextlib.suppress(OSError):
                d.rmdir()  # only when empty


def _missing_ancestors(folder: Path) -> list[Path]:
    """``folder`` and its ancestors that do not exist yet, outermost first."""
    out = []
    q = Path(os.path.abspath(folder))
    while not q.exists() and q.parent != q:
        out.append(q)
        q = q.parent
    return out[::-1]


@contextlib.contextmanager
def published_on_success(roots, *, keep_on: tuple = ()) -> Iterator[None]:
    """All-or-nothing outputs for one run writing into the folders ``roots`` (module docstring):
    when the block raises, every file an atomic write created or replaced inside it is removed or
    restored, and the folders created (``roots`` themselves when they did not exist) are removed;
    files the run did not write are never touched.

    Args:
        roots: the folders the run writes into.
        keep_on: exception types after which the outputs stay (a run that completed and reports a
            failed check, whose outputs are the evidence).
    """
    journal = _Journal(roots)
    token = _JOURNAL.set(journal)
    try:
        yield
    except keep_on:
        journal.commit()
        raise
    except BaseException:
        journal.rollback()
        raise
    else:
        journal.commit()
    finally:
        _JOURNAL.reset(token)


def journal_mkdir(folder: Path) -> None:
    """Record the folders ``mkdir(parents=True)`` of ``folder`` is about to create (no-op outside
    :func:`published_on_success`)."""
    j = _JOURNAL.get()
    if j is not None:
        j.before_mkdir(folder)


def journal_temporary(path: Path) -> None:
    """Record a temporary file the run created (no-op outside :func:`published_on_success`)."""
    j = _JOURNAL.get()
    if j is not None:
        j.made(path)


def journal_replace(path: Path) -> None:
    """Record that ``path`` is about to be created or replaced (no-op outside
    :func:`published_on_success`)."""
    j = _JOURNAL.get()
    if j is not None:
        j.before_replace(path)
