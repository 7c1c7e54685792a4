"""A sweep's runs as library calls: each run is one area function (``simfab.coupling.run``, ...)
called in a Dask task on an edited copy of the base scene, its figures picked from the result's
JSON; the runs' table is kept and resumed (:func:`run_sweep`).

:class:`ApiCall` names the area function (:data:`API_TARGETS`) and its arguments, with
``"{scene}"`` where the run's scene copy goes; :func:`execute_run` is the task. ``simfab sweep``
builds the calls from its spec (a command line per run); commands whose area has no function
yet are run by a caller-supplied callable with the same protocol (``call(scene_path=..., out=...)``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
import json
import math
import os
import tempfile
import time
from pathlib import Path
from typing import Callable

from simfab._version import __version__
from simfab.errors import InputError
from simfab.results import Result, field
from simfab.sweep.table import FINAL, frame, read_table, write_table

#: The command -> (module, function) of the area functions a sweep run can call.
API_TARGETS = {
    "couple simulate": ("simfab.coupling.insertion", "run"),
    "couple optimize": ("simfab.design.pipeline", "run"),
    "validate buckling": ("simfab.validate", "buckling"),
    "crowd aggregate": ("simfab.crowd.pipeline", "aggregate"),
    "crowd study": ("simfab.crowd.pipeline", "study"),
    "crowd truth": ("simfab.crowd.pipeline", "truth"),
    "crowd simulate": ("simfab.crowd.pipeline", "synthesize"),
    "crowd bracket": ("simfab.crowd.pipeline", "bracket"),
}

#: Columns every sweep table has besides its parameters and figures.
META_COLUMNS = ("run", "key", "status", "message", "seconds", "worker", "outputs")

SCENE = "{scene}"


def _with_scene(v, scene_path: str | None):
    if scene_path is None:
        return v
    if isinstance(v, str):
        return v.replace(SCENE, scene_path)
    if isinstance(v, (list, tuple)):
        return type(v)(_with_scene(x, scene_path) for x in v)
    if isinstance(v, dict):
        return {k: _with_scene(x, scene_path) for k, x in v.items()}
    return v


@dataclasses.dataclass(frozen=True, kw_only=True)
class ApiCall:
    """One run as an area function call (picklable: names, not functions).

    Args:
        command: a key of :data:`API_TARGETS` (``"couple simulate"``).
        args: positional arguments (``"{scene}"`` where the run's scene copy goes).
        kwargs: keyword arguments (``out`` is the run's folder, set by :func:`execute_run`).
    """

    command: str
    args: tuple = ()
    kwargs: dict = dataclasses.field(default_factory=dict)

    def __call__(self, *, scene_path: str | None, out: str) -> dict:
        """Call the function into ``out``; return its result's JSON object."""
        module, name = API_TARGETS[self.command]
        fn = getattr(importlib.import_module(module), name)
        result = fn(*_with_scene(self.args, scene_path), out=out, **_with_scene(self.kwargs, scene_path))
        return result.to_json()


def execute_run(*, call: Callable[..., dict], figures: list[tuple[str, str]], run_dir: str, keep: bool,
                scene: dict | None) -> dict:
    """One run of a sweep (a Dask task): write the edited scene, call ``call``, pick the figures.

    Args:
        call: an :class:`ApiCall` (or any picklable callable ``call(scene_path=..., out=...) -> dict``).
        figures: (name, dotted path into the result's JSON) per figure.
        run_dir: the run's folder (its outputs and its scene copy).
        keep: False runs in a temporary folder removed afterwards.
        scene: the base scene's files and edits (:func:`write_scene`), or None.

    Returns:
        {figure name: value}. Raises what the call raises (the task wrapper turns it into a row).
    """
    with contextlib.ExitStack() as stack:
        d = Path(run_dir) if keep else Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="simfab-run-")))
        d.mkdir(parents=True, exist_ok=True)
        scene_path = str(write_scene(scene, d / "scene")) if scene is not None else None
        summary = call(scene_path=scene_path, out=str(d))
    return {name: table_cell(lookup(summary, path)) for name, path in figures}


@dataclasses.dataclass(frozen=True, kw_only=True)
class SweepResult(Result):
    """A sweep's outcome (the ``--json`` summary of ``simfab sweep``).

    Args:
        spec: the spec file; name: the sweep's name.
        runs: runs of the spec; ran: run now; skipped: already in the table.
        ok: runs that succeeded; failed: status -> count of the others.
        seconds: wall time [s]; run_seconds: the runs' own seconds, summed [s].
        simfab_version: the version the runs' keys carry.
        outputs: table_parquet, table_csv, plots {name: png}, summary_json.
    """

    spec: str
    name: str
    runs: int
    ran: int
    skipped: int
    ok: int
    failed: dict
    seconds: float = field(unit="s")
    run_seconds: float = field(unit="s")
    simfab_version: str

    def to_json(self) -> dict:
        """The summary (``outputs`` last).

        Returns:
            A dict of JSON values.
        """
        d = super().to_json()
        return {**{k: v for k, v in d.items() if k != "outputs"}, "outputs": d["outputs"]}


#: Seconds between rewrites of the table while results arrive.
SAVE_INTERVAL = 2.0


def columns(spec) -> list[str]:
    """The table's columns in order (parameters, figures, derived columns, then :data:`META_COLUMNS`)."""
    return (["run", "key"] + [p.name for p in spec.parameters] + [g.name for g in spec.figures]
            + [n for n, _ in spec.derived] + [c for c in META_COLUMNS if c not in ("run", "key")])


def _check_derived(spec) -> None:
    """Evaluate every derived expression on a one-row table of ones (names and syntax)."""
    import pandas as pd

    df = pd.DataFrame({c: [1.0] for c in columns(spec)})
    for name, expr in spec.derived:
        try:
            df[name] = df.eval(expr)
        except Exception as e:
            raise InputError(f"cannot evaluate {expr!r}: {' '.join(str(e).split())}",
                             where=f"{spec.source} [derived] {name}") from None


def with_derived(spec, df):
    """``df`` with the derived columns (NaN where an input is missing)."""
    for name, expr in spec.derived:
        try:
            df[name] = df.eval(expr) if len(df) else []
        except Exception:  # an input column holds text in this table: leave the column empty
            df[name] = math.nan
    return df


def _native(v):
    """A table cell read back from Parquet/CSV as a plain Python value (missing -> None)."""
    import pandas as pd

    if v is None or v is pd.NA or (isinstance(v, float) and math.isnan(v)):
        return None
    return v.item() if hasattr(v, "item") else v


def run_sweep(spec, out, *, make_task: Callable[[dict, str], dict], scheduler=None, quiet: bool = False,
              retry_failed: bool = False) -> SweepResult:
    """Run a sweep spec's missing runs as Dask tasks of :func:`execute_run` and keep the table.

    Resume: the runs already in ``OUT/NAME.parquet`` whose key (hash of parameters, fixed settings,
    command, base scene and simfab version) matches a run of the spec, and whose status is final
    (ok, bad_input, not_converged), are not run again; internal errors and dead workers are. Rows of
    the old table that match no run of the spec are dropped.

    Args:
        spec: the sweep spec (``points()``, ``run_key``, ``parameters``, ``figures``, ``derived``,
            ``keep_outputs``, ``name``, ``source``; ``simfab sweep`` reads it from SPEC.toml).
        out: the sweep's folder.
        make_task: (point, run_dir) -> keyword arguments of :func:`execute_run` for that run.
        scheduler: Dask scheduler address, a running client, or "serial".
        quiet: no log lines or progress bars.
        retry_failed: run again the runs whose status is bad_input or not_converged.

    Returns:
        The :class:`SweepResult` (counts per status, the table's and plots' paths).
    """
    from simfab.io.atomic import write_json
    from simfab.io.outpaths import make_out_dir
    from simfab.progress import log
    from simfab.sweep.plots import plot_sweep
    from simfab.sweep.tasks import SERIAL, connect, run_tasks

    t0 = time.perf_counter()
    out = Path(out).absolute()
    _check_derived(spec)
    points = spec.points()
    keys = [spec.run_key(p, __version__) for p in points]
    first = {}
    for i, k in enumerate(keys):
        if k in first:
            raise InputError(f"runs {first[k]} and {i} have the same parameters ({points[i]}); "
                             "remove the repeated value", where=f"{spec.source} [parameters]")
        first[k] = i
    cols = columns(spec)
    rows: dict[str, dict] = {}
    old = read_table(out, spec.name)
    keep = FINAL[:1] if retry_failed else FINAL
    if old is not None and "key" in old and "status" in old:
        for rec in old.to_dict("records"):
            k = str(rec.get("key"))
            if k in first and rec.get("status") in keep:
                rows[k] = {c: _native(rec.get(c)) for c in cols} | {"run": first[k]}
        log(f"sweep: {spec.name}: resuming, {len(rows)} of {len(points)} runs already in the table", quiet=quiet)
    todo = [i for i, k in enumerate(keys) if k not in rows]

    def table():
        return with_derived(spec, frame(list(rows.values()), cols))

    last = [time.perf_counter()]

    def on_result(r):
        i = todo[r.index]
        k = keys[i]
        figs = r.value if r.ok else {}
        kept = spec.keep_outputs and r.status not in ("worker_died", "version_mismatch")
        rows[k] = {"run": i, "key": k, **{p: table_cell(v) for p, v in points[i].items()},
                   **{g.name: figs.get(g.name) for g in spec.figures},
                   "status": r.status, "message": r.message, "seconds": r.seconds, "worker": r.worker,
                   "outputs": f"runs/{k}" if kept else ""}
        if time.perf_counter() - last[0] > SAVE_INTERVAL:
            write_table(table(), out, spec.name)
            last[0] = time.perf_counter()

    tasks = [make_task(points[i], str(out / "runs" / keys[i])) for i in todo]
    with contextlib.ExitStack() as stack:
        if todo and scheduler != SERIAL:  # a scheduler that cannot be reached: no output at all
            scheduler = stack.enter_context(connect(scheduler, quiet=quiet))
        make_out_dir(out)
        log(f"sweep: {spec.name}: {len(points)} runs, {len(todo)} to run", quiet=quiet)
        try:
            run_tasks(execute_run, tasks, scheduler=scheduler, quiet=quiet, desc=spec.name, on_result=on_result)
        finally:  # an interrupted sweep keeps what finished
            df = table()
            paths = write_table(df, out, spec.name)
    plots = plot_sweep(spec, df, out)
    counts = df["status"].value_counts().to_dict() if len(df) else {}
    outputs = {"table_parquet": paths["parquet"], "table_csv": paths["csv"], "plots": plots,
               "summary_json": str(out / f"{spec.name}.json")}
    result = SweepResult(spec=str(spec.source), name=spec.name, runs=len(points), ran=len(todo),
                         skipped=len(points) - len(todo), ok=int(counts.get("ok", 0)),
                         failed={k: int(v) for k, v in counts.items() if k != "ok"}, seconds=time.perf_counter() - t0,
                         run_seconds=float(df["seconds"].sum()) if len(df) else 0.0, simfab_version=__version__,
                         outputs=outputs)
    write_json(outputs["summary_json"], result.to_json())
    return result


def lookup(summary: dict, path: str):
    """The value at dotted ``path`` (dict keys; integers index lists); KeyError naming the
    missing part and the keys that are there."""
    cur = summary
    for i, part in enumerate(path.split(".")):
        if isinstance(cur, dict) and part in cur:
            cur = cur[part]
        elif isinstance(cur, list) and part.lstrip("-").isdigit() and -len(cur) <= int(part) < len(cur):
            cur = cur[int(part)]
        else:
            here = ".".join(path.split(".")[:i]) or "the summary"
            have = ", ".join(list(cur)[:12]) if isinstance(cur, dict) else f"a {type(cur).__name__}"
            raise KeyError(f"{here} has no {part!r} (has: {have})")
    return cur


def table_cell(v):
    """A table cell: scalars as they are, anything nested as compact JSON."""
    if isinstance(v, (dict, list)):
        return json.dumps(v, separators=(",", ":"))
    return v


def write_scene(scene: dict, folder: Path) -> Path:
    """Write the base scene's files with the edits applied into ``folder``; returns the main
    file's path. File references relative to the base folder become absolute."""
    folder.mkdir(parents=True, exist_ok=True)
    base = Path(scene["base"])
    for name, text in scene["files"].items():
        if name.endswith(".toml"):
            text = _edit_toml(text, scene["toml"], base, where=name)
        else:
            text = _edit_mjcf(text, scene["mjcf"], base, where=name)
        (folder / name).write_text(text, encoding="utf-8")
    return folder / scene["main"]


def _edit_toml(text: str, edits, base: Path, *, where: str) -> str:
    import tomllib

    import tomli_w

    d = tomllib.loads(text)

    def absolute(x):  # relative file names (outline, mesh, mesh_file) keep pointing at the base folder
        if isinstance(x, dict):
            return {k: absolute(v) for k, v in x.items()}
        if isinstance(x, str) and x and not os.path.isabs(x) and (base / x).is_file():
            return str(base / x)
        return x

    d = absolute(d)
    for path, v in edits:
        cur = d
        for k in path[:-1]:
            cur = cur.setdefault(k, {})
            if not isinstance(cur, dict):
                raise InputError(f"{'.'.join(path)}: {k!r} is not a table", where=where)
        cur[path[-1]] = v
    return tomli_w.dumps(d)


def _edit_mjcf(text: str, edits, base: Path, *, where: str) -> str:
    import xml.etree.ElementTree as ET

    try:
        root = ET.fromstring(text)
    except ET.ParseError as e:
        raise InputError(f"not valid XML: {e}", where=where) from None
    for el in root.iter():  # file references stay valid from the run folder
        for attr in ("file", "meshdir", "texturedir", "assetdir"):
            v = el.get(attr)
            if v and not os.path.isabs(v) and (base / v).exists():
                el.set(attr, str(base / v))
    for tag, name, attr, index, v in edits:
        hits = [el for el in root.iter(tag) if el.get("name") == name]
        if not hits:
            raise InputError(f"no <{tag} name={name!r}> in the MJCF scene", where=where)
        for el in hits:
            if index:
                old = el.get(attr)
                if old is None:
                    raise InputError(f"<{tag} name={name!r}> has no {attr!r} to set components of", where=where)
                comps = old.split()
                if max(index) >= len(comps):
                    raise InputError(f"<{tag} name={name!r}> {attr}={old!r} has no component {max(index)}", where=where)
                for i in index:
                    comps[i] = repr(float(v)) if isinstance(v, float) else str(v)
                el.set(attr, " ".join(comps))
            else:
                text = " ".join(map(str, v)) if isinstance(v, (list, tuple)) else (
                    repr(v) if isinstance(v, float) else str(v))
                el.set(attr, text)
    return ET.tostring(root, encoding="unicode")
