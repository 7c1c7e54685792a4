"""Many independent runs as Dask tasks: ``run_tasks(fn, kwargs_list)``.

The one entry point every many-run study in simfab goes through (``simfab sweep``, the
micro-crowd study, optimization restarts)::

    from simfab.sweep import run_tasks

    results = run_tasks(fn, [{"seed": s} for s in range(8)], scheduler=None, desc="restarts")
    best = min((r for r in results if r.ok), key=lambda r: r.value["energy"])

``fn`` is a picklable module-level function called as ``fn(**kwargs)`` on a Dask worker.
Results come back in the order of ``kwargs_list``, one :class:`TaskResult` per task: the
value, or the failure as data (``status`` and a one-line ``message``) -- an exception in one
task never stops the others.

Where the tasks run (``scheduler``): ``None``, a ``distributed.LocalCluster`` started for the
call (one single-threaded worker process per core); ``"HOST:PORT"``, an existing Dask cluster
whose workers have the same simfab version (checked at connect time); a ``distributed.Client``,
reused and left open; ``"serial"``, in this process without Dask (:func:`connect`,
:func:`run_tasks`). A worker that dies while running a task is replaced and the task rescheduled
(``distributed.scheduler.allowed-failures`` times); past that the task's row says ``worker_died``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import socket
import time
from typing import Any, Callable, Iterator, Sequence

from simfab._version import __version__
from simfab.errors import ConvergenceError, InputError
from simfab.progress import log

#: ``TaskResult.status`` values.
STATUSES = ("ok", "bad_input", "not_converged", "error", "worker_died", "version_mismatch")

SERIAL = "serial"

#: Shortest interval between two gathers of finished results [s] (a gather is a round trip
#: to the workers; for short tasks it dominates Dask's per-task overhead).
GATHER_INTERVAL = 0.1


@dataclasses.dataclass(frozen=True, kw_only=True)
class TaskResult:
    """Outcome of one task.

    Args:
        index: position in ``kwargs_list``.
        value: what ``fn`` returned (None unless ok).
        status: one of :data:`STATUSES` ("ok", "bad_input" for :class:`InputError`, "not_converged"
            for :class:`ConvergenceError`, "error" for any other exception, "worker_died",
            "version_mismatch").
        message: one line, "" when ok.
        seconds: wall time of ``fn`` on the worker [s] (0 when the worker died).
        worker: the worker's address ("serial" in-process).
    """

    index: int
    value: Any = None
    status: str = "ok"
    message: str = ""
    seconds: float = 0.0
    worker: str = ""

    @property
    def ok(self) -> bool:
        return self.status == "ok"


def one_line(e: BaseException) -> str:
    """``TypeName: message`` on one line (the message alone for simfab's own errors)."""
    msg = " ".join(str(e).split())
    if isinstance(e, (InputError, ConvergenceError)):
        return msg or type(e).__name__
    return f"{type(e).__name__}: {msg}" if msg else type(e).__name__


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return get_worker().address
    except (ImportError, ValueError):
        return SERIAL


def call(fn: Callable, kwargs: dict, version: str | None = None) -> dict:
    """Run ``fn(**kwargs)`` and turn its outcome into a plain dict (runs on the worker).

    ``version``: the client's simfab version; a worker with another one refuses the task.
    """

    t0 = time.perf_counter()
    out = {"value": None, "status": "ok", "message": "", "worker": _worker_name()}
    if version is not None and version != __version__:
        out.update(status="version_mismatch",
                   message=f"worker {out['worker']} runs simfab {__version__}, the client {version}")
    else:
        try:
            out["value"] = fn(**kwargs)
        except InputError as e:
            out.update(status="bad_input", message=one_line(e))
        except ConvergenceError as e:
            out.update(status="not_converged", message=one_line(e))
        except Exception as e:  # failure is data: the row says what went wrong
            out.update(status="error", message=one_line(e))
    out["seconds"] = time.perf_counter() - t0
    return out


def _call_kw(kwargs: dict, *, fn: Callable, version: str | None) -> dict:
    return call(fn, kwargs, version)


def machine_workers() -> int:
    """Worker processes of the default LocalCluster: the cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def _dashboard(client) -> str | None:
    """The dashboard URL, or None when the scheduler serves none (its status pages need bokeh
    installed where the scheduler runs)."""

    def has_bokeh():  # pickled by value, runs in the scheduler
        import importlib.util

        return importlib.util.find_spec("bokeh") is not None

    try:
        if "dashboard" not in client.scheduler_info().get("services", {}) or not client.run_on_scheduler(has_bokeh):
            return None
        return client.dashboard_link
    except Exception:  # an informational extra; never fail a study over it
        return None


def check_worker_versions(client, version: str | None = None, *, where: str = "--scheduler") -> dict:
    """Ask every worker of ``client`` for its simfab version; InputError if any differs from
    ``version`` (default: this process's) or cannot import simfab. Returns {address: version}."""

    version = version or __version__

    def probe():  # pickled by value: runs even where simfab is missing
        import importlib

        try:
            return importlib.import_module("simfab").__version__  # (the worker's installation, by name)
        except ImportError as e:
            return f"not installed ({e})"

    found = client.run(probe)
    bad = {a: v for a, v in found.items() if v != version}
    if bad:
        addr, v = sorted(bad.items())[0]
        more = f" (and {len(bad) - 1} more workers)" if len(bad) > 1 else ""
        raise InputError(f"Dask worker {addr} has simfab {v}, this client {version}{more}: "
                         "install the same simfab on every worker", where=where)
    return found


@contextlib.contextmanager
def connect(scheduler=None, *, quiet: bool = False, min_workers: int = 1, timeout: float = 30.0) -> Iterator:
    """Yield a ``distributed.Client`` for ``scheduler`` (a context manager).

    A cluster started here is closed on exit; a passed-in Client is left open.

    Args:
        scheduler: None (a ``LocalCluster``, one single-threaded worker process per core: Warp's CPU
            kernels and numpy hold one core each), ``"HOST:PORT"`` / ``"tcp://HOST:PORT"`` (an existing
            cluster of ``dask scheduler`` and ``dask worker`` processes, see README.md) or a
            ``distributed.Client`` (not ``"serial"``).
        quiet: no chatter on stderr.
        min_workers: the workers a remote cluster must have within ``timeout``.
        timeout: seconds to wait for the connection and the workers [s].

    Yields:
        A connected ``distributed.Client``.

    Raises:
        InputError: the scheduler cannot be reached, has no workers, or a worker runs another simfab version.
    """
    from distributed import Client, LocalCluster


    if isinstance(scheduler, Client):
        yield scheduler
        return
    with contextlib.ExitStack() as stack:
        if scheduler is None:
            n = machine_workers()
            cluster = stack.enter_context(LocalCluster(
                n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                silence_logs=logging.ERROR))
            client = stack.enter_context(Client(cluster))
            log(f"dask: local cluster, {n} worker processes", quiet=quiet)
        else:
            addr = str(scheduler)
            if "://" not in addr:
                addr = "tcp://" + addr
            try:
                if addr.startswith("tcp://"):  # refused at once rather than after Dask's retries
                    from distributed.comm.addressing import parse_host_port

                    socket.create_connection(parse_host_port(addr[6:]), timeout=timeout).close()
                client = stack.enter_context(Client(addr, timeout=timeout))
            except (OSError, TimeoutError) as e:
                raise InputError(f"cannot connect to a Dask scheduler at {addr}: {one_line(e)}",
                                 where="--scheduler") from None
            try:
                client.wait_for_workers(min_workers, timeout=timeout)
            except TimeoutError:
                raise InputError(f"the Dask scheduler at {addr} has no workers (start some with 'dask worker {addr}')",
                                 where="--scheduler") from None
            check_worker_versions(client)
            log(f"dask: scheduler {addr}, {len(client.scheduler_info()['workers'])} workers", quiet=quiet)
        link = _dashboard(client)
        if link:
            log(f"dask: dashboard {link}", quiet=quiet)
        yield client


class _Bar:
    """Progress over tasks on stderr: completed / failed / running (rich, only on a terminal)."""

    def __init__(self, total: int, desc: str, quiet: bool):
        import sys

        self.total, self.done, self.failed, self.running = total, 0, 0, 0
        self._bar = None
        if quiet or not sys.stderr.isatty() or total == 0:
            return
        from rich.console import Console
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        self._bar = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                             TextColumn("[red]{task.fields[failed]} failed[/] {task.fields[running]} running"),
                             TimeElapsedColumn(), TimeRemainingColumn(), console=Console(stderr=True), transient=True)
        self._bar.start()
        self._task = self._bar.add_task(desc or "tasks", total=total, failed=0, running=0)

    def update(self, *, ok: bool | None = None, running: int | None = None) -> None:
        if ok is not None:
            self.done += 1
            self.failed += not ok
        if running is not None:
            self.running = running
        if self._bar is not None:
            self._bar.update(self._task, completed=self.done, failed=self.failed, running=self.running)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.stop()


def _result(index: int, d: dict) -> TaskResult:
    return TaskResult(index=index, value=d["value"], status=d["status"], message=d["message"], seconds=d["seconds"],
                      worker=d["worker"])


def run_tasks(fn: Callable, kwargs_list: Sequence[dict], *, scheduler=None, quiet: bool = False, desc: str = "",
              on_result: Callable[[TaskResult], None] | None = None) -> list[TaskResult]:
    """Run ``fn(**kw)`` for every ``kw`` in ``kwargs_list`` as independent Dask tasks.

    Args:
        fn: picklable module-level function (workers import it by name, so it must live in an
            installed module, e.g. simfab's).
        kwargs_list: (T,) dicts of picklable arguments.
        scheduler: None (LocalCluster sized to this machine), ``"HOST:PORT"``, a ``distributed.Client``
            or ``"serial"`` (in this process, no Dask: for debugging and as a benchmark's serial baseline);
            see :func:`connect`.
        quiet: no progress bar or chatter.
        desc: progress label.
        on_result: called in the client as each task finishes (completion order), e.g. to save
            partial results.

    Returns:
        (T,) :class:`TaskResult` in the order of ``kwargs_list``.

    Raises:
        InputError: the scheduler cannot be reached or a worker has another simfab version.
    """

    kwargs_list = list(kwargs_list)
    results: list[TaskResult | None] = [None] * len(kwargs_list)
    bar = _Bar(len(kwargs_list), desc, quiet)

    def finish(r: TaskResult) -> None:
        results[r.index] = r
        bar.update(ok=r.ok)
        if on_result is not None:
            on_result(r)

    try:
        if scheduler == SERIAL:
            for i, kw in enumerate(kwargs_list):
                bar.update(running=1)
                finish(_result(i, call(fn, kw)))
        elif kwargs_list:
            with connect(scheduler, quiet=quiet) as client:
                _run_dask(client, fn, kwargs_list, __version__, finish, bar)
    finally:
        bar.close()
    return results  # type: ignore[return-value]


def _run_dask(client, fn, kwargs_list, version, finish, bar) -> None:
    from distributed import as_completed
    from distributed.scheduler import KilledWorker

    token = f"{getattr(fn, '__name__', 'task')}-{socket.gethostname()}-{os.getpid()}-{time.time_ns()}"
    keys = [f"simfab-{token}-{i}" for i in range(len(kwargs_list))]
    futures = client.map(_call_kw, kwargs_list, fn=fn, version=version, key=keys, pure=False)
    index = {f.key: i for i, f in enumerate(futures)}
    bar.update(running=min(len(futures), sum(client.nthreads().values())))
    last = 0.0
    try:
        done = as_completed(futures)
        t_gather = 0.0
        while not done.is_empty():
            batch = done.next_batch(block=True)
            wait = GATHER_INTERVAL - (time.perf_counter() - t_gather)
            if wait > 0:  # many short tasks: collect a few more, then one round trip for all
                time.sleep(wait)
                batch += done.next_batch(block=False)
            t_gather = time.perf_counter()
            try:
                values = client.gather(batch)
            except Exception:  # some task of the batch failed outside fn: one by one
                values = None
            for j, fut in enumerate(batch):
                i = index[fut.key]
                try:
                    r = _result(i, values[j] if values is not None else fut.result())
                except KilledWorker as e:
                    r = TaskResult(index=i, status="worker_died", message=one_line(e))
                except Exception as e:  # lost in transit (e.g. the result could not be unpickled)
                    r = TaskResult(index=i, status="error", message=one_line(e))
                finish(r)
            now = time.perf_counter()
            if bar._bar is not None and now - last > 0.5:  # a scheduler round trip: throttled
                last = now
                busy = sum(len(v) for v in client.processing().values())  # incl. queued on a worker
                bar.update(running=min(busy, sum(client.nthreads().values()), bar.total - bar.done))
    finally:
        client.cancel([f for f in futures if not f.done()])
