"""Studies at scale: parameter sweeps and many-run studies as Dask tasks.

- :func:`simfab.sweep.tasks.run_tasks` -- run a picklable function over a list of keyword
  dicts on a Dask cluster (a LocalCluster sized to this machine by default, or
  ``scheduler="HOST:PORT"``); failures come back as data (:class:`TaskResult`). Used by the
  micro-crowd study and by ``simfab sweep``.
- :mod:`simfab.sweep.spec` -- the sweep spec (``SPEC.toml``): command, base scene, parameters,
  figures to collect; run keys.
- :mod:`simfab.sweep.runner` -- one run on a worker: edited scene copy, the subcommand called
  in-process, figures picked from its summary.
- :mod:`simfab.sweep.study` -- :func:`run_sweep`: resume, the result table, plots.
- :mod:`simfab.sweep.table`, :mod:`simfab.sweep.plots` -- Parquet/CSV table, PNG plots.
"""

from simfab.sweep.tasks import TaskResult, connect, run_tasks  # noqa: F401

__all__ = ["TaskResult", "connect", "run_tasks", "load_spec", "run_sweep"]


def __getattr__(name):  # the sweep machinery imports pandas/matplotlib: only when asked for
    if name == "load_spec":
        from simfab.sweep.spec import load_spec

        return load_spec
    if name == "run_sweep":
        from simfab.sweep.study import run_sweep

        return run_sweep
    raise AttributeError(name)
