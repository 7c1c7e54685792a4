"""Companion files a scene refers to (arrays, tables, meshes): read behind one loader each, every
failure to read or parse becoming an :class:`~simfab.errors.InputError` that names the file
(exit 2), never a library's own exception (``BadZipFile``, ``EOFError``, ``UnicodeDecodeError``,
a pickle error, ...).

- :func:`reading` the context every companion file is read in (missing file, any read error);
- :func:`read_npz` named arrays of an ``.npz`` (no pickles);
- :func:`read_csv_numbers` a table of numbers, a fixed number of columns per row, an optional
  header row (``x,y``, as spreadsheets and most tools write it), ``#`` comments and blank lines;
- meshes (STL/OBJ/PLY/OFF/GLB): :func:`simfab.io.mesh.read_mesh`, which reads in :func:`reading`.
"""

from __future__ import annotations

import contextlib
import math
import os
from pathlib import Path
from typing import Iterator

import numpy as np

from simfab.errors import InputError


@contextlib.contextmanager
def reading(path: str | os.PathLike, what: str) -> Iterator[Path]:
    """Read ``path`` (a ``what``, e.g. "mesh file") inside this block: InputError naming the file
    when it is missing or not a file, and for any exception the block raises while reading or
    parsing it (an InputError raised inside passes unchanged)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{what} not found" + (" (it is a folder)" if path.is_dir() else ""), where=str(path))
    try:
        yield path
    except InputError:
        raise
    except Exception as e:  # any library's failure on a corrupt or foreign file is bad input
        detail = " ".join(str(e).split())
        raise InputError(f"cannot read the {what}: {type(e).__name__}{': ' + detail if detail else ''}",
                         where=str(path)) from None


def read_npz(path: str | os.PathLike, arrays: tuple[str, ...], *, what: str = "array file (.npz)") -> dict:
    """The named ``arrays`` of an ``.npz`` file as a dict of ndarrays (pickled objects refused)."""
    with reading(path, what) as p:
        z = np.load(p, allow_pickle=False)
        if not isinstance(z, np.lib.npyio.NpzFile):
            raise InputError(f"a single array, not an .npz archive of the arrays {', '.join(arrays)}", where=str(p))
        with z:
            missing = [a for a in arrays if a not in z.files]
            if missing:
                raise InputError(f"no array {missing[0]!r} in the {what} (it has {', '.join(z.files) or 'none'}; "
                                 f"need {', '.join(arrays)})", where=str(p))
            return {a: np.asarray(z[a]) for a in arrays}


def read_csv_numbers(path: str | os.PathLike, columns: int | tuple, *, what: str = "CSV file",
                     min_rows: int = 1) -> np.ndarray:
    """(k, c) float array of a comma-separated table of finite numbers.

    The first data line may be a header (every cell not a number, e.g. ``x,y``); blank lines
    and lines starting with ``#`` are skipped. ``columns``: the count c of every row, or a tuple of
    the counts allowed (the first row's count, or the header's, is then every row's). Any other line
    that is not c finite numbers is an InputError naming the file and the line."""
    with reading(path, what) as p:
        text = p.read_text(encoding="utf-8-sig")  # a spreadsheet's byte-order mark is not a character
    where = str(path)
    rows: list[list[float]] = []
    first = True
    for lineno, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        cells = [c.strip() for c in s.split(",")]
        vals = [_number(c) for c in cells]
        if first and isinstance(columns, tuple) and len(cells) in columns:
            columns = len(cells)  # (the header's or the first row's count: every row's)
        if first and all(v is None for v in vals):  # a header row
            first = False
            continue
        first = False
        if isinstance(columns, tuple) or len(cells) != columns or any(v is None for v in vals):
            want = columns if isinstance(columns, int) else " or ".join(map(str, columns))
            raise InputError(f"line {lineno}: expected {want} comma-separated numbers, got {s[:60]!r}", where=where)
        if not all(math.isfinite(v) for v in vals):
            raise InputError(f"line {lineno}: {s[:60]!r} is not finite", where=where)
        rows.append(vals)
    if isinstance(columns, tuple):  # (no data line)
        columns = columns[0]
    if len(rows) < min_rows:
        raise InputError(f"needs at least {min_rows} row(s) of {columns} numbers, found {len(rows)}", where=where)
    return np.array(rows, dtype=np.float64).reshape(-1, columns)


def _number(cell: str) -> float | None:
    try:
        return float(cell)
    except ValueError:
        return None
