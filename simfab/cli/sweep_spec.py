"""Sweep specification (``SPEC.toml``): which command, which parameters, which figures.

A spec names a base command (any ``simfab`` subcommand line), optionally a base scene whose
parameters it varies, the swept parameters with their values, and the figures to collect from each
run's JSON summary (:class:`SweepConfig`; tables read by :func:`simfab.io.tables.load_table`)::

    [sweep]
    name = "cclamp2d_chart"                     # table / plot file stem (default: the spec's stem)
    command = ["couple", "simulate", "{scene}", "--steps", "20"]
    scene = "coupling/cclamp2d.toml"            # relative to the spec, else to the bundled scenes/
    combine = "product"                         # "product" (grid) | "zip" (equal-length lists)
    seed = 0                                    # --seed of every run, and of random parameters
    [set]                                       # fixed for every run (same addresses as below)
    "material.poisson_ratio" = 0.36
    [parameters.youngs_modulus]                 # a column of the table
    set = "material.youngs_modulus"             # where the value goes (default: the name)
    values = [1.0e9, 2.0e9, 3.5e9]              # or range = [lo, hi] + num (+ log), or random = ...
    [collect]                                   # column = dotted path in the run's summary
    F_in = { path = "F_in", unit = "N" }
    [derived]                                   # columns computed from others (pandas.eval)
    [plot]                                      # optional: x, y, figures

Addresses (``set``): ``"--flag"`` a command-line option; ``"table.key"`` a key of the scene's TOML;
``"tag:name.attr[i,j]"`` an attribute of the MJCF element ``<tag name="name">``. The full format:
docs/methods.md, "simfab.cli.sweep_spec".
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import re
import tomllib
import zlib
from pathlib import Path

import numpy as np

from simfab.errors import InputError
from simfab.io.tables import FieldError, check_keys, load_table
from simfab.sweep.runs import META_COLUMNS  # columns every table has besides parameters and figures

_IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_MJCF = re.compile(r"^(?P<tag>[A-Za-z_]+):(?P<name>[^.\[\]]+)(?:\.(?P<attr>[A-Za-z_]+))?(?:\[(?P<idx>[0-9, ]+)\])?$")


@dataclasses.dataclass(frozen=True, kw_only=True)
class Address:
    """Where a swept or fixed value goes.

    Args:
        text: the address as written in the spec.
        kind: "flag" (``--flag``), "toml" (a key path of the scene's TOML) or "mjcf" (an MJCF attribute).
        path: the TOML key path.
        tag: the MJCF element's tag.
        name: the MJCF element's name.
        attr: the MJCF attribute.
        index: the components of a vector attribute to set (empty: the whole attribute).
    """

    text: str
    kind: str
    path: tuple = ()
    tag: str = ""
    name: str = ""
    attr: str = ""
    index: tuple[int, ...] = ()

    @classmethod
    def parse(cls, text: str, where: str) -> "Address":
        """Parse an address.

        Args:
            text: ``"--flag"``, ``"table.key"`` or ``"tag:name.attr[i,j]"``.
            where: the file and table, for messages.

        Returns:
            The address; InputError naming ``where`` when it is malformed.
        """
        text = str(text).strip()
        if text.startswith("--"):
            return cls(text=text, kind="flag")
        if ":" in text:
            m = _MJCF.match(text)
            if not m:
                raise InputError(f"MJCF address {text!r} is not 'tag:name.attr[i,j]'", where=where)
            tag, attr = m["tag"], m["attr"] or ("data" if m["tag"] == "numeric" else "")
            if not attr:
                raise InputError(f"MJCF address {text!r} names no attribute ('{tag}:{m['name']}.ATTR')", where=where)
            idx = tuple(int(i) for i in m["idx"].split(",")) if m["idx"] else ()
            return cls(text=text, kind="mjcf", tag=tag, name=m["name"], attr=attr, index=idx)
        parts = tuple(p for p in text.split("."))
        if not text or any(not p for p in parts):
            raise InputError(f"TOML key path {text!r} is empty or has an empty part", where=where)
        return cls(text=text, kind="toml", path=parts)


@dataclasses.dataclass(frozen=True, kw_only=True)
class Parameter:
    """One swept parameter.

    Args:
        name: its column.
        address: where its value goes.
        values: its (n,) values.
        unit: its unit.
        log: plot it on a log axis.
    """

    name: str
    address: Address
    values: tuple
    unit: str = ""
    log: bool = False


@dataclasses.dataclass(frozen=True, kw_only=True)
class Figure:
    """A collected figure.

    Args:
        name: its column.
        path: the dotted path of its value in the run's summary.
        unit: its unit.
    """

    name: str
    path: str
    unit: str = ""


@dataclasses.dataclass(frozen=True, kw_only=True)
class PlotConfig:
    """The ``[plot]`` table.

    Args:
        x, y: the columns on the plot's axes (None: the swept parameters).
        figures: the columns plotted (None: every collected and derived figure).
    """

    x: str | None = None
    y: str | None = None
    figures: tuple[str, ...] | None = None


@dataclasses.dataclass(frozen=True, kw_only=True)
class SweepTableConfig:
    """The ``[sweep]`` table (see the module docstring).

    Args:
        command: the simfab command line each run executes (a list, or a string split like a shell).
        name: the table's and plots' file stem (None: the spec's stem).
        scene: the base scene, relative to the spec or to the bundled scenes (None: none).
        combine: "product" (grid) or "zip" (equal-length lists).
        seed: ``--seed`` of every run and of random parameters.
        keep_outputs: keep each run's folder.
    """

    command: str | tuple[str | int | float, ...] | None = None
    name: str | None = None
    scene: str | None = None
    combine: str = "product"
    seed: int = 0
    keep_outputs: bool = True

    def __post_init__(self):
        cmd = self.command
        if not (isinstance(cmd, (str, tuple)) and cmd
                and (isinstance(cmd, str) or all(isinstance(c, (str, int, float)) for c in cmd))):
            raise FieldError("command must be a simfab command line, e.g. ['couple', 'simulate', '{scene}']",
                             key="command", where="[sweep] command")
        if self.combine not in ("product", "zip"):
            raise FieldError(f"combine must be 'product' or 'zip', got {self.combine!r}", key="combine",
                             where="[sweep]")
        if not isinstance(self.seed, int) or isinstance(self.seed, bool):
            raise FieldError(f"seed must be an integer, got {self.seed!r}", key="seed", where="[sweep]")


@dataclasses.dataclass(frozen=True, kw_only=True)
class SweepConfig:
    """A parsed spec (see the module docstring).

    Args:
        name: the table's and plots' file stem.
        source: the spec file.
        command: the command line of every run.
        scene: the resolved base scene file, or None.
        combine: "product" or "zip".
        seed: the runs' seed.
        keep_outputs: keep each run's folder.
        fixed: (address, value) applied to every run.
        parameters: the swept parameters.
        figures: the collected figures.
        derived: (column, expression) computed from others.
        plot: the ``[plot]`` table.
    """

    name: str
    source: Path
    command: tuple[str, ...]
    scene: Path | None
    combine: str
    seed: int
    keep_outputs: bool
    fixed: tuple[tuple[Address, object], ...]
    parameters: tuple[Parameter, ...]
    figures: tuple[Figure, ...]
    derived: tuple[tuple[str, str], ...]
    plot: PlotConfig

    @property
    def swept(self) -> tuple[Parameter, ...]:
        """Parameters that take more than one value (the plot axes)."""
        return tuple(p for p in self.parameters if len(set(map(_canon, p.values))) > 1)

    def points(self) -> list[dict]:
        """The runs' parameter values, in the order the spec expands them.

        Returns:
            [{parameter name: value}] (one empty dict without parameters).
        """
        names = [p.name for p in self.parameters]
        if not names:
            return [{}]
        if self.combine == "zip":
            return [dict(zip(names, vals)) for vals in zip(*(p.values for p in self.parameters))]
        return [dict(zip(names, vals)) for vals in itertools.product(*(p.values for p in self.parameters))]

    def run_key(self, point: dict, version: str) -> str:
        """Hash of everything that determines a run.

        Args:
            point: the run's parameter values.
            version: simfab's version.

        Returns:
            16 hex digits over the parameter values, the fixed values, the command, the base scene's
            content and ``version``.
        """
        scene = ""
        if self.scene is not None:
            scene = "".join(hashlib.sha256(f.read_bytes()).hexdigest() for f in scene_files(self.scene))
        blob = json.dumps({
            "command": list(self.command), "scene": scene, "version": version,
            "fixed": [[a.text, _canon(v)] for a, v in self.fixed],
            "params": {p.name: [p.address.text, _canon(point[p.name])] for p in self.parameters},
        }, sort_keys=True)
        return hashlib.sha256(blob.encode()).hexdigest()[:16]


def _canon(v):
    """A JSON-stable form of a value (floats by repr, so 0.1 keys the same on every machine)."""
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, tuple)):
        return [_canon(x) for x in v]
    return v


def scene_files(scene: Path) -> list[Path]:
    """The base scene and its companion (a coupling scene is NAME.xml + NAME.toml).

    Args:
        scene: the base scene file.

    Returns:
        The scene file, then its companion when it exists.
    """
    other = scene.with_suffix(".xml" if scene.suffix == ".toml" else ".toml")
    return [scene] + ([other] if other.is_file() else [])


def _plain(v):
    """numpy scalars -> Python scalars (values must pickle and hash the same everywhere)."""
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, list):
        return [_plain(x) for x in v]
    return v


def _values(name: str, d: dict, seed: int, where: str) -> tuple[tuple, bool]:
    """(values, log) of one parameter table."""
    kinds = [k for k in ("values", "range", "random") if k in d]
    if len(kinds) != 1 and not (kinds == ["values", "random"] and d.get("random") == "choice"):
        raise InputError("give exactly one of values = [...], range = [lo, hi] with num, or random = ...", where=where)
    log = bool(d.get("log", False))
    if "random" in d:
        kind = d["random"]
        n = d.get("samples")
        if not isinstance(n, int) or n < 1:
            raise InputError(f"random parameters need samples = N >= 1, got {n!r}", where=where)
        rng = np.random.default_rng([int(seed), zlib.crc32(name.encode())])
        if kind == "choice":
            vals = d.get("values")
            if not isinstance(vals, list) or not vals:
                raise InputError("random = 'choice' needs values = [...]", where=where)
            return tuple(_plain(vals[i]) for i in rng.integers(len(vals), size=n)), log
        lo, hi = d.get("low"), d.get("high")
        if not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in (lo, hi)) or not lo < hi:
            raise InputError(f"random = {kind!r} needs numbers low < high, got {lo!r}, {hi!r}", where=where)
        if kind == "uniform":
            return tuple(float(x) for x in rng.uniform(lo, hi, n)), log
        if kind == "loguniform":
            if lo <= 0:
                raise InputError(f"loguniform needs low > 0, got {lo!r}", where=where)
            return tuple(float(x) for x in np.exp(rng.uniform(np.log(lo), np.log(hi), n))), True
        if kind == "integers":
            return tuple(int(x) for x in rng.integers(int(lo), int(hi), n, endpoint=True)), log
        raise InputError(f"random = {kind!r}; use 'uniform', 'loguniform', 'integers' or 'choice'", where=where)
    if "range" in d:
        r, n = d["range"], d.get("num")
        numbers = isinstance(r, list) and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in r)
        if not (numbers and len(r) == 2):
            raise InputError(f"range must be [lo, hi] (numbers), got {r!r}", where=where)
        if not isinstance(n, int) or n < 2:
            raise InputError(f"range needs num = N >= 2 points, got {n!r}", where=where)
        if log:
            if min(r) <= 0:
                raise InputError(f"a log range needs positive ends, got {r!r}", where=where)
            return tuple(float(x) for x in np.geomspace(r[0], r[1], n)), log
        return tuple(float(x) for x in np.linspace(r[0], r[1], n)), log
    vals = d["values"]
    if not isinstance(vals, list) or not vals:
        raise InputError(f"values must be a non-empty list, got {vals!r}", where=where)
    return tuple(_plain(v) for v in vals), log


def _ident(name: str, where: str) -> str:
    if not _IDENT.match(name) or name in META_COLUMNS:
        raise InputError(f"column name {name!r} must be an identifier (letters, digits, _) and not one of "
                         f"{', '.join(META_COLUMNS)}", where=where)
    return name


def resolve_scene(text: str, base: Path) -> Path:
    """A scene path from a spec.

    Args:
        text: the ``[sweep] scene`` value.
        base: the spec's folder.

    Returns:
        The scene file, relative to the spec's folder, else to the bundled scenes/ (InputError when neither).
    """
    from simfab._bundled import scenes_dir

    for p in (base / text, scenes_dir(text)):
        if p.is_file():
            return p.resolve()
    raise InputError(f"scene {text!r} found neither beside the spec nor among the bundled scenes",
                     where="[sweep] scene")


def find_spec(text: str) -> Path:
    """The spec file.

    Args:
        text: SPEC.toml, or the name of a bundled spec in scenes/sweeps (``cclamp2d_chart``).

    Returns:
        Its path (InputError when it is neither).
    """
    from simfab._bundled import scenes_dir

    p = Path(text)
    if p.is_file():
        return p
    bundled = scenes_dir("sweeps", p.name if p.suffix == ".toml" else p.name + ".toml")
    if p.parent == Path(".") and bundled.is_file():
        return bundled
    raise InputError("sweep spec not found (a TOML file, or a bundled spec: simfab sweep --list)", where=text)


_TOP = {"sweep", "set", "parameters", "collect", "derived", "plot"}
_PARAM = {"set", "values", "range", "num", "log", "random", "low", "high", "samples", "unit"}


def load_spec(path) -> SweepConfig:
    """Parse and check a sweep spec file.

    Args:
        path: SPEC.toml, or the name of a bundled spec (scenes/sweeps).

    Returns:
        The spec; InputError naming the file, the table and the key when it is refused.
    """
    path = find_spec(str(path))
    f = str(path)
    try:
        d = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"not valid TOML: {e}", where=f) from None
    except OSError as e:
        raise InputError(f"cannot read: {e.strerror}", where=f) from None
    for k in d:
        if k not in _TOP:
            raise InputError(f"unknown table [{k}] (have: {', '.join(sorted(_TOP))})", where=f)
    if not isinstance(d.get("sweep"), dict):
        raise InputError("missing the [sweep] table (command = [...])", where=f)
    sw = load_table(SweepTableConfig, d["sweep"], table_name="sweep", file=f)
    cmd = sw.command
    if isinstance(cmd, str):
        import shlex

        cmd = shlex.split(cmd)
        if not cmd:
            raise InputError("command must be a simfab command line, e.g. ['couple', 'simulate', '{scene}']",
                             where=f"{f} [sweep] command")
    cmd = tuple(str(c) for c in cmd)
    from simfab.cli import SUBCOMMANDS

    if cmd[0] not in SUBCOMMANDS or cmd[0] == "sweep":
        have = ", ".join(s for s in SUBCOMMANDS if s != "sweep")
        raise InputError(f"{cmd[0]!r} is not a subcommand to sweep (have: {have})", where=f"{f} [sweep] command")
    if any(c in ("--out", "--json") for c in cmd):
        raise InputError("the sweep sets --out (one folder per run) and reads the summary itself; drop --out/--json",
                         where=f"{f} [sweep] command")
    scene = resolve_scene(sw.scene, path.parent) if sw.scene is not None else None
    if scene is not None and scene.suffix not in (".toml", ".xml"):
        raise InputError(f"the base scene must be a .toml or .xml file, got {scene.name}", where=f"{f} [sweep] scene")
    if scene is not None and "{scene}" not in cmd:
        raise InputError("the command must place the scene: put '{scene}' where the scene path goes",
                         where=f"{f} [sweep] command")
    combine, seed = sw.combine, sw.seed

    def address(text, where):
        a = Address.parse(text, where)
        if a.kind == "toml" and (scene is None or not any(s.suffix == ".toml" for s in scene_files(scene))):
            raise InputError(f"{text!r} is a scene TOML key but the spec has no TOML scene "
                             "(a command-line option starts with --)", where=where)
        if a.kind == "mjcf" and (scene is None or not any(s.suffix == ".xml" for s in scene_files(scene))):
            raise InputError(f"{text!r} is an MJCF address but the spec has no MJCF scene", where=where)
        if a.kind == "flag" and a.text in ("--out", "--json", "--quiet"):
            raise InputError(f"{a.text} is set by the sweep", where=where)
        return a

    fixed = tuple((address(k, f"{f} [set] {k}"), _plain(v)) for k, v in (d.get("set") or {}).items())
    params = []
    for name, pd in (d.get("parameters") or {}).items():
        where = f"{f} [parameters.{name}]"
        _ident(name, where)
        if not isinstance(pd, dict):
            pd = {"values": pd}
        check_keys(pd, _PARAM, table_name=f"parameters.{name}", file=f)
        vals, log = _values(name, pd, seed, where)
        params.append(Parameter(name=name, address=address(pd.get("set", name), where), values=vals,
                                unit=str(pd.get("unit", "")), log=log))
    if combine == "zip" and len({len(p.values) for p in params}) > 1:
        raise InputError(f"combine = 'zip' needs equally many values per parameter, "
                         f"got {[len(p.values) for p in params]}", where=f"{f} [parameters]")
    texts = [p.address.text for p in params] + [a.text for a, _ in fixed]
    dup = {t for t in texts if texts.count(t) > 1}
    if dup:
        raise InputError(f"{sorted(dup)[0]!r} is set twice", where=f"{f} [parameters]")
    figures = []
    for name, v in (d.get("collect") or {}).items():
        where = f"{f} [collect] {name}"
        _ident(name, where)
        v = {"path": v} if isinstance(v, str) else v
        if not isinstance(v, dict) or not isinstance(v.get("path"), str):
            raise InputError("give a dotted path into the run's summary, or {path = ..., unit = ...}", where=where)
        figures.append(Figure(name=name, path=v["path"], unit=str(v.get("unit", ""))))
    derived = []
    for name, expr in (d.get("derived") or {}).items():
        _ident(name, f"{f} [derived] {name}")
        if not isinstance(expr, str):
            raise InputError(f"must be an expression string, got {expr!r}", where=f"{f} [derived] {name}")
        derived.append((name, expr))
    cols = [p.name for p in params] + [g.name for g in figures] + [n for n, _ in derived]
    dup = {c for c in cols if cols.count(c) > 1}
    if dup:
        raise InputError(f"column {sorted(dup)[0]!r} is defined twice", where=f)
    plot = load_table(PlotConfig, d.get("plot"), table_name="plot", file=f)
    for k in ("x", "y"):
        if getattr(plot, k) is not None and getattr(plot, k) not in cols:
            raise InputError(f"{k} = {getattr(plot, k)!r} is not a parameter or figure column", where=f"{f} [plot]")
    if plot.figures is not None:
        bad = [c for c in plot.figures if c not in cols]
        if bad:
            raise InputError(f"figure {bad[0]!r} is not a collected or derived column", where=f"{f} [plot]")
    return SweepConfig(
        name=sw.name if sw.name is not None else path.stem, source=path.resolve(), command=cmd, scene=scene,
        combine=combine, seed=seed, keep_outputs=sw.keep_outputs, fixed=fixed, parameters=tuple(params),
        figures=tuple(figures), derived=tuple(derived), plot=plot,
    )


#: The earlier names of the spec's config types (``...Config`` is the package's one suffix for configuration).
