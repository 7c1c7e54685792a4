"""Growth benchmark: seconds per growth (2000 attractors) and per skin, every bundled scene.

``python tools/bench.py growth [--repeats R] [--attractors N] [--scenes a,b,...]``

For each scene in ``scenes/growth`` the full growth (attractor placement, colonization,
pruning, smoothing; all stages for guided scenes) and the skin (union, carving, STL
cleanup and the round-trip checks) are timed for seeds 0..R-1 after one warm-up run.
Reported per scene: median and max wall seconds (and process CPU seconds, less sensitive to
other load on the machine), nodes, segments, targets reached, and whether the targets (growth
<= 0.3 s per growth -- a guided scene grows once per stage --, skin <= 1 s) are met. The
reference is the original method's total run time per growth with 2000 attractors
("growth_seconds_original" in the shared reference figures; "<1" entries are taken as 1 s, an
upper bound), compared with our growth + skin time.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

from simfab._bundled import scenes_dir

TARGET_GROWTH_SECONDS = 0.3
TARGET_SKIN_SECONDS = 1.0

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
    a = ap.parse_args(argv)

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
    }
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
