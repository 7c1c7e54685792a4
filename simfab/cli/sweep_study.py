"""``run_sweep``: a spec's runs (:mod:`simfab.cli.sweep_runner` turns each command line into an
area function call) through the library's sweep (:func:`simfab.sweep.runs.run_sweep`: Dask
tasks, the resumable table, plots, summary)."""

from __future__ import annotations

from simfab.cli.sweep_spec import SweepConfig


def run_sweep(spec: SweepConfig, out, *, scheduler=None, quiet: bool = False, retry_failed: bool = False) -> dict:
    """Run ``spec`` into the folder ``out``; returns the summary (the :class:`simfab.sweep.runs.SweepResult`'s
    JSON): counts per status, the paths of the table (Parquet, CSV), plots (PNG) and summary JSON."""
    from simfab.cli.sweep_runner import run_task
    from simfab.sweep.runs import run_sweep as run

    def make_task(point: dict, run_dir: str) -> dict:
        return run_task(spec, point, run_dir=run_dir)

    return run(spec, out, make_task=make_task, scheduler=scheduler, quiet=quiet,
               retry_failed=retry_failed).to_json()


__all__ = ["run_sweep"]
