"""Rest-shape optimization benchmark: the stand-side design end to end.

``python tools/bench.py optimize [--method anneal|gradient] [--scene standside2d] [--iterations N] [--seed S]
[--repeat N]``

Runs what ``simfab couple optimize standside2d`` runs - the initial insertion (for displacement
handle placement), the handle placement (bounded biharmonic weights, affinity propagation), the
annealing with one full insertion simulation per iteration - and reports the wall time, the
simulations run and simulations per second, the fraction of the time spent outside the
simulator, the number of iterations to the first design meeting every constraint and whether
the final design meets them all, with its E_L and handle parameters (``design``: per active handle
its translation [m] and per-axis scales). Outputs are not written (timed is the computation).
``--workers`` (default 2, the machine the target was set for) evaluates that many proposals at
once (simfab.design.parallel: speculative evaluation, the same design as 1 worker); the time
includes starting the workers (started first, as ``couple optimize`` does: their start-up overlaps
the initial insertion and the handle placement). Then, as ``couple optimize`` does, the design's mesh check on
refined meshes (and correction rounds if needed), timed separately (``mesh_check``). ``--repeat N``
(default REPEAT) runs the optimization N times, after the first each in a fresh process, and
reports the fastest run (``seconds_all_runs``, ``seconds_median`` and each run's machine
reference too); the runs must reach the same design.

``--method gradient`` runs the trust-region SQP on the adjoint sensitivities (:mod:`simfab.design.gradient`)
instead of the annealing (one process; ``--iterations`` caps the SQP's iterations, one insertion each);
``insertions`` counts every insertion simulation of the optimization (complete, stopped early, speculative;
the placement's initial insertion and the mesh check excluded; the gradient method reuses that insertion,
recorded, as its first), ``gradient_evaluations`` those that gave gradients.

Reference: the original method's 4.8 s per stand-side insertion simulation (shared reference
figures, "insertion_simulation_seconds_original", row "stand side (2D)") times its up to 300
iterations (~24 minutes); the target here is <= 30 s for the whole optimization.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from simfab.errors import InputError

TARGET_SECONDS = {"anneal": 30.0, "gradient": 10.0}
#: Runs by default: the machine's speed drifts by up to 2x within minutes (``machine_reference_ms``
#: shows it) and interference only ever adds time, so the fastest of the runs is the best estimate
#: of the cost (as timeit and pyperf advise; the insertion benchmark does the same).
REPEAT = 2


def run(argv) -> dict:
    ap = argparse.ArgumentParser(prog="bench.py optimize")
    ap.add_argument("--scene", default="standside2d")
    ap.add_argument("--method", choices=["anneal", "gradient"], default="anneal",
                    help="optimizer: simulated annealing or a trust-region SQP on the adjoint sensitivities")
    ap.add_argument("--iterations", type=int, default=None, help="annealing iterations (default: the brief's)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2,
                    help="processes evaluating proposals (speculative lookahead; same result as 1)")
    ap.add_argument("--no-mesh-check", action="store_true",
                    help="skip the mesh check (and correction rounds) that couple optimize runs after the annealing")
    ap.add_argument("--repeat", type=int, default=REPEAT,
                    help=f"runs of the optimization, each after the first in a fresh process (default {REPEAT}): "
                         "the fastest one's figures are reported, every run's seconds too")
    a = ap.parse_args(argv)
    if a.repeat < 1:
        raise InputError(f"must be >= 1, got {a.repeat}", where="--repeat")
    out = _run_once(a)
    return out if a.repeat == 1 else _fastest(a, out)


def _fastest(a, first: dict) -> dict:
    """``first`` (this process's run, with the mesh check) and a.repeat - 1 runs in fresh processes
    (each pays its own imports and worker start-up, as a user's run does): the fastest run's
    figures with the mesh check of the first, every run's seconds and machine reference. Every
    run must reach the same design (the optimization is seeded; a difference is an error)."""
    cmd = [sys.executable, str(Path(__file__).resolve().parents[1] / "bench.py"), "optimize", "--repeat", "1",
           "--no-mesh-check", "--scene", a.scene, "--seed", str(a.seed), "--workers", str(a.workers),
           "--method", a.method]
    if a.iterations is not None:
        cmd += ["--iterations", str(a.iterations)]
    runs = [first]
    for _ in range(a.repeat - 1):
        # (the child's stderr shows)
        child = json.loads(subprocess.run(cmd, stdout=subprocess.PIPE, text=True, check=True).stdout)
        if (child["E_L"], child["design"], child["simulations"], child["feasible"]) != (
                first["E_L"], first["design"], first["simulations"], first["feasible"]):
            raise RuntimeError(f"a repeated run reached another design: E_L {child['E_L']} vs {first['E_L']}, "
                               f"{child['simulations']} vs {first['simulations']} simulations")
        runs.append(child)
    best = dict(min(runs, key=lambda r: r["seconds"]))
    check = first["mesh_check"]
    best.update(mesh_check=check, seconds_with_mesh_check=best["seconds"] + check["seconds"] if check else None,
                meets_target=best["meets_target"] and (check is None or bool(check["feasible_mesh_converged"])),
                seconds_all_runs=[r["seconds"] for r in runs],
                seconds_median=statistics.median(r["seconds"] for r in runs),
                machine_reference_ms_all_runs=[r["machine_reference_ms"] for r in runs])
    return best


def _run_once(a) -> dict:
    """One timed optimization in this process (and the mesh check unless a.no_mesh_check)."""
    from benchmarks._machine import machine_reference_ms
    from benchmarks._reference import figures
    from simfab.coupling.simulate import simulate_insertion
    from simfab.design.gradient import design_recorder, optimize_gradient
    from simfab.design.optimize import optimize_anneal
    from simfab.design.outputs import insertions
    from simfab.design.parallel import Workers
    from simfab.design.problem import ProblemSource, make_problem
    from simfab.design.scene import load_design_scene

    ds = load_design_scene(a.scene)
    simulate_insertion(ds.cm)  # warm-up: Warp kernels loaded, caches built (not timed)
    ref_before = machine_reference_ms()
    t0, c0 = time.perf_counter(), time.process_time()
    ds = load_design_scene(a.scene)
    t_load = time.perf_counter() - t0
    workers = a.workers if a.method == "anneal" else 1
    with Workers(workers) if workers > 1 else contextlib.nullcontext(1) as procs:
        # as `couple optimize`: the workers start while this process places the handles
        t1 = time.perf_counter()
        # (the gradient method reuses this insertion of the initial shape, recorded, as couple optimize does)
        rec = design_recorder(ds.cm, ds.brief) if a.method == "gradient" else None
        initial = simulate_insertion(ds.cm, recorder=rec)
        problem = make_problem(ds.cm, ds.brief, kept_regions=ds.kept_regions, target=ds.target, initial=initial,
                               seed=a.seed, source=ProblemSource(scene=str(ds.xml)), initial_recorder=rec)
        t_setup = time.perf_counter() - t1
        if a.method == "gradient":
            res = optimize_gradient(problem, iterations=a.iterations, seed=a.seed)
        else:
            res = optimize_anneal(problem, iterations=a.iterations, seed=a.seed, workers=procs)
        total = time.perf_counter() - t0
        cpu = time.process_time() - c0
        ref_after = machine_reference_ms()
        check = None
        if not a.no_mesh_check:  # what `couple optimize` runs next (simfab.design.pipeline)
            from simfab.design.pipeline import mesh_corrected

            t2 = time.perf_counter()
            _, mc, rounds = mesh_corrected(res, a.seed, procs, True)
            check = {"seconds": time.perf_counter() - t2, "feasible_mesh_converged": mc.feasible_fine,
                     "correction_rounds": len(rounds), "elements": [lv.elements for lv in mc.levels],
                     "constraints_mesh_converged": {c.name: c.value for c in mc.constraints}}
    first = next((r["k"] for r in res.history if r["evaluation"].feasible), None)
    ins = insertions(res)
    done = [r["evaluation"] for r in res.history[1:] if r["evaluation"].status == "ok"]
    # the initial insertion (run for the placement) is the optimizer's initial evaluation (reused)
    sims = res.simulations + (0 if problem.initial is initial else 1)
    sim_seconds = res.sim_seconds + (0.0 if problem.initial is initial else initial.seconds)
    ref = figures().get("insertion_simulation_seconds_original")
    row = next((r for r in (ref or {}).get("rows", []) if r["model"].startswith("stand side")), None)
    ref_total = row["seconds"] * 300 if row else None
    return {
        "benchmark": "optimize",
        "scene": a.scene,
        "method": res.method,
        "elements": int(ds.cm.fem.n_elements),
        "steps": int(len(ds.cm.s_steps) - 1),
        "handles": int(problem.handles.n_active),
        "seconds": total,
        "cpu_seconds": cpu,  # process CPU time: less sensitive to other load on the machine
        "seconds_setup": t_load + t_setup,
        "iterations": res.iterations,
        "stopped_early": res.stopped_early,
        "first_feasible_iteration": first,
        "feasible": res.best.feasible,
        "E_L": res.best.E_L,
        "design": res.best.h.tolist(),  # the best design's handle parameters (translations [m], scales)
        "insertions": ins,
        "gradient_evaluations": res.gradient_evaluations,
        "nonsmooth_events": res.events,
        "simulations": sims,
        "simulations_stopped_early": res.stopped_simulations,
        "workers": res.workers,
        "speculative_simulations": res.speculative,  # run ahead on a worker, not needed
        "acceptance_branches": {"drawn": res.branches[0], "adopted": res.branches[1]},
        "load_average_1min": os.getloadavg()[0],
        # the machine's momentary speed before and after the timed run (benchmarks._machine; ~25 ms usual)
        "machine_reference_ms": [ref_before, ref_after],
        "candidates_rejected_before_simulating": sum(1 for r in res.history if r["evaluation"].sim_seconds == 0),
        "simulations_per_second": (sims + res.stopped_simulations) / total,  # full + stopped early
        "seconds_per_simulation": sim_seconds / (sims + res.stopped_simulations),
        # machine-independent: Newton iterations per complete insertion of a candidate
        "newton_iterations_per_simulation": float(np.mean([ev.newton_iterations for ev in done])) if done else None,
        # the share of the processes' wall time not spent simulating (workers x wall)
        "fraction_outside_simulator": max(0.0, 1.0 - sim_seconds / (total * res.workers)),
        "rejected": res.rejected,
        "target_seconds": TARGET_SECONDS[a.method],
        # (and, when the mesh check runs, the design meets the brief on it)
        "meets_target": total <= TARGET_SECONDS[a.method] and res.best.feasible and (
            check is None or bool(check["feasible_mesh_converged"])),
        "reference": {"source": "insertion_simulation_seconds_original: stand side (2D) x 300 iterations",
                      "seconds_per_simulation": row["seconds"] if row else None, "seconds": ref_total},
        "speedup_vs_reference": ref_total / total if ref_total else None,
        # after the annealing: the mesh check of the design on refined meshes (and any correction rounds)
        "mesh_check": check,
        "seconds_with_mesh_check": total + check["seconds"] if check else None,
    }
