"""Many independent runs as Dask tasks (the library part of simfab's studies at scale).

- :func:`simfab.sweep.tasks.run_tasks` -- run a picklable function over a list of keyword
  dicts on a Dask cluster (a LocalCluster sized to this machine by default, or
  ``scheduler="HOST:PORT"``); failures come back as data (:class:`TaskResult`). Used by the
  micro-crowd study, the rest-shape optimization's restarts and handle study, and ``simfab sweep``.
- :mod:`simfab.sweep.table`, :mod:`simfab.sweep.plots` -- the result table (Parquet/CSV) and PNG plots.

``simfab sweep SPEC.toml`` runs subcommands, so its spec, per-run runner and resume logic live
in the command-line layer (``simfab/cli/sweep_spec.py``, ``sweep_runner.py``,
``sweep_study.py``): the library never imports the CLI.
"""

from simfab.sweep.tasks import TaskResult, connect, run_tasks  # noqa: F401

__all__ = ["TaskResult", "connect", "run_tasks"]
