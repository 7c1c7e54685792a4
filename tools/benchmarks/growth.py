"""Growth benchmark: seconds per growth (2000 attractors) and per skin, every bundled scene,
and the growth time's scaling with the attractor count on phone_stand.

``python tools/bench.py growth [--repeats R] [--attractors N] [--scenes a,b,...] [--scaling N1,N2,...]``

For each scene in ``scenes/growth`` the full growth (attractor placement, colonization,
pruning, smoothing; all stages for guided scenes) and the skin (union, carving, STL
cleanup and the round-trip checks) are timed for seeds 0..R-1 after one warm-up run.
Reported per scene: median and max wall seconds (and process CPU seconds, less sensitive to
other load on the machine), nodes, segments, targets reached, and whether the targets
(growth <= 0.3 s per growth -- a guided scene grows once per stage --, skin <= 1 s) are met. The
reference is the original method's total run time per growth with 2000 attractors ("growth_seconds_original" in the
shared reference figures; "<1" entries are taken as 1 s, an upper bound), compared with
our growth + skin time.

Scaling (``--scaling``, default 2000,20000,200000; ``--scaling ""`` skips it): phone_stand grown
with each attractor count (seeds 0..R-1, after the warm-up), one row per count with its
median wall and process CPU seconds, nodes grown, steps and stop reason (the node cap raised to
2 n so that the largest count grows to the end); the exponent p of seconds ~ n^p is fitted
between consecutive counts. Target: 20,000 attractors <= 0.5 s of growth.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import time

from simfab._bundled import scenes_dir
from simfab.errors import InputError

TARGET_GROWTH_SECONDS = 0.3
TARGET_SKIN_SECONDS = 1.0
TARGET_20K_SECONDS = 0.5
SCALING_SCENE = "phone_stand"

SCENES = scenes_dir("growth")


def _seconds(v) -> float:
    """A reference table entry: a number of seconds or '<1' (taken as its bound)."""
    if isinstance(v, (int, float)):
        return float(v)
    return float(str(v).lstrip("<").strip())


def _reference():
    from benchmarks._reference import figures

    ref = figures().get("growth_seconds_original")
    if not ref:
        return None, None
    per_example = {row["example"]: statistics.median(_seconds(s) for s in row["seconds"]) for row in ref["rows"]}
    return ref, per_example


def run(argv) -> dict:
    ap = argparse.ArgumentParser(prog="bench.py growth")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--attractors", type=int, default=2000)
    ap.add_argument("--scenes", default=None, help="comma-separated scene names (default: all)")
    ap.add_argument("--scaling", default="2000,20000,200000",
                    help=f"comma-separated attractor counts grown on {SCALING_SCENE} (empty: skip)")
    a = ap.parse_args(argv)
    try:
        counts = [int(c) for c in a.scaling.split(",") if c.strip()]
    except ValueError:
        raise InputError(f"--scaling: expected comma-separated integers, got {a.scaling!r}") from None
    if any(c < 1 for c in counts):
        raise InputError(f"--scaling: attractor counts must be positive, got {a.scaling!r}")

    from simfab.growth import grow, load_growth_scene, skin_result

    names = a.scenes.split(",") if a.scenes else sorted(p.stem for p in SCENES.glob("*.xml"))
    out = {}
    warm = load_growth_scene(SCENES / f"{names[0]}.xml")
    skin_result(grow(warm, seed=0, attractors=a.attractors))  # imports, caches
    for name in names:
        scene = load_growth_scene(SCENES / f"{name}.xml")
        tg, ts, cg, cs, rows = [], [], [], [], []
        for seed in range(a.repeats):
            t0, c0 = time.perf_counter(), time.process_time()
            r = grow(scene, seed=seed, attractors=a.attractors)
            tg.append(time.perf_counter() - t0)
            cg.append(time.process_time() - c0)
            t0, c0 = time.perf_counter(), time.process_time()
            mesh, rep, _ = skin_result(r)
            ts.append(time.perf_counter() - t0)
            cs.append(time.process_time() - c0)
            s = r.summary()
            rows.append((s, rep))
        s0 = rows[0][0]
        stages = len(s0["stop_reasons"])  # a guided scene grows once per stage (each with its own attractors)
        out[name] = {
            "mode": s0["mode"],
            "growth_seconds_median": statistics.median(tg),
            "growth_seconds_max": max(tg),
            "skin_seconds_median": statistics.median(ts),
            "skin_seconds_max": max(ts),
            "growth_cpu_seconds_median": statistics.median(cg),
            "skin_cpu_seconds_median": statistics.median(cs),
            "stages": stages,
            "growth_seconds_per_stage_median": statistics.median(tg) / stages,
            "nodes_grown": s0["nodes_grown"],
            "segments": s0["segments"],
            "targets": f"{min(r[0]['targets_reached'] for r in rows)}/{s0['targets_total']}",
            "skins_ok": all(r[1].ok for r in rows),
            "growth_target_met": statistics.median(tg) / stages <= TARGET_GROWTH_SECONDS,
            "skin_target_met": statistics.median(ts) <= TARGET_SKIN_SECONDS,
        }
    scaling = _scaling(counts, a.repeats)
    ref, per_example = _reference()
    ours_total = [v["growth_seconds_median"] + v["skin_seconds_median"] for v in out.values()]
    result = {
        "benchmark": "growth",
        "load_average_1min": os.getloadavg()[0],
        "cpus": os.cpu_count(),
        "attractors": a.attractors,
        "repeats": a.repeats,
        "targets_seconds": {"growth": TARGET_GROWTH_SECONDS, "skin": TARGET_SKIN_SECONDS},
        "scenes": out,
        "all_growth_targets_met": all(v["growth_target_met"] for v in out.values()),
        "all_skin_targets_met": all(v["skin_target_met"] for v in out.values()),
        "ours_total_seconds_range": [min(ours_total), max(ours_total)],
        "scaling": scaling,
    }
    row20k = next((r for r in scaling["rows"] if r["attractors"] == 20000), None)
    if row20k is not None:
        result["growth_20k_seconds_median"] = row20k["growth_seconds_median"]
        result["growth_20k_target_met"] = row20k["growth_seconds_median"] <= TARGET_20K_SECONDS
    if ref is not None:
        orig = list(per_example.values())
        result["reference"] = {
            "name": "growth_seconds_original",
            "about": ref.get("_about"),
            "median_seconds_per_example": per_example,
            "note": "'<1' entries taken as 1 s (upper bound); the original's examples are other models than ours",
        }
        result["ratio_original_median_over_ours_median"] = statistics.median(orig) / statistics.median(ours_total)
        result["ratio_original_slowest_over_ours_slowest"] = max(orig) / max(ours_total)
    return result


def _scaling(counts: list[int], repeats: int) -> dict:
    """Growth seconds of :data:`SCALING_SCENE` per attractor count, and the exponents between counts."""
    from simfab.growth import grow, load_growth_scene

    scene = load_growth_scene(SCENES / f"{SCALING_SCENE}.xml")
    rows = []
    for n in counts:
        t, c = [], []
        for seed in range(repeats):
            t0, c0 = time.perf_counter(), time.process_time()
            r = grow(scene, seed=seed, attractors=n, max_nodes=max(scene.params.max_nodes, 2 * n))
            t.append(time.perf_counter() - t0)
            c.append(time.process_time() - c0)
        s = r.summary()
        rows.append({"attractors": n, "growth_seconds_median": statistics.median(t), "growth_seconds_max": max(t),
                     "growth_cpu_seconds_median": statistics.median(c),
                     "nodes_grown": s["nodes_grown"], "steps": s["steps"], "stop_reasons": s["stop_reasons"],
                     "targets": f"{s['targets_reached']}/{s['targets_total']}"})
    pairs = [(a, b) for a, b in zip(rows, rows[1:]) if b["attractors"] != a["attractors"]]
    exps = [math.log(b["growth_seconds_median"] / a["growth_seconds_median"])
            / math.log(b["attractors"] / a["attractors"]) for a, b in pairs]
    return {"scene": SCALING_SCENE, "target_seconds_at_20000": TARGET_20K_SECONDS, "rows": rows,
            "exponent_between_counts": exps}
