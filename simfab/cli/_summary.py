"""The plain-text (non ``--json``) summary: compact rich tables.

A run's summary dict is shown as one table of its top-level figures (4 significant digits,
with units), one sub-table per nested result (dicts of figures, lists of rows) and a table of
the output files. Units come from the summary's own ``units`` dict, then the subcommand
module's ``UNITS``, then the key's suffix (``_m``, ``_m3``, ``_pa``, ``seconds``...).
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
               "penetration_tolerance": "m", "time_split": "s", "phase_split": "s"}
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


def _unit(key: str, units: dict) -> str:
    units = {**KNOWN_UNITS, **units}
    if key in units:
        return "" if units[key] in ("-", None) else str(units[key])
    k = key.lower()
    for suf, u in SUFFIX_UNITS:
        if k.endswith(suf):
            return u
    return ""


def _list_cell(v: list) -> str:
    if all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
        if len(v) <= 6:
            return ", ".join(fmt(x) for x in v)
        return f"{len(v)} values, {fmt(min(v))} … {fmt(max(v))}"
    if all(isinstance(x, str) for x in v) and any(len(x) > 30 for x in v):
        return "\n".join(v[:8]) + (f"\n… ({len(v)} in all)" if len(v) > 8 else "")
    if all(_scalar(x) for x in v):
        s = ", ".join(fmt(x) for x in v[:8])
        return s + (f", … ({len(v)} in all)" if len(v) > 8 else "")
    return f"{len(v)} entries"


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


def build_tables(result: dict, *, units: dict | None = None, title: str = "simfab") -> list:
    """rich renderables for a summary (see the module docstring)."""
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

    def walk(d: dict, name: str, depth: int, inherited: str = ""):
        t = figures_table(d, name)
        nested = []
        for k, v in d.items():
            if (k == "units" and isinstance(v, dict)) or (is_path(v) and k not in INPUT_KEYS):
                continue
            if _scalar(v):
                t.add_row(Text(str(k)), _cell(fmt(v)), Text(_unit(str(k), units) or inherited))
            elif isinstance(v, list) and (not v or all(_scalar(x) for x in v)):
                t.add_row(Text(str(k)), _cell(_list_cell(v)), Text(_unit(str(k), units) or inherited))
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
                    side_by_side(v, sub)
                else:  # many: one row each
                    rows_table([{"name": kk, **vv} for kk, vv in v.items()], sub)
                for kk, vv in v.items():  # and what does not fit a row
                    inner = {a: b for a, b in vv.items() if isinstance(b, (dict, list)) and not _row_cell(b)}
                    if inner:
                        walk(inner, f"{sub} › {kk}", depth + 2)
            elif isinstance(v, dict):
                walk(v, sub, depth + 1, _unit(str(k), units))  # e.g. time_split [s]: its entries in s
            elif isinstance(v, list) and all(isinstance(x, dict) for x in v):
                rows_table(v, sub)

    def side_by_side(d: dict, name: str):
        keys = []
        for vv in d.values():
            keys += [k for k, x in vv.items() if k not in keys and _row_cell(x) and not is_path(x)]
        t = Table(title=escape(name), box=box.SIMPLE_HEAD, title_justify="left", show_edge=False, pad_edge=False,
                  min_width=len(name) + 2)
        t.add_column("quantity", style="bold", no_wrap=True)
        for kk in d:
            t.add_column(escape(str(kk)), justify="right", overflow="fold")
        t.add_column("unit", no_wrap=True)
        for k in keys:
            cells = [d[kk].get(k) for kk in d]
            t.add_row(Text(str(k)), *(Text(fmt(c) if _scalar(c) else _list_cell(c)) for c in cells),
                      Text(_unit(str(k), units)))
        subs.append(t)

    def rows_table(rows: list, name: str):
        cols = []
        for r in rows:
            for k, x in r.items():
                if k not in cols and _row_cell(x) and not is_path(x):
                    cols.append(k)
        cols = cols[:MAX_COLS]
        t = Table(title=escape(name), box=box.SIMPLE_HEAD, title_justify="left", show_edge=False, pad_edge=False,
                  min_width=len(name) + 2)
        for i, c in enumerate(cols):
            u = _unit(str(c), units)
            t.add_column(escape(f"{c} [{u}]" if u else str(c)), justify="left" if i == 0 else "right", overflow="fold",
                         no_wrap=i == 0)
        for r in rows[:MAX_ROWS]:
            t.add_row(*(Text(fmt(r.get(c)) if _scalar(r.get(c)) else _list_cell(r.get(c))) for c in cols))
        if len(rows) > MAX_ROWS:
            t.add_row(*(["…"] * len(cols)))
            t.caption = f"{len(rows)} rows; all of them with --json"
        subs.append(t)

    walk(result, title, 0)
    paths: list = []
    _collect_paths(result, "", paths)
    if paths:
        t = Table(title="output files", box=box.SIMPLE_HEAD, title_justify="left", show_edge=False, pad_edge=False)
        t.add_column("output", style="bold")
        t.add_column("path", overflow="fold")
        for k, p in paths:
            t.add_row(Text(k), Text(p))
        subs.append(t)
    return subs


def render_text(result: dict, *, units: dict | None = None, title: str = "simfab",
                width: int | None = None) -> str:
    """The summary as plain text (no colour codes), as printed on a non-terminal stdout."""
    from rich.console import Console

    buf = io.StringIO()
    con = Console(file=buf, width=width or 110, color_system=None, highlight=False, soft_wrap=False)
    for t in build_tables(result, units=units, title=title):
        con.print(t)
    return buf.getvalue().rstrip() + "\n"


def print_summary(result: dict, *, units: dict | None = None, title: str = "simfab") -> None:
    """Print the summary on stdout (colours only on a terminal)."""
    if sys.stdout.isatty():
        from rich.console import Console

        con = Console(highlight=False)
        for t in build_tables(result, units=units, title=title):
            con.print(t)
    else:
        sys.stdout.write(render_text(result, units=units, title=title))
