"""Sweep benchmark: many independent runs on Dask (``simfab.sweep``) against one process.

``python tools/bench.py sweep [--subcrowds 500] [--empty-tasks 400] [--skip-crowd]``

1. Per-task overhead of Dask: W single-threaded worker processes (a LocalCluster sized to
   this machine, started once and warmed up), T empty tasks through ``run_tasks``:
   overhead per task = wall * W / T (what each task costs a worker beyond its own work).
   Target: < 5 % of a 0.2 s task (10 ms). Also the CPU seconds per empty task of the client,
   scheduler and workers together (barely affected by other load on a shared machine, unlike
   the wall time). Cross-check: T/4 tasks that sleep 0.2 s, whose efficiency is
   (T/4 * 0.2 s / W) / wall.
2. A 16-run insertion sweep: the cclamp2d coupling scene over 4 Young's moduli x 4 arm widths
   (the sweep's runs, :func:`simfab.sweep.runs.execute_run`: each ``simfab.coupling.run`` on an
   edited scene copy with all its outputs), serial (in this process, one run after the other) and
   on the LocalCluster; the figures must be identical.
3. The micro-crowd study of the bundled practitioner crowd (15 raters, sizes 5..14,
   ``--subcrowds`` per size, one task per size), serial and on the LocalCluster; the two
   results must be identical.

Parallel efficiency = serial time / (W * Dask time). Dask times are given without the
cluster's start-up (reported separately: it is paid once per study or once per session).
``*_cores_used`` = CPU seconds / wall seconds of each phase (this process and its children):
a serial run already keeps more than one core busy (simfab's second worker thread, threaded
BLAS and CHOLMOD), while Dask's workers run single-threaded (Dask sets OMP_NUM_THREADS=1),
so on a machine with few cores the gain of W workers is less than W.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import cloudpickle


def empty() -> None:
    """The empty task."""


def sleep_02() -> float:
    time.sleep(0.2)
    return 0.2


def _cpu_seconds() -> float:
    """CPU time of this process (client and, for a LocalCluster, the scheduler) and of its
    children (nannies and workers) [s]: unlike wall time, barely affected by other load."""
    import psutil

    me = psutil.Process()
    total = sum(me.cpu_times()[:2])
    for ch in me.children(recursive=True):
        try:
            total += sum(ch.cpu_times()[:2])
        except psutil.Error:
            pass
    return total


def _overhead(client, workers: int, n: int) -> dict:
    from simfab.sweep.tasks import run_tasks

    run_tasks(empty, [{}] * (4 * workers), scheduler=client, quiet=True)  # warm: imports on every worker
    best = cpu = None
    for _ in range(3):  # the machine is shared: the least disturbed of three
        c0 = _cpu_seconds()
        t0 = time.perf_counter()
        res = run_tasks(empty, [{}] * n, scheduler=client, quiet=True)
        wall = time.perf_counter() - t0
        c = _cpu_seconds() - c0
        assert all(r.ok for r in res)
        best = wall if best is None else min(best, wall)
        cpu = c if cpu is None else min(cpu, c)
    m = max(n // 4, 2 * workers)
    t0 = time.perf_counter()
    run_tasks(sleep_02, [{}] * m, scheduler=client, quiet=True)
    wall_s = time.perf_counter() - t0
    per_task = best * workers / n
    return {
        "workers": workers, "empty_tasks": n, "empty_wall_seconds": best,
        "overhead_per_task_seconds": per_task,
        "cpu_seconds_per_task": cpu / n,
        "overhead_fraction_of_0_2s_task": per_task / 0.2, "target_fraction": 0.05,
        "ratio_to_target": (per_task / 0.2) / 0.05,
        "sleep_0_2s_tasks": m, "sleep_wall_seconds": wall_s,
        "sleep_efficiency": (m * 0.2 / workers) / wall_s,
        "sleep_overhead_per_task_seconds": (wall_s - m * 0.2 / workers) * workers / m,
    }


#: The insertion sweep: cclamp2d (Poisson ratio 0.36) over Young's modulus [Pa] x arm width [m].
YOUNGS_MODULI = (0.5e9, 1.0e9, 2.0e9, 3.5e9)
ARM_WIDTHS = (0.002, 0.0025, 0.003, 0.0035)


def _insertion_tasks(tmp: str, name: str) -> list[dict]:
    """One :func:`simfab.sweep.runs.execute_run` task per (E, width): ``simfab.coupling.run`` on an
    edited copy of the bundled scene, writing every output into its own folder."""
    from simfab._bundled import scenes_dir
    from simfab.sweep.runs import ApiCall

    toml = scenes_dir("coupling", "cclamp2d.toml")
    files = {f.name: f.read_text(encoding="utf-8") for f in (toml, toml.with_suffix(".xml"))}
    tasks = []
    for i, (E, w) in enumerate((E, w) for E in YOUNGS_MODULI for w in ARM_WIDTHS):
        scene = {"main": toml.with_suffix(".xml").name, "base": str(toml.parent), "files": files,
                 "toml": [(("material", "poisson_ratio"), 0.36), (("material", "youngs_modulus"), E),
                          (("compliant", "width"), w)], "mjcf": []}
        tasks.append({"call": ApiCall(command="couple simulate", args=("{scene}",)),
                      "figures": [("category", "category"), ("F_in", "F_in")],
                      "run_dir": os.path.join(tmp, name, f"run{i}"), "keep": True, "scene": scene})
    return tasks


def _insertion(client, workers: int, tmp: str) -> dict:
    from simfab.sweep import run_tasks
    from simfab.sweep.runs import execute_run

    c0, t0 = _cpu_seconds(), time.perf_counter()
    s = run_tasks(execute_run, _insertion_tasks(tmp, "serial"), scheduler="serial", quiet=True)
    serial, serial_cpu = time.perf_counter() - t0, _cpu_seconds() - c0
    c0, t0 = _cpu_seconds(), time.perf_counter()
    d = run_tasks(execute_run, _insertion_tasks(tmp, "dask"), scheduler=client, quiet=True)
    dask, dask_cpu = time.perf_counter() - t0, _cpu_seconds() - c0
    return {
        "runs": len(s), "ok": sum(r.ok for r in d), "serial_seconds": serial, "dask_seconds": dask,
        "speedup": serial / dask, "parallel_efficiency": serial / (workers * dask),
        "mean_run_seconds_serial": sum(r.seconds for r in s) / len(s),
        "mean_run_seconds_dask": sum(r.seconds for r in d) / len(d),
        "serial_cores_used": serial_cpu / serial, "dask_cores_used": dask_cpu / dask,
        "results_identical": [r.value for r in s] == [r.value for r in d],
    }


def _crowd(client, workers: int, n_sub: int) -> dict:
    import numpy as np

    from simfab._bundled import scenes_dir
    from simfab.crowd.data import Scale, load_ratings, load_truth
    from simfab.crowd.microcrowd import micro_crowd_study

    ratings = load_ratings(str(scenes_dir("crowd", "ratings_practitioners.csv")), Scale(lo=1, hi=10))
    truth = load_truth(str(scenes_dir("crowd", "truth_support.csv")), ratings)
    c0, t0 = _cpu_seconds(), time.perf_counter()
    a = micro_crowd_study(ratings, truth, n_sub=n_sub, seed=0, scheduler="serial")
    serial, serial_cpu = time.perf_counter() - t0, _cpu_seconds() - c0
    c0, t0 = _cpu_seconds(), time.perf_counter()
    b = micro_crowd_study(ratings, truth, n_sub=n_sub, seed=0, scheduler=client)
    dask, dask_cpu = time.perf_counter() - t0, _cpu_seconds() - c0
    same = all(np.array_equal(getattr(a, f), getattr(b, f)) for f in ("sizes", "percentile_mean", "percentile_sd",
                                                                        "bias_mean", "bias_sd", "unconverged",
                                                                        "rhat_median"))
    return {
        "crowd": f"bundled practitioners, {len(ratings.workers)} raters x {len(ratings.tasks)} questions",
        "sizes": len(a.sizes), "subcrowds_per_size": n_sub, "tasks": len(a.sizes),
        "serial_seconds": serial, "dask_seconds": dask, "speedup": serial / dask,
        "parallel_efficiency": serial / (workers * dask), "results_identical": bool(same),
        "serial_cores_used": serial_cpu / serial, "dask_cores_used": dask_cpu / dask,
    }


def run(argv):
    from simfab.sweep.tasks import connect, machine_workers

    ap = argparse.ArgumentParser(prog="bench sweep")
    ap.add_argument("--subcrowds", type=int, default=500,
                    help="sub-crowds per size in the crowd study (default 500, the study's)")
    ap.add_argument("--empty-tasks", type=int, default=400)
    ap.add_argument("--skip-crowd", action="store_true")
    a = ap.parse_args(argv)
    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # workers need not import tools/
    workers = machine_workers()
    out = {"machine": {"cores": workers, "load_average_1min_at_start": os.getloadavg()[0]}}
    t0 = time.perf_counter()
    with connect(None, quiet=True) as client, tempfile.TemporaryDirectory(prefix="simfab-bench-sweep-") as tmp:
        out["cluster_start_seconds"] = time.perf_counter() - t0
        out["overhead"] = _overhead(client, workers, a.empty_tasks)
        out["insertion_sweep"] = _insertion(client, workers, tmp)
        if not a.skip_crowd:
            out["crowd_study"] = _crowd(client, workers, a.subcrowds)
    out["machine"]["load_average_1min_at_end"] = os.getloadavg()[0]
    return out
