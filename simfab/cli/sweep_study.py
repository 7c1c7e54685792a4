"""``run_sweep``: expand a spec into runs, run the missing ones as Dask tasks, keep the table.

Resume: the runs already in ``OUT/NAME.parquet`` whose key (hash of parameters, fixed
settings, command, base scene and simfab version) matches a run of the spec, and whose status
is final (ok, bad_input, not_converged), are not run again; internal errors and dead workers
are. Rows of the old table that match no run of the spec are dropped.
"""

from __future__ import annotations

import contextlib
import math
import time
from pathlib import Path

from simfab.cli.sweep_spec import META_COLUMNS, SweepSpec
from simfab.errors import InputError
from simfab.io.outpaths import make_out_dir
from simfab.sweep.table import FINAL, frame, read_table, table_paths, write_table

#: Seconds between rewrites of the table while results arrive.
SAVE_INTERVAL = 2.0


def columns(spec: SweepSpec) -> list[str]:
    """The table's columns in order."""
    return (["run", "key"] + [p.name for p in spec.parameters] + [g.name for g in spec.figures]
            + [n for n, _ in spec.derived] + [c for c in META_COLUMNS if c not in ("run", "key")])


def _check_derived(spec: SweepSpec) -> None:
    """Evaluate every derived expression on a one-row table of ones (names and syntax)."""
    import pandas as pd

    df = pd.DataFrame({c: [1.0] for c in columns(spec)})
    for name, expr in spec.derived:
        try:
            df[name] = df.eval(expr)
        except Exception as e:
            raise InputError(f"cannot evaluate {expr!r}: {' '.join(str(e).split())}",
                             where=f"{spec.source} [derived] {name}") from None


def with_derived(spec: SweepSpec, df):
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


def run_sweep(spec: SweepSpec, out, *, scheduler=None, quiet: bool = False, retry_failed: bool = False) -> dict:
    """Run ``spec`` into the folder ``out`` (see the module docstring); returns the summary:
    counts per status, the paths of the table (Parquet, CSV), plots (PNG) and summary JSON."""
    from simfab import __version__
    from simfab.cli.sweep_runner import cell, execute_run, run_task
    from simfab.io.atomic import write_json
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
        rows[k] = {"run": i, "key": k, **{p: cell(v) for p, v in points[i].items()},
                   **{g.name: figs.get(g.name) for g in spec.figures},
                   "status": r.status, "message": r.message, "seconds": r.seconds, "worker": r.worker,
                   "outputs": f"runs/{k}" if kept else ""}
        if time.perf_counter() - last[0] > SAVE_INTERVAL:
            write_table(table(), out, spec.name)
            last[0] = time.perf_counter()

    tasks = [run_task(spec, points[i], run_dir=str(out / "runs" / keys[i])) for i in todo]
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
    summary = {
        "spec": str(spec.source), "name": spec.name, "runs": len(points), "ran": len(todo),
        "skipped": len(points) - len(todo),
        "ok": int(counts.get("ok", 0)), "failed": {k: int(v) for k, v in counts.items() if k != "ok"},
        "seconds": time.perf_counter() - t0, "run_seconds": float(df["seconds"].sum()) if len(df) else 0.0,
        "simfab_version": __version__,
        "outputs": {"table_parquet": paths["parquet"], "table_csv": paths["csv"], "plots": plots},
    }
    summary["outputs"]["summary_json"] = str(write_json(out / f"{spec.name}.json", summary))
    return summary


__all__ = ["run_sweep", "columns", "table_paths"]
