"""Sphinx directive ``scene-keys``: the reference table of one scene-file table, generated from its
configuration dataclass so it cannot drift from the code.

Usage::

    .. scene-keys:: simfab.coupling.config.InsertionConfig
       :table: simulation

Every field of the dataclass is a row: key, type, default (from ``dataclasses.fields``) and its
description, read from (in order) the class docstring's ``Args:`` / ``Attributes:`` section (Google
style) or ``name : description`` entries, ``#:``
comments above the field, an attribute docstring below it, the ``key = value  # comment`` lines of
a TOML block in the docstring of the module named by ``:toml-doc:``, or :data:`EXTRA` below for
fields the code leaves undocumented. A field with no description anywhere, or an :data:`EXTRA` entry
naming a field that no longer exists, is a Sphinx warning (an error under ``-W``). ``:keys:`` maps
TOML keys to fields where they differ (``decay=radius_decay, age=radius_age``); ``:only:`` and
``:exclude:`` select fields.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import inspect
import math
import re
import textwrap

from docutils import nodes
from docutils.parsers.rst import directives
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective

LOG = logging.getLogger(__name__)

#: Descriptions of fields their dataclass leaves undocumented (class path -> field -> text).
EXTRA: dict[str, dict[str, str]] = {
    "simfab.deploy.pattern.PatternConfig": {
        "beam_width": "in-plane width of the beams [m]",
        "beam_thickness": "sheet thickness of the beams [m]",
        "insert_half_size": "r: distance from an insert's centre to where it clamps the beams (one size for all "
                            "inserts) [m]",
    },
    "simfab.deploy.network.DeployConfig": {
        "young": "[material] Young's modulus of the sheet [Pa]",
        "poisson": "[material] Poisson's ratio of the sheet [-]",
        "density": "[material] density of the sheet [kg/m^3]",
    },
    "simfab.deploy.mjcf_sim.SimConfig": {
        "timestep": "MuJoCo time step [s]",
        "damping_ratio": "zeta of every hinge [-]",
        "body_mass": "mass of each junction body [kg] (inserts get insert_mass)",
        "insert_mass": "mass of each insert body [kg]",
    },
}

_ENTRY = re.compile(r"^(\s*)([A-Za-z_][\w]*(?:\s*,\s*[A-Za-z_][\w]*)*)\s+:\s+(.*)$")
_TOML_LINE = re.compile(r"^\s*([A-Za-z_]\w*)\s*=\s*[^#]*#\s*(.*)$")


def docstring_entries(doc: str) -> dict[str, str]:
    """``name : description`` entries (with indented continuation lines) of a docstring."""
    out: dict[str, str] = {}
    lines = textwrap.dedent(doc or "").splitlines()
    cur: list | None = None
    base = 0
    for line in lines:
        m = _ENTRY.match(line)
        if m and (cur is None or len(m.group(1)) <= base):
            base = len(m.group(1))
            cur = [m.group(3).strip()]
            for name in re.split(r"\s*,\s*", m.group(2)):
                out[name] = cur
            continue
        if cur is not None and line.strip() and len(line) - len(line.lstrip()) > base:
            cur.append(line.strip())
        else:
            cur = None
    return {k: " ".join(v) for k, v in out.items()}


_SECTION = re.compile(r"^\s*(Args|Arguments|Attributes|Parameters):\s*$")
_ARG = re.compile(r"^\s*([A-Za-z_]\w*(?:\s*,\s*[A-Za-z_]\w*)*)\s*(?:\([^)]*\))?:\s+(.*)$")


def args_entries(doc: str) -> dict[str, str]:
    """``name: description`` entries (with indented continuation lines) of a Google-style ``Args:`` /
    ``Attributes:`` section; a blank line or a dedent ends the section."""
    out: dict[str, str] = {}
    inside, base, cur = False, None, None
    for line in inspect.cleandoc(doc or "").splitlines():
        if _SECTION.match(line):
            inside, base, cur = True, None, None
            continue
        if not inside:
            continue
        if not line.strip():
            inside = False
            continue
        ind = len(line) - len(line.lstrip())
        base = ind if base is None else base
        m = _ARG.match(line) if ind == base else None
        if m:
            cur = [m.group(2).strip()]
            for name in re.split(r"\s*,\s*", m.group(1)):
                out[name] = cur
        elif cur is not None and ind > base:
            cur.append(line.strip())
        else:
            inside = False
    return {k: " ".join(v) for k, v in out.items()}


def _until_semicolon(text: str) -> str:
    """``text`` up to the first ``;`` outside parentheses / brackets (the end of one prose entry)."""
    depth = 0
    for i, c in enumerate(text):
        if c in "([{":
            depth += 1
        elif c in ")]}":
            depth -= 1
        elif c == ";" and depth <= 0:
            return text[:i]
    return text


def prose_entries(doc: str, names) -> dict[str, str]:
    """Descriptions from prose docstrings: ``name [unit]: text; other: text`` and shared ones
    (``a, b [unit]: text`` / ``a and b: text``); ``[unit]`` is kept with the text."""
    flat = " ".join((doc or "").split())
    names = set(names)
    out: dict[str, str] = {}
    for name in names:
        for m in re.finditer(rf"(?<![\w.]){re.escape(name)}(?![\w])", flat):
            rest = flat[m.end():]
            unit = re.match(r"\s*(\[[^\]]*\])", rest)
            u = unit.group(1) + " " if unit else ""
            rest = rest[unit.end():] if unit else rest
            paren = re.match(r"\s*(\([^)]*\))", rest)
            extra = paren.group(1) + " " if paren else ""
            rest = rest[paren.end():] if paren else rest
            if rest.lstrip().startswith(":"):
                text = _until_semicolon(rest.lstrip()[1:]).strip()
                out[name] = (extra + text + (" " + u.strip() if u else "")).strip()
                break
            nxt = re.match(r"\s*(?:,|and)\s*([A-Za-z_]\w*)", rest)
            if nxt and nxt.group(1) in names:  # a list sharing one description: resolved below
                out.setdefault(name, "@" + nxt.group(1) + ("|" + u.strip() if u else ""))
                break
    for name, v in list(out.items()):  # follow shared descriptions
        seen = set()
        unit = ""
        while v.startswith("@") and name not in seen:
            seen.add(name)
            ref, _, uu = v[1:].partition("|")
            unit = unit or uu
            v = out.get(ref, "")
        out[name] = (v + (f" {unit}" if unit and unit not in v else "")).strip()
    return {k: v for k, v in out.items() if v}


def source_comments(cls) -> dict[str, str]:
    """``#:`` comments above a field and attribute docstrings below it, from the class source."""
    try:
        src = textwrap.dedent(inspect.getsource(cls))
    except (OSError, TypeError):
        return {}
    out: dict[str, str] = {}
    lines = src.splitlines()
    tree = ast.parse(src)
    body = tree.body[0].body
    for i, node in enumerate(body):
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            name = node.target.id
            j = node.lineno - 2
            com: list[str] = []
            while j >= 0 and lines[j].strip().startswith("#:"):
                com.insert(0, lines[j].strip()[2:].strip())
                j -= 1
            nxt = body[i + 1] if i + 1 < len(body) else None
            if isinstance(nxt, ast.Expr) and isinstance(getattr(nxt, "value", None), ast.Constant) \
                    and isinstance(nxt.value.value, str):
                com.append(" ".join(nxt.value.value.split()))
            if com:
                out[name] = " ".join(com)
    return out


def toml_comments(doc: str) -> dict[str, str]:
    """``key = value  # comment`` lines (continued by ``#`` lines indented under the comment)."""
    out: dict[str, str] = {}
    last = None
    for line in (doc or "").splitlines():
        m = _TOML_LINE.match(line)
        if m:
            last = m.group(1)
            out[last] = m.group(2).strip()
        elif last and line.strip().startswith("#") and "=" not in line:
            out[last] += " " + line.strip().lstrip("#").strip()
        else:
            last = None
    return out


def _plain(text: str) -> str:
    """Sphinx roles and inline literals of a docstring as plain text."""
    text = re.sub(r":[\w:]+:`~?([^`]+)`", r"\1", text)
    return text.replace("``", "")


def _fmt_default(f) -> str:
    if f.default is not dataclasses.MISSING:
        v = f.default
    elif f.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
        v = f.default_factory()  # type: ignore[misc]
    else:
        return "(required)"
    if isinstance(v, float) and math.isinf(v):
        return "inf"
    if v is None:
        return "derived (see description)"
    if dataclasses.is_dataclass(v):
        return getattr(v, "name", type(v).__name__)
    return repr(v)


def _fmt_type(f) -> str:
    t = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
    return t.replace("typing.", "")


def rows_for(path: str, *, toml_doc: str | None = None, keys: dict | None = None, only=None, exclude=()):
    """(rows [(key, type, default, description)], missing field names, stale EXTRA names)."""
    mod, _, name = path.rpartition(".")
    cls = getattr(importlib.import_module(mod), name)
    docs: dict[str, str] = {}
    if toml_doc:
        docs.update(toml_comments(importlib.import_module(toml_doc).__doc__ or ""))
    field_names = {f.name for f in dataclasses.fields(cls)}
    docs.update({k: v for k, v in prose_entries(cls.__doc__ or "", field_names).items() if not v.startswith("@")})
    docs.update(args_entries(cls.__doc__ or ""))
    docs.update(source_comments(cls))
    docs.update(docstring_entries(cls.__doc__ or ""))
    docs.update(EXTRA.get(path, {}))
    docs = {k: _plain(v) for k, v in docs.items()}
    stale = sorted(set(EXTRA.get(path, {})) - field_names)
    rename = {v: k for k, v in (keys or {}).items()}
    rows, missing = [], []
    for f in dataclasses.fields(cls):
        if (only and f.name not in only) or f.name in exclude:
            continue
        d = docs.get(f.name, "")
        if not d:
            missing.append(f.name)
        rows.append((rename.get(f.name, f.name), _fmt_type(f), _fmt_default(f), d))
    return rows, missing, stale


def _csv_list(text):
    return [s.strip() for s in (text or "").split(",") if s.strip()]


class SceneKeys(SphinxDirective):
    required_arguments = 1
    option_spec = {"table": directives.unchanged, "toml-doc": directives.unchanged, "keys": directives.unchanged,
                   "only": directives.unchanged, "exclude": directives.unchanged}

    def run(self):
        path = self.arguments[0]
        keys = dict(kv.split("=", 1) for kv in _csv_list(self.options.get("keys")))
        rows, missing, stale = rows_for(path, toml_doc=self.options.get("toml-doc"), keys=keys,
                                        only=set(_csv_list(self.options.get("only"))) or None,
                                        exclude=set(_csv_list(self.options.get("exclude"))))
        loc = self.get_location()
        for m in missing:
            LOG.warning(f"scene-keys: {path}.{m} has no description (document it in the class or in "
                        f"docs/_ext/scenekeys.py EXTRA)", location=loc)
        for s in stale:
            LOG.warning(f"scene-keys: EXTRA describes {path}.{s}, which is no field any more", location=loc)
        table, body = _table(["key", "type", "default", "meaning (units in brackets)"], (18, 14, 14, 54),
                             classes=["scene-keys"])
        for r in rows:
            body += self._row(list(r), code=(0, 2))
        if "table" in self.options:
            title = nodes.title(text=f"[{self.options['table']}]  ({path})")
            table.insert(0, title)
        return [table]

    @staticmethod
    def _row(cells, code=()):
        row = nodes.row()
        for i, c in enumerate(cells):
            entry = nodes.entry()
            para = nodes.paragraph()
            para += nodes.literal(text=c) if i in code else nodes.Text(c)
            entry += para
            row += entry
        return row



def _table(header, widths, classes=()):
    """A docutils table with a header row and column widths; returns (table, body) to append rows to."""
    table = nodes.table(classes=list(classes))
    tgroup = nodes.tgroup(cols=len(widths))
    table += tgroup
    for w in widths:
        tgroup += nodes.colspec(colwidth=w)
    head = nodes.thead()
    tgroup += head
    head += SceneKeys._row(list(header))
    body = nodes.tbody()
    tgroup += body
    return table, body

class DictTable(SphinxDirective):
    """``.. dict-table:: module.NAME``: a two-column table of a ``{name: description}`` dict in the code
    (e.g. :data:`simfab.coupling.outputs.CSV_COLUMN_DOCS`)."""

    required_arguments = 1
    option_spec = {"header": directives.unchanged}

    def run(self):
        mod, _, name = self.arguments[0].rpartition(".")
        data = getattr(importlib.import_module(mod), name)
        table, body = _table(_csv_list(self.options.get("header", "column, meaning")), (25, 75))
        for k, v in data.items():
            body += SceneKeys._row([str(k), _plain(str(v))], code=(0,))
        return [table]


class CouplingTables(SphinxDirective):
    """``.. coupling-tables::``: every table of a coupling scene's TOML and the keys it accepts, read
    from :data:`simfab.coupling.scene.SCENE_TABLES` (``[compliant]``: per generator and dimension)."""

    def run(self):
        from simfab.coupling import scene

        table, body = _table(["table", "keys accepted (any other is an error naming file, table and key)"], (30, 70))
        body += SceneKeys._row(["(top level)", ", ".join(sorted(scene.TOP_LEVEL_KEYS))], code=(0,))
        for name, allowed in scene.SCENE_TABLES.items():
            if callable(allowed):
                for dim, gens in ((2, scene.GENERATORS_2D), (3, scene.GENERATORS_3D)):
                    for g in gens:
                        keys = allowed({"generator": g}, dim)
                        body += SceneKeys._row([f"[{name}] generator = {g!r} (dim {dim})", ", ".join(sorted(keys))],
                                               code=(0,))
            elif allowed is None:
                body += SceneKeys._row([f"[{name}]", "checked where it is read (see its table below)"], code=(0,))
            else:
                body += SceneKeys._row([f"[{name}]", ", ".join(sorted(allowed))], code=(0,))
        return [table]


def setup(app):
    app.add_directive("coupling-tables", CouplingTables)
    app.add_directive("dict-table", DictTable)
    app.add_directive("scene-keys", SceneKeys)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
