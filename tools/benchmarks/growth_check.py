"""Structural check of every bundled growth scene, before and after strengthening.

``python tools/bench.py growth_check [--scenes a,b,...] [--strengthen SF] [--thin] [--rounds K] [--seed S]``

For each scene in ``scenes/growth``: grow (the scene's attractors, seed S), check the support
under its objects' weights, its own weight and its ``[loads]`` (:func:`simfab.growth.structure.
check_structure`), then :func:`~simfab.growth.structure.strengthen` to safety factor SF (default
2; ``--thin``: thinning over-strong branches too, at most K rounds). One row per scene: safety
factor, peak von Mises stress (critical-distance mean) [Pa], largest target deflection [m],
mass [kg], check seconds, before and after, and the number of checks strengthening took.
Target: the phone stand's check <= 30 s. No published reference exists for this figure (the
thesis leaves structural soundness to the user).
"""

from __future__ import annotations

import argparse
import os
import time

from simfab._bundled import scenes_dir

TARGET_CHECK_SECONDS = 30.0


def _row(c) -> dict:
    return {"safety_factor": c.safety_factor, "max_von_mises_Pa": c.max_von_mises_Pa,
            "max_deflection_m": max(c.deflection_m.values(), default=0.0), "mass_kg": c.mass_kg,
            "tets": c.tets, "seconds": c.seconds}


def run(argv) -> dict:
    ap = argparse.ArgumentParser(prog="bench.py growth_check")
    ap.add_argument("--scenes", default=None, help="comma-separated scene names (default: all)")
    ap.add_argument("--strengthen", type=float, default=2.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--thin", action="store_true")
    ap.add_argument("--rounds", type=int, default=5)
    a = ap.parse_args(argv)

    from simfab.growth import grow, load_growth_scene
    from simfab.growth.structure import check_structure, strengthen

    d = scenes_dir("growth")
    names = a.scenes.split(",") if a.scenes else sorted(p.stem for p in d.glob("*.xml"))
    rows = {}
    for name in names:
        scene = load_growth_scene(d / f"{name}.xml")
        r = grow(scene, seed=a.seed)
        c = check_structure(r.skeleton, scene)
        t0 = time.perf_counter()
        st = strengthen(r.skeleton, scene, a.strengthen, check=c, thin=a.thin, rounds=a.rounds)
        rows[name] = {"before": _row(c), "after": _row(st.check), "checks": len(st.history), "reached": st.reached,
                      "strengthen_seconds": time.perf_counter() - t0,
                      "volume_change": st.summary()["volume_change"]}
    out = {"benchmark": "growth_check", "load_average_1min": os.getloadavg()[0], "cpus": os.cpu_count(),
           "seed": a.seed, "strengthen": a.strengthen, "thin": a.thin, "rounds": a.rounds, "scenes": rows,
           "target_check_seconds": TARGET_CHECK_SECONDS, "reference": None}
    if "phone_stand" in rows:
        out["phone_stand_check_seconds"] = rows["phone_stand"]["before"]["seconds"]
        out["phone_stand_check_target_met"] = rows["phone_stand"]["before"]["seconds"] <= TARGET_CHECK_SECONDS
    return out
