"""Many independent runs as Dask tasks (the library part of simfab's studies at scale).

- :func:`simfab.sweep.tasks.run_tasks` -- run a picklable function over a list of keyword
  dicts on a Dask cluster (a LocalCluster sized to this machine by default, or
  ``scheduler="HOST:PORT"``); failures come back as data (:class:`TaskResult`). Used by the
  micro-crowd study, the rest-shape optimization's restarts and handle study, and ``simfab sweep``.
- :mod:`simfab.sweep.runs` -- a sweep's runs as area function calls (:class:`~simfab.sweep.runs.ApiCall`)
  in Dask tasks, the resumable table (:func:`~simfab.sweep.runs.run_sweep`, typed ``SweepResult``).
- :mod:`simfab.sweep.table`, :mod:`simfab.sweep.plots` -- the result table (Parquet/CSV) and PNG plots.

``simfab sweep SPEC.toml`` reads its spec (a command line per run, ``simfab/cli/sweep_spec.py``)
and turns each run's line into a call (``simfab/cli/sweep_runner.py``); the library never imports
the CLI.
"""

from simfab.sweep.tasks import TaskResult, connect, run_tasks  # noqa: F401

__all__ = ["TaskResult", "connect", "run_tasks"]
