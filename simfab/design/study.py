"""The handle-placement study (thesis, "Shape Modification", Figure "handle placements").

For each handle count K: one optimization with displacement-based placement, one with spatial
clustering and ``randoms`` with random placements (seeds 0..randoms-1), all with the same brief,
objective and annealing settings. Reported per (method, K): the fraction of runs whose best design
meets every constraint ("converged") and the final modification energy E_L (median over the
converged runs, and the best). Every optimization is one independent task, run on Dask
(:func:`simfab.sweep.run_tasks`: a local cluster by default, or ``scheduler``).
"""

from __future__ import annotations

import math
import statistics
from pathlib import Path

import numpy as np

from simfab._warp import device as check_device
from simfab.design.optimize import optimize_anneal
from simfab.design.problem import make_problem
from simfab.design.scene import load_design_scene
from simfab.io.atomic import atomic_paths, save_figure, write_csv, write_json
from simfab.io.outpaths import make_out_dir
from simfab.sweep import run_tasks

METHODS = ("displacement", "spatial", "random")


def iterations_per_handle_budget(brief, handles: int) -> int:
    """Annealing iterations for an optimization with ``handles`` active handles at the budget per
    handle of ``brief`` (a :class:`simfab.design.brief.DesignConfig`: its ``iterations`` for its
    ``handles``): round(iterations * handles / brief.handles), at least 1.

    A comparison of handle counts gives each the same iterations per design variable (2 d per
    handle: a translation and a scale per axis). The annealer moves about one handle per proposal
    (:mod:`simfab.design.anneal`), so a handle is proposed ~iterations / handles times, and the
    progress per iteration of a random-walk search falls as 1 / variables (an adaptive-step
    (1+1) search on a quadratic needs O(n log(1 / eps)) iterations for n variables): with one
    budget for every count the largest count stops furthest from its optimum
    (tests/design/test_handle_budget.py shows it on a least-squares stand-in with a known optimum). The
    mesh check's correction rounds (half the budget each,
    :func:`simfab.design.pipeline.mesh_corrected`) scale with it."""
    return max(1, round(brief.iterations * int(handles) / brief.handles))


def run_one(*, scene: str, design: dict, simulation: dict, method: str, count: int, seed: int) -> dict:
    """One optimization of the study (a Dask task): returns its figures."""
    check_device("cpu")
    ds = load_design_scene(scene, design=dict(design, handles=count, placement=method), simulation=simulation)
    problem = make_problem(ds.cm, ds.brief, kept_regions=ds.kept_regions, target=ds.target, seed=seed)
    res = optimize_anneal(problem, seed=seed)
    return {"method": method, "handles": count, "seed": seed, "converged": bool(res.best.feasible),
            "E_L": float(res.best.E_L), "objective": float(res.best.objective), "iterations": res.iterations,
            "simulations": res.simulations, "seconds": res.seconds,
            "handle_vertices": [int(v) for v in problem.handles.vertex[problem.handles.active]]}


def handle_study(scene, *, out, counts=(2, 4, 6), randoms: int = 10, design: dict | None = None,
                 simulation: dict | None = None, seed: int = 0, quiet: bool = True,
                 scheduler: str | None = None) -> dict:
    """Run the study and write ``NAME_handle_study.csv`` (one row per run), ``..._summary.csv``,
    ``.png`` and ``.json`` into ``out``; returns the summary."""
    out = make_out_dir(out)
    ds = load_design_scene(scene, design=design, simulation=simulation)  # validates before any task runs
    name = ds.cm.name
    scene_path = str(ds.xml)
    tasks = []
    for k in counts:
        for method in METHODS:
            seeds = range(seed, seed + randoms) if method == "random" else [seed]
            tasks += [dict(scene=scene_path, design=dict(design or {}), simulation=dict(simulation or {}),
                           method=method, count=int(k), seed=int(s)) for s in seeds]
    results = run_tasks(run_one, tasks, scheduler=scheduler, quiet=quiet, desc=f"handle study {name}")
    runs = []
    for t, r in zip(tasks, results):
        row = {"method": t["method"], "handles": t["count"], "seed": t["seed"], "status": r.status,
               "message": r.message or ""}
        if r.status == "ok":
            row.update({k: r.value[k]
                        for k in ("converged", "E_L", "objective", "iterations", "simulations", "seconds")})
        else:
            row.update(converged=False, E_L=math.nan, objective=math.nan, iterations=0, simulations=0,
                       seconds=r.seconds)
        runs.append(row)
    rows = study_rows(runs, counts)
    paths = {"runs_csv": out / f"{name}_handle_study.csv", "summary_csv": out / f"{name}_handle_study_summary.csv",
             "plot_png": out / f"{name}_handle_study.png", "summary_json": out / f"{name}_handle_study.json"}
    result = {"scene": name, "rows": rows, "runs": len(runs), "failed_runs": sum(r["status"] != "ok" for r in runs),
              "outputs": {k: str(v) for k, v in paths.items()}, "units": {"E_L": "-"}}
    with atomic_paths(paths) as tmp:
        keys = list(runs[0].keys())
        write_csv(tmp["runs_csv"], keys, ([r[k] for k in keys] for r in runs))
        skeys = list(rows[0].keys())
        write_csv(tmp["summary_csv"], skeys, ([r[k] for k in skeys] for r in rows))
        plot(rows, name, tmp["plot_png"])
        write_json(tmp["summary_json"], result)
    return result


def study_rows(runs: list[dict], counts) -> list[dict]:
    rows = []
    for k in counts:
        for m in METHODS:
            sel = [r for r in runs if r["method"] == m and r["handles"] == k]
            conv = [r for r in sel if r["converged"]]
            el = [r["E_L"] for r in conv]
            rows.append({"method": m, "handles": int(k), "runs": len(sel),
                         "converged_fraction": len(conv) / len(sel) if sel else math.nan,
                         "E_L_median": statistics.median(el) if el else math.nan,
                         "E_L_best": min(el) if el else math.nan})
    return rows


def plot(rows: list[dict], name: str, path) -> Path:
    import matplotlib  # deferred: pyplot costs about a second of start-up, and only plotting needs it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9.6, 3.8), dpi=120)
    counts = sorted({r["handles"] for r in rows})
    w = 0.8 / len(METHODS)
    for i, m in enumerate(METHODS):
        sel = [next(r for r in rows if r["method"] == m and r["handles"] == k) for k in counts]
        x = np.arange(len(counts)) + (i - 1) * w
        a1.bar(x, [100 * r["converged_fraction"] for r in sel], w, label=m)
        a2.bar(x, [r["E_L_median"] for r in sel], w, label=m)
    for a in (a1, a2):
        a.set_xticks(np.arange(len(counts)), [str(k) for k in counts])
        a.set_xlabel("active handles")
        a.legend(fontsize=8)
    a1.set_ylabel("runs meeting every constraint [%]")
    a1.set_ylim(0, 105)
    a2.set_ylabel("final E_L, median of converged runs [-]")
    fig.suptitle(f"{name}: handle placement study (random: several seeds per count)")
    fig.tight_layout()
    return save_figure(fig, path, close=True)
