"""Insertion-simulation benchmark: wall time of full insertions at the original's model sizes,
against the factorization floor.

``python tools/bench.py insertion [--only NAME,...] [--repeat K | --budget SECONDS] [--max-repeat K]
[--friction MU]``; ``--scaling [--scenes clip3d,claw3d] [--factors 1,2,4,8] [--frictions 0,0.3]
[--plot PNG] [--repeat K]``: the cost's growth with the mesh (tools/benchmarks/_scaling.py; K runs per level, the
fastest counts).

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

The target is the **factorization floor**: a run that solves S steps (the records after the start pose, the
rest search's included) needs at least S sparse factorizations of its Hessian, so floor = S x (one CHOLMOD
numeric factorization + solve of the case's P2 Hessian on its free dofs, at the run's last state, fastest of
FLOOR_REPEAT after each run, in the same process: :class:`FloorTimer`); ``floor_ratio`` = seconds /
floor_seconds, the target FLOOR_TARGET (``floor_ratio_cpu``: the same in process CPU time, the run's on both
of its threads, steadier when the machine is shared).
The machine-independent counts beside it: Newton's linear solves over every solve of the run (the rest
search's discarded trials included), numeric factorizations per floor step, FEM assembly blocks.
Each row also reports the simulation seconds (fastest run; scene loading and meshing excluded, as in the original's
per-iteration cost; the median and every run's time too), the original's seconds
(``figures.json``) and the speed-up original/ours with the accuracy of both beside it, Newton
iterations and their histogram per step, and the run's wall time split by stage, each second
booked once (``stage_split_seconds``, also per Newton iteration in ms): FEM assembly at Newton
iterates, numeric factorization, solves (triangular solves, the pin's Woodbury update), the contact
field (IMLS evaluations), the barrier (and friction) terms, the line search (trial evaluations
and the step cap), the predictor (the warm start, everything in it), the facet check, the step
record, the rigid-mode check and Python (the rest: Newton's and the loop's own work); the phase
split (warm_start, newton, facet_check, record, rigid_check, other) as before.
The process CPU time, the load average and the time of a fixed reference workload are reported
too: on a shared (virtual) machine the same run's wall time moves with the machine's momentary
speed, and the reference workload's time moves with it.
"""

from __future__ import annotations

import argparse
import collections
import os
import statistics
import time

import numpy as np

from benchmarks._machine import machine_reference_ms
from benchmarks._repeat import add_repeat_options, repeat_rule

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

#: The target: a run within this multiple of its factorization floor (see the module docstring).
FLOOR_TARGET = 5.0
FLOOR_REPEAT = 7
#: Accuracy of each case against its mesh-converged figures (ours) and of the original's linear
#: elements at its size (scenes/coupling/README.md; "+" = too stiff), largest over E_max, F_in, F_rm.
ACCURACY = {
    "cclamp2d": {"ours": "+0.9% (P2, 455 triangles)", "original": "+36% (linear, 455 triangles)"},
    "clip3d": {"ours": "+2.9% (grip +11%; P2, one layer)",
               "original": ">= +11% (linear tets: 28,836 of them were 11% too stiff; 1,040 are stiffer)"},
    "knocker3d": {"ours": "+4.9% (P2, 2 layers)", "original": "+74% (linear, 4,880 tets)"},
    "claw3d": {"ours": "<= 3.5% (P2, 5,130 tets)", "original": "+44% (linear, 12,390 tets)"},
}
STAGES = ("assembly", "factorization", "solves", "contact_field", "barrier", "line_search", "predictor")
PHASE_STAGES = ("facet_check", "record", "rigid_check")
#: Without --repeat, each case runs until --budget seconds of runs are spent (at least MIN_REPEAT,
#: at most --max-repeat runs: benchmarks._repeat; the first run, which pays the process's one-off
#: costs, outside the budget) and the fastest run counts, as timeit and pyperf advise: on a shared
#: machine interference only ever adds time, so the minimum is the best estimate of the cost.
MIN_REPEAT = 2


def run(argv) -> dict:
    from benchmarks._reference import figures
    from simfab.contact.sdf import PrimitiveField
    from simfab.coupling.outputs import summarize
    from simfab.coupling.scene import load_coupling_scene, scene_paths
    from simfab.coupling.simulate import simulate_insertion
    from simfab.errors import InputError
    from simfab.io.outpaths import check_out_file

    ap = argparse.ArgumentParser(prog="bench insertion")
    ap.add_argument("--only", default=None, help="comma-separated scene names")
    add_repeat_options(ap, what="runs", repeat_help="runs per case, the fastest counts (default: as many as fit in "
                       f"--budget, at least {MIN_REPEAT}; with --scaling: runs per level, in rounds of alternating "
                       "order, default 1)")
    ap.add_argument("--friction", type=float, default=None,
                    help="Coulomb friction coefficient mu for every case (default: the scene's)")
    ap.add_argument("--scaling", action="store_true",
                    help="cost growth with the mesh: clip3d and claw3d at 1x..8x their tets (see _scaling.py)")
    ap.add_argument("--scenes", default="clip3d,claw3d", help="--scaling: scenes")
    ap.add_argument("--factors", default="1,2,4,8", help="--scaling: tet-count factors")
    ap.add_argument("--frictions", default="0,0.3", help="--scaling: friction coefficients")
    ap.add_argument("--plot", default=None, help="--scaling: PNG path of the time-vs-dofs plot")
    ap.add_argument("--level-timeout", type=float, default=1800.0, help="--scaling: seconds per level at most")
    ap.add_argument("--scaling-level", default=None, help=argparse.SUPPRESS)  # SCENE:FACTOR:MU, one child
    a = ap.parse_args(argv)
    rule = repeat_rule(a, min_runs=MIN_REPEAT, first_outside_budget=True)
    if a.plot is not None:  # before any level runs (the plot is drawn after the last)
        check_out_file(a.plot, where="--plot", suffixes=(".png",))
    if a.scaling_level:
        from benchmarks._scaling import parse_level, run_level

        return run_level(*parse_level(a.scaling_level))
    if a.scaling:
        from benchmarks._scaling import run_scaling

        try:
            factors = [float(f) for f in a.factors.split(",")]
            frictions = [float(f) for f in a.frictions.split(",")]
        except ValueError:
            raise InputError("--factors and --frictions must be comma-separated numbers") from None
        if not all(0 < f <= 64 for f in factors) or not all(0 <= f < 10 for f in frictions):
            raise InputError(f"--factors must lie in (0, 64] and --frictions in [0, 10), got {a.factors!r} and "
                             f"{a.frictions!r}")
        if not a.level_timeout > 0:
            raise InputError(f"--level-timeout must be > 0 seconds, got {a.level_timeout}")
        scenes = a.scenes.split(",")
        for scene in scenes:  # checked before any level's child process starts
            if not all(p.is_file() for p in scene_paths(scene)):
                raise InputError(f"--scenes: no coupling scene {scene!r} (a bundled name, or NAME.xml with NAME.toml "
                                 "beside it)")
        return run_scaling(scenes, factors, frictions, a.level_timeout, a.plot, repeat=a.repeat or 1)
    if a.friction is not None and not a.friction >= 0:
        raise InputError(f"--friction must be >= 0, got {a.friction}")
    only = set(a.only.split(",")) if a.only else None
    cases = [scene for scene, _ in CASES]
    if only and not only <= set(cases):
        raise InputError(f"--only: no case {sorted(only - set(cases))[0]!r} (the cases: {', '.join(cases)})")
    ref_rows = {r["model"]: r for r in figures().get("insertion_simulation_seconds_original", {}).get("rows", [])}
    rows = []
    for scene, ref_name in CASES:
        if only and scene not in only:
            continue
        over = {k: dict(v) for k, v in ORIGINAL_SIZE.get(scene, {}).items()}
        if a.friction is not None:
            over.setdefault("contact", {})["friction"] = a.friction
        cm = load_coupling_scene(scene, overrides=over)
        best = None
        runs = []
        floor_timer = None
        while len(runs) < rule.wanted(runs):
            t0, c0 = time.perf_counter(), time.process_time()
            res = simulate_insertion(cm)
            dt, dc = time.perf_counter() - t0, time.process_time() - c0
            runs.append(dt)
            if best is None or dt < best[0]:
                best = (dt, dc, res)
            if floor_timer is None:  # (every run ends in the same state: its Hessian is the floor's)
                floor_timer = FloorTimer(cm, res.steps[-1].x)
            floor_timer.sample()  # after every run: the fastest run and the fastest floor from the same phases
        dt, dc, res = best
        _, summ = summarize(res)
        ref = ref_rows.get(ref_name, {})
        ref_s = ref.get("seconds")
        records = list(res.steps[1:]) + list(res.removal)
        fact, fact_cpu = floor_timer.best, floor_timer.best_cpu
        floor, floor_cpu = len(records) * fact, len(records) * fact_cpu
        iters = int(sum(r.iterations for r in records) + res.steps[0].iterations)
        hist = collections.Counter(int(r.iterations) for r in records)
        t = dict(res.timings)
        stages = {k: float(t.get(k, 0.0)) for k in STAGES}
        stages.update({k: float(res.phases.get(k, 0.0)) for k in PHASE_STAGES})
        stages["python"] = dt - sum(stages.values())
        split = {"assembly": t.get("assembly", 0.0),
                 "factorization": t.get("factorization", 0.0) + t.get("solves", 0.0),
                 "contact": t.get("contact_field", 0.0) + t.get("barrier", 0.0)}
        split = {k: round(float(v), 3) for k, v in split.items()}
        split["other"] = round(float(dt - sum(split.values())), 3)
        rows.append({
            "scene": scene,
            "elements": int(cm.fem.n_elements),
            "friction": float(cm.contact.friction),
            # IMLS samples of a mesh object (None: primitives, exact signed distance)
            "object_samples": None if isinstance(cm.field, PrimitiveField) else int(len(cm.field.vertices)),
            "steps": len(cm.s_steps) - 1,
            "seconds": round(dt, 3),
            "floor_seconds": round(floor, 3),
            "floor_ratio": round(dt / floor, 2),
            "target_floor_ratio": FLOOR_TARGET,
            "meets_target": bool(dt <= FLOOR_TARGET * floor),
            # the same in process CPU time (the run's on both threads): steadier on a loaded machine
            "floor_cpu_seconds": round(floor_cpu, 3),
            "floor_ratio_cpu": round(dc / floor_cpu, 2),
            "factorization_ms": round(fact * 1e3, 2),
            "floor_steps": len(records),
            "seconds_median": round(statistics.median(runs), 3),
            "seconds_all_runs": [round(v, 3) for v in runs],
            "cpu_seconds": round(dc, 3),
            "machine_reference_ms": machine_reference_ms(),
            "load_average_1min": round(os.getloadavg()[0], 2),
            "newton_iterations": iters,
            "newton_iterations_per_step": round(iters / max(1, len(records)), 2),
            # over every solve of the run (the rest search's discarded trials included): Newton's
            # linear solves (its iterations, chord steps included), numeric factorizations (failed
            # exact ones included) and timed assembly blocks (FEM evaluations at Newton iterates, the
            # on-demand exact and projected Hessians each one more); per floor step
            "newton_solves_all": int(res.counts.get("solves", 0)),
            "factorizations": int(res.counts.get("factorization", 0)),
            "factorizations_per_step": round(res.counts.get("factorization", 0) / max(1, len(records)), 2),
            "assembly_blocks": int(res.counts.get("assembly", 0)),
            # steps (records after the start) by their Newton iterations, and the share within 1-2
            "newton_histogram": {str(k): hist[k] for k in sorted(hist)},
            "steps_within_2_iterations": round(sum(v for k, v in hist.items() if k <= 2) / max(1, len(records)), 3),
            "steps_run": len(res.steps) - 1,
            "category": summ["category"],
            "stage_split_seconds": {k: round(v, 3) for k, v in stages.items()},
            "stage_ms_per_newton_iteration": {k: round(1e3 * v / max(1, iters), 2) for k, v in stages.items()},
            "time_split_seconds": split,
            "phase_split_seconds": {k: round(float(v), 3) for k, v in res.phases.items()},
            "reference_model": ref_name,
            "reference_elements": ref.get("elements"),
            "reference_steps": ref.get("steps"),
            "reference_seconds": ref_s,
            "speedup": round(ref_s / dt, 2) if ref_s else None,
            "speedup_cpu_time": round(ref_s / dc, 2) if ref_s else None,
            "accuracy": ACCURACY.get(scene),
        })
    return {"benchmark": "insertion", "reference": "figures.json: insertion_simulation_seconds_original "
            "(SQP + MOSEK, 3.2 GHz i5)", "target": f"floor_ratio <= {FLOOR_TARGET:g} (seconds / factorization floor)",
            "machine": "2 cores, CPU only", "rows": rows}


class FloorTimer:
    """One CHOLMOD numeric factorization + solve of the case's Hessian on its free dofs (the PSD FEM
    Hessian at positions x with the rigid-mode regularization: the run's pattern, so the run's
    factorization cost), timed FLOOR_REPEAT times per :meth:`sample` after the symbolic analysis;
    ``best`` / ``best_cpu``: the fastest wall / CPU seconds over every sample. Sampled after each run,
    so that the fastest run and the fastest floor come from the same stretch of the machine's phases
    (a floor timed once, in a few milliseconds after the runs, moved the ratio by up to 1.8x)."""

    def __init__(self, cm, x):
        from simfab.coupling.layout import regularize
        from simfab.fem.elastic import energy_gradient_hessian
        from simfab.solve.linear import SPDSolver

        _, _, self.H = energy_gradient_hessian(cm.fem, np.asarray(x))
        regularize(cm, self.H)
        self.free = np.flatnonzero(np.asarray(cm.free).ravel())
        self.solver = SPDSolver()
        self.b = np.ones(len(self.free))
        self.solver.solve_free(self.H, self.free, self.b)  # symbolic analysis and value map (as every run's)
        self.best, self.best_cpu = np.inf, np.inf

    def sample(self) -> None:
        for _ in range(FLOOR_REPEAT):
            self.H.data *= 1.0 + 1e-9  # new values: a numeric factorization each time
            t0, c0 = time.perf_counter(), time.process_time()
            self.solver.solve_free(self.H, self.free, self.b)
            self.best = min(self.best, time.perf_counter() - t0)
            self.best_cpu = min(self.best_cpu, time.process_time() - c0)
