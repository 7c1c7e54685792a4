"""The plain-text (non ``--json``) summary: compact rich tables.

A run's summary dict is shown as one table of its top-level figures (4 significant digits,
with units), one sub-table per nested result (dicts of figures, lists of rows) and a table of
the output files. Units come from the summary's own ``units`` dict, then the subcommand
module's ``UNITS``, then the key's suffix (``_m``, ``_m3``, ``_pa``, ``seconds``...); a units key
may be a dotted path's tail (``deviation.rms``) to name one figure among like-named ones. A
figure whose unit is ``fraction`` is shown in percent. Lists of names are shown whole; output
paths relative to the working folder when they lie in it, else absolute (either pastes).
``--quiet`` does not change it (it silences progress bars and log lines only).
"""

from __future__ import annotations

import io
import os
import sys

OUTPUT_SUFFIXES = (".png", ".usda", ".usdc", ".usd", ".xml", ".csv", ".json", ".stl", ".ply", ".obj", ".npz", ".txt")
SUFFIX_UNITS = (("_m3", "m³"), ("_m2", "m²"), ("_mm", "mm"), ("_m", "m"), ("_pa", "Pa"), ("_n", "N"), ("_j", "J"),
                ("_deg", "deg"), ("_s", "s"), ("seconds", "s"))
CONTAINER_KEYS = {"outputs", "pipelines", "scenes", "inserts"}  # left out of output-file labels
MAX_ROWS = 20  # rows of a list-of-rows sub-table before it is elided
MAX_SIDE_BY_SIDE = 4  # up to this many like results are shown as columns (quantities as rows)
#: units of keys common to several subcommands whose modules do not list them
KNOWN_UNITS = {"insert_half_size": "m", "gap_half_size": "m", "gaussian_curvature": "1/m²", "insert_rise": "m",
               "saddle_amplitude": "m", "angle_deficit": "rad", "gaussian_curvature_per_increment": "1/m²",
               "energy": "J", "max_bending_strain": "-",
               "critical_load": "N", "euler_load": "N", "volume": "m³", "yield_stress": "Pa",
               "penetration_tolerance": "m", "time_split": "s", "phase_split": "s",
               # deploy surface: deviations as fractions of the target's diameter (its README quotes percent)
               "deviation.rms": "fraction", "deviation.hausdorff": "fraction", "tuning.rms_before": "fraction",
               "tuning.hausdorff_before": "fraction", "relaxation.rms_rel": "fraction",
               "relaxation.max_rel": "fraction"}
#: the unit that marks a fraction: shown x100 in percent
FRACTION = "fraction"
MAX_COLS = 9
MAX_DEPTH = 3


def fmt(v) -> str:
    """A value for a person: floats to 4 significant digits, booleans as yes/no."""
    if isinstance(v, bool):
        return "yes" if v else "no"
    if v is None:
        return "–"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


INPUT_KEYS = {"source", "file", "scene", "ratings", "mesh", "skeleton", "truth"}  # paths read, not written


def is_path(v) -> bool:
    return isinstance(v, str) and v.lower().endswith(OUTPUT_SUFFIXES) and (os.sep in v or "/" in v)


def _scalar(v) -> bool:
    return v is None or isinstance(v, (bool, int, float, str))


def _unit(key: str, units: dict, path: tuple = ()) -> str:
    """The unit of ``key`` (reached through the keys ``path``): the longest dotted tail of
    ``path + (key,)`` that ``units`` names, else the key's suffix."""
    units = {**KNOWN_UNITS, **units}
    keys = (*path, key)
    for i in range(len(keys)):
        tail = ".".join(map(str, keys[i:]))
        if tail in units:
            return "" if units[tail] in ("-", None) else str(units[tail])
    k = key.lower()
    for suf, u in SUFFIX_UNITS:
        if k.endswith(suf):
            return u
    return ""


def _shown(v, unit: str):
    """(value, unit) as shown: a fraction in percent."""
    if unit == FRACTION:
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            return 100.0 * v, "%"
        if isinstance(v, list) and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
            return [100.0 * x for x in v], "%"
        return v, "%"
    return v, unit


def display_path(p: str) -> str:
    """An output path a user can paste: relative to the working folder when it lies inside it,
    else absolute."""
    a = os.path.abspath(p)
    cwd = os.getcwd()
    return os.path.relpath(a, cwd) if a == cwd or a.startswith(cwd.rstrip(os.sep) + os.sep) else a


def _list_cell(v: list) -> str:
    if all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
        if len(v) <= 6:
            return ", ".join(fmt(x) for x in v)
        return f"{len(v)} values, {fmt(min(v))} … {fmt(max(v))}"
    if all(isinstance(x, str) for x in v) and any(len(x) > 30 for x in v):
        return "\n".join(v)  # sentences (warnings): every one, one a line
    return ", ".join(fmt(x) for x in v)  # a listing (names): the whole list


def _row_cell(x) -> bool:
    """Fits a table cell: a scalar or a short list of scalars."""
    return _scalar(x) or (isinstance(x, list) and len(x) <= 6 and all(_scalar(y) for y in x))


def _same_keys(ds: list) -> bool:
    """Dicts that share most of their scalar keys (results of the same kind, e.g. per scene)."""
    keys = [{k for k, v in d.items() if _row_cell(v)} for d in ds]
    common = set.intersection(*keys) if keys else set()
    return bool(common) and all(len(common) >= 0.6 * len(k) for k in keys)


def _cell(text: str):
    """Numbers right-aligned; sentences (and anything with line breaks) left-aligned, folded."""
    from rich.text import Text

    return Text(text, justify="left" if (len(text) > 24 or "\n" in text) else "right")


def _collect_paths(d, prefix: str, paths: list) -> None:
    """Every output path in the summary, with its dotted key."""
    if isinstance(d, dict):
        for k, v in d.items():
            _collect_paths(v, f"{prefix}{k}" if not prefix else f"{prefix}.{k}", paths)
    elif isinstance(d, list):
        for i, v in enumerate(d):
            if isinstance(v, (dict, list)):
                _collect_paths(v, f"{prefix}[{i}]", paths)
    elif is_path(d) and prefix.rsplit(".", 1)[-1] not in INPUT_KEYS:
        short = ".".join(p for p in prefix.split(".") if p not in CONTAINER_KEYS) or prefix
        paths.append((short, d))


def build_tables(result: dict, *, units: dict | None = None, title: str = "simfab", width: int = 110) -> list:
    """rich renderables for a summary (see the module docstring) on a console ``width`` wide."""
    from rich import box
    from rich.markup import escape
    from rich.table import Table
    from rich.text import Text

    own = result.get("units")
    units = {**(units or {}), **(own if isinstance(own, dict) else {})}

    def figures_table(d: dict, name: str):
        t = Table(title=escape(name), box=box.SIMPLE_HEAD, title_justify="left", show_edge=False, pad_edge=False,
                  min_width=len(name) + 2)
        t.add_column("quantity", style="bold", no_wrap=True)
        t.add_column("value", justify="right", overflow="fold")
        t.add_column("unit", no_wrap=True)
        return t

    subs: list = []

    def walk(d: dict, name: str, depth: int, inherited: str = "", path: tuple = ()):
        t = figures_table(d, name)
        nested = []
        for k, v in d.items():
            if (k == "units" and isinstance(v, dict)) or (is_path(v) and k not in INPUT_KEYS):
                continue
            if _scalar(v) or (isinstance(v, list) and (not v or all(_scalar(x) for x in v))):
                shown, unit = _shown(v, _unit(str(k), units, path) or inherited)
                t.add_row(Text(str(k)), _cell(fmt(shown) if _scalar(shown) else _list_cell(shown)), Text(unit))
            elif isinstance(v, dict) and v and all(is_path(x) for x in v.values()):
                continue  # an 'outputs' dict: shown in the files table
            else:
                nested.append((k, v))
        if t.row_count:
            subs.append(t)
        for k, v in nested:
            sub = f"{name} › {k}"
            if depth + 1 > MAX_DEPTH:
                continue
            if isinstance(v, dict) and len(v) > 1 and all(isinstance(x, dict) for x in v.values()) and \
                    _same_keys(list(v.values())):
                if len(v) <= MAX_SIDE_BY_SIDE:  # a few named results: one column each
                    side_by_side(v, sub, (*path, k))
                else:  # many: one row each
                    rows_table([{"name": kk, **vv} for kk, vv in v.items()], sub, (*path, k))
                for kk, vv in v.items():  # and what does not fit a row
                    inner = {a: b for a, b in vv.items() if isinstance(b, (dict, list)) and not _row_cell(b)}
                    if inner:
                        walk(inner, f"{sub} › {kk}", depth + 2, path=(*path, k, kk))
            elif isinstance(v, dict):  # e.g. time_split [s]: its entries in s
                walk(v, sub, depth + 1, _unit(str(k), units, path), path=(*path, k))
            elif isinstance(v, list) and all(isinstance(x, dict) for x in v):
                rows_table(v, sub, (*path, k))

    def side_by_side(d: dict, name: str, path: tuple):
        keys = []
        for vv in d.values():
            keys += [k for k, x in vv.items() if k not in keys and _row_cell(x) and not is_path(x)]
        t = Table(title=escape(name), box=box.SIMPLE_HEAD, title_justify="left", show_edge=False, pad_edge=False,
                  min_width=len(name) + 2)
        t.add_column("quantity", style="bold", no_wrap=True)
        for kk in d:
            t.add_column(escape(str(kk)), justify="right", overflow="fold", min_width=len(str(kk)))
        t.add_column("unit", no_wrap=True)
        for k in keys:
            unit = _unit(str(k), units, path)
            cells = [_shown(d[kk].get(k), unit)[0] for kk in d]
            t.add_row(Text(str(k)), *(Text(fmt(c) if _scalar(c) else _list_cell(c)) for c in cells),
                      Text(_shown(None, unit)[1]))
        subs.append(t)

    def rows_table(rows: list, name: str, path: tuple):
        cols = []
        for r in rows:
            for k, x in r.items():
                if k not in cols and _row_cell(x) and not is_path(x):
                    cols.append(k)
        heads, used = [], 0
        for i, c in enumerate(cols[:MAX_COLS]):  # as many columns as fit with whole header words (values fold)
            u = _unit(str(c), units, path)
            head = f"{c} [{_shown(None, u)[1]}]" if u else str(c)
            need = max(len(w) for w in head.split())
            if i == 0:  # the first column does not wrap
                need = max([need, *(len(fmt(r.get(c))) for r in rows[:MAX_ROWS] if _scalar(r.get(c)))])
            if heads and used + need + 3 > width:
                break
            heads.append((c, u, head))
            used += need + 3  # the cell's padding and the gap to the next column
        cols, col_units = [c for c, _, _ in heads], [u for _, u, _ in heads]
        t = Table(title=escape(name), box=box.SIMPLE_HEAD, title_justify="left", show_edge=False, pad_edge=False,
                  min_width=len(name) + 2)
        for i, (_, _, head) in enumerate(heads):
            t.add_column(escape(head), justify="left" if i == 0 else "right", overflow="fold", no_wrap=i == 0,
                         min_width=max(len(w) for w in head.split()))
        for r in rows[:MAX_ROWS]:
            cells = [_shown(r.get(c), u)[0] for c, u in zip(cols, col_units)]
            t.add_row(*(Text(fmt(x) if _scalar(x) else _list_cell(x)) for x in cells))
        left = [f"{len(rows)} rows"] if len(rows) > MAX_ROWS else []
        if len(rows) > MAX_ROWS:
            t.add_row(*(["…"] * len(cols)))
        n_all = len({k for r in rows for k, x in r.items() if _row_cell(x) and not is_path(x)})
        if n_all > len(cols):
            left.append(f"{n_all - len(cols)} more columns")
        if left:
            t.caption = f"{'; '.join(left)}: all of them with --json"
        subs.append(t)

    walk(result, title, 0)
    paths: list = []
    _collect_paths(result, "", paths)
    if paths:
        t = Table(title="output files", box=box.SIMPLE_HEAD, title_justify="left", show_edge=False, pad_edge=False)
        t.add_column("output", style="bold")
        t.add_column("path", overflow="fold")
        for k, p in paths:
            t.add_row(Text(k), Text(display_path(p)))
        subs.append(t)
    return subs


def render_text(result: dict, *, units: dict | None = None, title: str = "simfab",
                width: int | None = None) -> str:
    """The summary as plain text (no colour codes), as printed on a non-terminal stdout."""
    from rich.console import Console

    buf = io.StringIO()
    con = Console(file=buf, width=width or 110, color_system=None, highlight=False, soft_wrap=False)
    for t in build_tables(result, units=units, title=title, width=width or 110):
        con.print(t)
    return buf.getvalue().rstrip() + "\n"


def print_summary(result: dict, *, units: dict | None = None, title: str = "simfab") -> None:
    """Print the summary on stdout (colours only on a terminal)."""
    if sys.stdout.isatty():
        from rich.console import Console

        con = Console(highlight=False)
        for t in build_tables(result, units=units, title=title, width=con.width):
            con.print(t)
    else:
        sys.stdout.write(render_text(result, units=units, title=title))
