"""Interleaved A/B of the insertion loop's CPU time between two source trees, in one process.

Each round imports one tree's ``simfab`` (the other's modules dropped from ``sys.modules``), runs
one untimed insertion (Warp kernels, CHOLMOD) and then ``--reps`` timed ones on fresh models; the
rounds alternate the order (A B, B A, ...: the tree imported second in a round can run slower). On
a loaded machine the two trees then share its slow and fast moments, which separate processes
minutes apart do not. Also prints machine-independent counts of one run per tree: Python calls
(cProfile), contact-field evaluations and FEM kernel launches, and a hash of the records
(equal hashes: bit-identical records).

    python tools/ab_inprocess.py /work/main /work/wt/branch --scene snapfit2d --friction 0 --rounds 6 --reps 5
    python tools/ab_inprocess.py A B --scene cclamp2d --p2 --rounds 3 --reps 3   # the insertion bench's cclamp2d
"""

from __future__ import annotations

import argparse
import cProfile
import hashlib
import importlib
import os
import pstats
import statistics
import sys
import time

RECORD_FIELDS = ("s", "energy", "force", "path_force", "barrier_energy", "grip", "max_von_mises", "penetration",
                 "min_det_F", "iterations", "contact_points", "kappa", "normal_force", "path_force_friction",
                 "dissipated", "slipping", "lag_solves", "lag_change", "locked")


def _load(root: str):
    """Import ``root``'s simfab (and its tools/benchmarks); return its simulate_insertion."""
    for name in list(sys.modules):
        if name.split(".")[0] in ("simfab", "benchmarks"):
            del sys.modules[name]
    sys.path[:2] = [root, os.path.join(root, "tools")]
    importlib.invalidate_caches()
    from simfab.coupling.simulate import simulate_insertion

    return simulate_insertion


def _model(args):
    if args.scene == "snapfit2d":
        from benchmarks import peer

        return peer.case_model("snapfit2d", args.friction)
    from simfab.coupling.scene import load_coupling_scene

    over = {"contact": {"friction": args.friction}}
    if args.p2:
        over |= {"compliant": {"target_elements": 450}, "simulation": {"element_order": 2}}
    return load_coupling_scene(args.scene, overrides=over)


def _counts(simulate, args) -> dict:
    import numpy as np

    import simfab.fem.workspace as W

    cm = _model(args)
    n = {"field_evaluations": 0, "fem_launches": 0}
    field_type, evaluate, command = type(cm.field), type(cm.field).evaluate, W.Workspace.command

    def counted_evaluate(self, *a, **k):
        n["field_evaluations"] += 1
        return evaluate(self, *a, **k)

    def counted_command(self, *a):
        n["fem_launches"] += 1
        return command(self, *a)

    field_type.evaluate, W.Workspace.command = counted_evaluate, counted_command
    try:
        prof = cProfile.Profile()
        prof.enable()
        res = simulate(cm)
        prof.disable()
    finally:
        field_type.evaluate, W.Workspace.command = evaluate, command
    h = hashlib.sha1()
    for r in [*res.steps, *res.removal]:
        h.update(np.asarray([float(getattr(r, k)) for k in RECORD_FIELDS]).tobytes())
        h.update(r.x.tobytes())
    iterations = sum(r.iterations for r in [*res.steps, *res.removal])
    return {"python_calls": pstats.Stats(prof).total_calls, **n, "newton_iterations": iterations,
            "records_hash": h.hexdigest()[:12]}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trees", nargs=2, help="two source trees (each with simfab/ and tools/benchmarks/)")
    ap.add_argument("--scene", default="snapfit2d", help="snapfit2d (the peer bench's case) or a bundled scene")
    ap.add_argument("--friction", type=float, default=0.0)
    ap.add_argument("--p2", action="store_true", help="the insertion bench's size: 450 P2 elements")
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--reps", type=int, default=5)
    args = ap.parse_args(argv)
    sys.path[:0] = ["", ""]
    times = {t: [] for t in args.trees}
    counts = {}
    for rnd in range(args.rounds):
        for tree in (args.trees if rnd % 2 == 0 else args.trees[::-1]):  # ABBA: neither is always second
            simulate = _load(os.path.abspath(tree))
            simulate(_model(args))  # untimed: kernels, CHOLMOD
            for _ in range(args.reps):
                cm = _model(args)
                c0 = time.process_time()
                simulate(cm)
                times[tree].append(time.process_time() - c0)
            if rnd == 0:
                counts[tree] = _counts(simulate, args)
    for tree in args.trees:
        v = times[tree]
        print(f"{tree}: CPU s median {statistics.median(v):.4f} min {min(v):.4f} (n {len(v)}); {counts[tree]}")
    print(f"load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
