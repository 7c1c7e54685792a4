"""Insertion-simulation benchmark: wall time of full insertions at the original's model sizes.

``python tools/bench.py insertion [--only NAME,...] [--repeat K | --budget SECONDS] [--max-repeat K]``

Cases (bundled scenes, closest to the sizes of the thesis' timing table):
  cclamp2d  (450 6-node triangles, 35 steps) vs "stand side (2D)"  450 elements, 35 steps
            (run at the original's size on P2, within 1% of the mesh-converged figures; the
            bundled scene is 4,800 linear triangles, within 5%)
  clip3d    (~1080 10-node tets, 35 steps) vs "alligator 3D"  1040 elements, 35 steps
            (run at the original's size: one layer of ~360 triangles; the bundled scene is finer)
  knocker3d (5,220 10-node tets in 2 layers, 40 steps; bundled: 8,181 in 3, 80 steps) vs "door knocker"
            5080 elements, 40 steps
  claw3d    (5,130 10-node tets, 25 steps) vs "claw 3D"     12063 elements, 25 steps
            (the 3D scenes run quadratic tets, as bundled: claw3d on its bundled mesh with an
            exact ball, within 3.5% of its mesh-converged figures where linear tets were 40-44% too
            stiff; knocker3d
            at 2 layers, 2-5% above 8 layers; clip3d at the original's size, one layer, ~3% on
            E_max and forces, ~11% on the grip: see scenes/coupling/README.md)
Each row reports the simulation seconds (fastest run; scene loading and meshing excluded, as in
the original's per-iteration cost; the median and every run's time too), the original's seconds
(``figures.json``), the speed-up ratio original/ours, Newton iterations and the time split (FEM
assembly, sparse factorization + solve, contact = IMLS evaluation + barrier; "other", the wall
time minus the three, is predictor, refinement checks and Python overhead), and the same wall time
split by phase of the insertion loop (warm_start, newton, facet_check, record, rigid_check, other).
The process CPU time, the load average and the time of a fixed reference workload are reported
too: on a shared (virtual) machine the same run's wall time moves with the machine's momentary
speed, and the reference workload's time moves with it.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

from benchmarks._machine import machine_reference_ms

CASES = [
    ("cclamp2d", "stand side (2D)"),
    ("clip3d", "alligator 3D"),
    ("knocker3d", "door knocker (rotating path)"),
    ("claw3d", "claw 3D"),
]
#: Scene overrides that put a case at the original's size (the bundled cclamp2d is meshed finer,
#: ~4,800 linear triangles, to be within 5% of its mesh-converged figures; the original's row is
#: 450, where linear triangles are 36% too stiff and 6-node ones within 1%: the case runs those).
ORIGINAL_SIZE = {"cclamp2d": {"compliant": {"target_elements": 450}, "simulation": {"element_order": 2}},
                 # the bundled clip3d is an extrusion of 782 triangles in 2 layers (4,692 P2 tets)
                 "clip3d": {"compliant": {"target_elements": 1040, "layers": 1, "segments": 48}},
                 # the bundled knocker3d is 8,181 tets in 3 layers and takes 80 steps (at 40 its
                 # step-work check warns; its figures are within 2.6% of 160 steps' at 40 and 2.4% at
                 # 80): the original's size here, 2 layers and 40 steps
                 "knocker3d": {"compliant": {"target_elements": 4275, "layers": 2}, "simulation": {"steps": 40}}}

TARGET_SPEEDUP = 50.0
#: Without --repeat, each case runs until BUDGET_SECONDS of runs are spent (at least MIN_REPEAT,
#: at most MAX_REPEAT runs) and the fastest run counts, as timeit and pyperf advise: on a shared
#: machine interference only ever adds time, so the minimum is the best estimate of the cost.
BUDGET_SECONDS = 10.0
MIN_REPEAT = 2
MAX_REPEAT = 15


def _runs_wanted(a, runs: list) -> int:
    """How many runs the case should have, given the seconds of those done so far."""
    if a.repeat is not None:
        return max(1, a.repeat)
    if len(runs) < MIN_REPEAT:
        return MIN_REPEAT
    return len(runs) + 1 if sum(runs) < a.budget and len(runs) < a.max_repeat else len(runs)


def run(argv) -> dict:
    from benchmarks._reference import figures

    from simfab.contact.sdf import PrimitiveField
    from simfab.coupling.outputs import summarize
    from simfab.coupling.scene import load_coupling_scene
    from simfab.coupling.simulate import simulate

    ap = argparse.ArgumentParser(prog="bench insertion")
    ap.add_argument("--only", default=None, help="comma-separated scene names")
    ap.add_argument("--repeat", type=int, default=None,
                    help="runs per case, the fastest counts (default: as many as fit in --budget)")
    ap.add_argument("--budget", type=float, default=BUDGET_SECONDS,
                    help="seconds of runs per case when --repeat is not given (at least 2 runs)")
    ap.add_argument("--max-repeat", type=int, default=MAX_REPEAT, help="at most this many runs per case")
    a = ap.parse_args(argv)
    only = set(a.only.split(",")) if a.only else None
    ref_rows = {r["model"]: r for r in figures().get("insertion_simulation_seconds_original", {}).get("rows", [])}
    rows = []
    for scene, ref_name in CASES:
        if only and scene not in only:
            continue
        cm = load_coupling_scene(scene, overrides=ORIGINAL_SIZE.get(scene))
        best = None
        runs = []
        while len(runs) < _runs_wanted(a, runs):
            t0, c0 = time.perf_counter(), time.process_time()
            res = simulate(cm)
            dt, dc = time.perf_counter() - t0, time.process_time() - c0
            runs.append(dt)
            if best is None or dt < best[0]:
                best = (dt, dc, res)
        dt, dc, res = best
        _, summ = summarize(res)
        ref = ref_rows.get(ref_name, {})
        ref_s = ref.get("seconds")
        t = dict(res.timings)
        split = {k: round(float(t.get(k, 0.0)), 3) for k in ("assembly", "factorization", "contact")}
        split["other"] = round(float(dt - sum(split.values())), 3)
        rows.append({
            "scene": scene,
            "elements": int(cm.fem.n_elements),
            # IMLS samples of a mesh object (None: primitives, exact signed distance)
            "object_samples": None if isinstance(cm.field, PrimitiveField) else int(len(cm.field.vertices)),
            "steps": len(cm.s_steps) - 1,
            "seconds": round(dt, 3),
            "seconds_median": round(statistics.median(runs), 3),
            "seconds_all_runs": [round(v, 3) for v in runs],
            "cpu_seconds": round(dc, 3),
            "machine_reference_ms": machine_reference_ms(),
            "load_average_1min": round(os.getloadavg()[0], 2),
            "newton_iterations": summ["newton_iterations"],
            "newton_iterations_per_step": round(summ["newton_iterations"] / max(1, len(res.steps) - 1), 2),
            "steps_run": len(res.steps) - 1,
            "category": summ["category"],
            "time_split_seconds": split,
            "phase_split_seconds": {k: round(float(v), 3) for k, v in res.phases.items()},
            "reference_model": ref_name,
            "reference_elements": ref.get("elements"),
            "reference_steps": ref.get("steps"),
            "reference_seconds": ref_s,
            "speedup": round(ref_s / dt, 2) if ref_s else None,
            "speedup_cpu_time": round(ref_s / dc, 2) if ref_s else None,
            "target_speedup": TARGET_SPEEDUP,
            "meets_target": bool(ref_s and ref_s / dt >= TARGET_SPEEDUP),
        })
    return {"benchmark": "insertion", "reference": "figures.json: insertion_simulation_seconds_original "
            "(SQP + MOSEK, 3.2 GHz i5)", "machine": "2 cores, CPU only", "rows": rows}
