"""simfab sweep: a parameter study over any subcommand, one Dask task per run.

Usage:

    simfab sweep SPEC.toml [--scheduler HOST:PORT] [--retry-failed] [--out DIR]
    simfab sweep --list

SPEC.toml (or the name of a bundled spec in scenes/sweeps, e.g. cclamp2d_chart) names a
command, optionally a base scene whose parameters it varies, the parameters' values (lists,
ranges, seeded random samples) and the figures to collect from each run's JSON summary (see
simfab.cli.sweep_spec and scenes/sweeps/README.md). Each run executes the subcommand
in-process on a Dask worker with --out OUT/runs/KEY; by default on a LocalCluster of one
worker process per core, with --scheduler on an existing cluster (dask scheduler +
dask worker; every worker needs the same simfab installed, checked at connect time).

Outputs under --out (default ./simfab-out/sweep/NAME): NAME.parquet and NAME.csv (one row
per run: run, key, parameters, figures, derived columns, status, message, seconds, worker,
outputs), NAME_<figure>.png (each figure against the 1-2 swept parameters), NAME.json (the
summary) and runs/KEY/ (each run's own outputs). A failing run is a row (status bad_input,
not_converged, error or worker_died, with its message); the sweep goes on. Started again with
the same spec and --out, a sweep resumes: runs already in the table are skipped (keyed by a
hash of their parameters and simfab's version); --retry-failed runs the failed ones again.

--json keys: runs, ran, skipped, ok, failed (count per status), seconds, run_seconds, outputs
(table and plot paths); with --list: specs.
"""

from __future__ import annotations

import os

HELP = "parameter sweep over any subcommand on Dask (table Parquet/CSV, plots, resume)"
DESCRIPTION = __doc__.split("\n\n", 1)[1]


def add_args(p) -> None:
    p.add_argument("spec", nargs="?", metavar="SPEC", help="sweep spec TOML, or a bundled spec name (see --list)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="Dask scheduler to run on, e.g. tcp://10.0.0.5:8786 (default: a local cluster)")
    p.add_argument("--retry-failed", action="store_true", help="on resume, run again the runs that failed")
    p.add_argument("--list", action="store_true", help="list the bundled sweep specs")


def run(args) -> dict:
    from simfab._bundled import scenes_dir
    from simfab.cli.sweep_spec import load_spec
    from simfab.cli.sweep_study import run_sweep
    from simfab.errors import InputError

    if args.list:
        return {"specs": sorted(p.stem for p in scenes_dir("sweeps").glob("*.toml"))}
    if not args.spec:
        raise InputError("give a sweep spec (SPEC.toml or a bundled name; 'simfab sweep --list')")
    spec = load_spec(args.spec)
    out = args.out
    if out == os.path.join("simfab-out", "sweep"):  # the default: one folder per spec
        out = os.path.join(out, spec.name)
    return run_sweep(spec, out, scheduler=args.scheduler, quiet=args.quiet, retry_failed=args.retry_failed)


def format_text(summary: dict) -> str:
    if "specs" in summary:
        return "\n".join(summary["specs"])
    import pandas as pd

    df = pd.read_parquet(summary["outputs"]["table_parquet"])
    show = df.drop(columns=["key", "worker", "outputs"], errors="ignore")
    if "message" in show and not show["message"].fillna("").astype(str).str.len().any():
        show = show.drop(columns=["message"])
    with pd.option_context("display.max_rows", 40, "display.width", 160, "display.max_colwidth", 60,
                           "display.float_format", "{:.4g}".format):
        body = show.to_string(index=False)
    failed = ", ".join(f"{n} {k}" for k, n in summary["failed"].items()) or "none"
    lines = [f"sweep {summary['name']}: {summary['runs']} runs ({summary['ran']} ran, "
             f"{summary['skipped']} from the table), {summary['ok']} ok, failed: {failed}; "
             f"{summary['seconds']:.1f} s wall, {summary['run_seconds']:.1f} s in runs",
             body, f"table: {summary['outputs']['table_parquet']} (+ .csv)"]
    lines += [f"plot: {p}" for p in summary["outputs"]["plots"].values()]
    return "\n".join(lines)
