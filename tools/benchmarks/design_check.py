"""Accuracy per second of the design mesh check's levels (simfab.design.verify): a design scene's
shape (or an optimized scene's) run at linear and P2 levels, each level's figures, seconds and
error against the finest P2 level, and the references the check variants would read.

``python tools/bench.py design_check [--scene standside2d] [--levels 1:0,1:1,1:2,1:3,2:0,2:1,2:2]
[--steps N] [--mesh-check]``

SCENE is a design scene name or an optimized scene's XML (``couple optimize``'s
``NAME_optimized.xml``). A level is ORDER:SUBDIVISIONS (1 linear, 2 quadratic; 2D 4^t, 3D 8^t
the elements). Reported: per level elements, nodes, seconds and the figures the brief reads
(insertion, removal and grip force [N], averaged von Mises stress [Pa], E_max [J]) with their
relative error against the finest P2 level; ``linear_fit``: the old check's reference (f =
f_inf + b h^p through the last three linear levels); ``p2_fit``: the same through three P2
levels. The measurements quoted in simfab/design/verify.py (standside2d, block2d_tight: the
default levels; the knocker design: ``--scene .../knocker3d_design_optimized.xml --levels
1:0,1:1,2:0,2:1``) came from this. ``--mesh-check`` instead runs the check ``couple optimize``
runs on its design (:func:`simfab.design.verify.mesh_check`: the brief's levels, the step check
where the steps do not resolve the profile) on the scene's shape and prints its result.
"""

from __future__ import annotations

import argparse
import time

FIGS = ("insertion_force", "removal_force", "grip_force", "von_mises", "E_max")


def run(argv) -> dict:
    import numpy as np

    from simfab.coupling.converge import extrapolate
    from simfab.coupling.simulate import simulate_insertion
    from simfab.design.scene import load_design_scene
    from simfab.design.verify import level_figures, refined_model

    ap = argparse.ArgumentParser(prog="bench design_check")
    ap.add_argument("--scene", default="standside2d")
    ap.add_argument("--levels", default="1:0,1:1,1:2,1:3,2:0,2:1,2:2")
    ap.add_argument("--steps", type=int, default=None, help="insertion steps (default: the scene's)")
    ap.add_argument("--mesh-check", action="store_true",
                    help="run couple optimize's mesh check (levels of the brief, step check) instead")
    a = ap.parse_args(argv)
    levels = [tuple(int(x) for x in lv.split(":")) for lv in a.levels.split(",")]
    ds = load_design_scene(a.scene, simulation={} if a.steps is None else {"steps": a.steps, "h_in": None})
    cm = ds.cm
    if a.mesh_check:
        from simfab.design.problem import make_problem
        from simfab.design.verify import check_warnings, mesh_check
        from simfab.results import to_json

        P = make_problem(cm, ds.brief, kept_regions=ds.kept_regions, target=ds.target)
        t0 = time.perf_counter()
        r = mesh_check(P, cm.fem.rest)
        return {"benchmark": "design_check", "scene": a.scene, "steps": len(cm.s_steps) - 1, "mesh_check": to_json(r),
                "warnings": check_warnings(r), "seconds": time.perf_counter() - t0}
    rows = []
    for o, t in levels:
        m = refined_model(cm, cm.fem.rest, t, o)
        t0 = time.perf_counter()
        res = simulate_insertion(m)
        dt = time.perf_counter() - t0
        f = level_figures(res, ds.brief.stress_radius)
        rows.append({"element_order": o, "subdivisions": t, "elements": int(m.fem.n_elements),
                     "nodes": int(m.fem.n_vertices), "seconds": dt, **{k: float(f[k]) for k in FIGS}})
    p2 = [r for r in rows if r["element_order"] == 2]
    ref = max(p2, key=lambda r: r["subdivisions"]) if p2 else rows[-1]
    for r in rows:
        r["error"] = {k: (r[k] - ref[k]) / ref[k] if ref[k] else None for k in FIGS}

    def fit(order):
        seq = sorted((r for r in rows if r["element_order"] == order), key=lambda r: r["subdivisions"])[-3:]
        if len(seq) < 3:
            return None
        N = np.array([r["elements"] for r in seq], float)
        out = {}
        for k in FIGS:
            f_inf, p = extrapolate(N, np.array([r[k] for r in seq]), cm.dim)
            out[k] = {"value": f_inf, "order": p, "error": (f_inf - ref[k]) / ref[k] if ref[k] else None}
        return out

    return {"benchmark": "design_check", "scene": a.scene, "dim": cm.dim, "steps": len(cm.s_steps) - 1,
            "reference": f"P{ref['element_order']} at {ref['elements']} elements", "levels": rows,
            "linear_fit": fit(1), "p2_fit": fit(2),
            "units": {"insertion_force": "N", "removal_force": "N", "grip_force": "N", "von_mises": "Pa",
                      "E_max": "J", "seconds": "s", "error": "-"}}
