"""Annealing against gradient design on the bundled design scenes.

``python tools/bench.py design_methods [--scenes a,b,...] [--methods anneal,gradient] [--seeds 0,1,2] [--out DIR]
[--profile-handles 2,4,8] [--element-orders 1,2] [--friction MU] [--anneal-workers N]``

For every scene, method and seed: ``simfab couple optimize NAME --method M --seed S`` (its [design] brief;
annealing on ``--anneal-workers`` processes (default 2; with 1 it runs no speculative proposals, so its
``insertions`` are the annealer's own need, the same design), the gradient method in one process; the mesh
check with its correction rounds), outputs under ``--out`` (default: a new temporary directory). Reported per
run: ``insertions`` (every insertion simulation of the optimization and its correction rounds, the placement's
initial insertion and the mesh check's excluded), ``gradient_evaluations``, ``seconds`` (end to end, mesh
check included), ``E_L``, ``rms_error_N`` (profile2d: the RMS force error, coarse and mesh-corrected),
``feasible`` (coarse, mesh-corrected), ``met_mesh_check`` (mesh-converged figures), ``rms_error_fine_N``
(profile2d: on the mesh check's finest level) and the optimizer's closing message. The gradient method does
not depend on the seed except through the handle placement and its annealing pre-phase. ``profile2d`` runs
once per count of ``--profile-handles`` (default: the scene's 4), its [design] handles overridden (``handles``
in the row; annealing gets the scene's iterations per handle,
:func:`simfab.design.study.iterations_per_handle_budget`). ``--element-orders`` runs each with those element
orders (``couple optimize --element-order``: 2 simulates every candidate on P2, the handles on the linear
mesh); ``--friction`` sets ``[contact] friction``.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

SCENES = ["standside2d", "paddleside2d", "block2d_loose", "block2d_tight", "block2d_tighter", "alligator2d",
          "profile2d", "alligator3d", "knocker3d_design"]


def _finest_rms(check: dict):
    """The RMS force error [N] on the mesh check's finest level (None without a target or a check)."""
    rms = (check.get("figures") or {}).get("rms_error")
    return None if rms is None else rms["values"][-1]


def run(argv) -> dict:
    from simfab.design import run as optimize_design
    from simfab.design.scene import load_design_scene
    from simfab.design.study import iterations_per_handle_budget
    from simfab.io.outpaths import check_out_dir

    ap = argparse.ArgumentParser(prog="bench.py design_methods")
    ap.add_argument("--scenes", default=",".join(SCENES[:6]))
    ap.add_argument("--methods", default="anneal,gradient")
    ap.add_argument("--seeds", default="0")
    ap.add_argument("--out", default=None)
    ap.add_argument("--profile-handles", default=None, help="profile2d's handle counts, e.g. 2,4,8")
    ap.add_argument("--element-orders", default=None, help="e.g. 1,2 (default: the scene's)")
    ap.add_argument("--friction", type=float, default=None)
    ap.add_argument("--anneal-workers", type=int, default=2)
    a = ap.parse_args(argv)
    orders = [None] if a.element_orders is None else [int(o) for o in a.element_orders.split(",")]
    contact = {} if a.friction is None else {"friction": a.friction}
    out = check_out_dir(a.out) if a.out else Path(tempfile.mkdtemp(prefix="design_methods_"))
    rows = []
    runs = []
    for scene in a.scenes.split(","):
        counts = [None]
        if scene == "profile2d" and a.profile_handles:
            counts = [int(k) for k in a.profile_handles.split(",")]
        runs += [(scene, k) for k in counts]
    for scene, k in runs:
        for method in a.methods.split(","):
            for seed, order in ((int(s), o) for s in a.seeds.split(",") for o in orders):
                design = None
                if k is not None:
                    brief = load_design_scene(scene).brief
                    design = {"handles": k, "iterations": iterations_per_handle_budget(brief, k)}
                t0 = time.perf_counter()
                sim = {} if order is None else {"element_order": order}
                name = f"{scene}{'' if k is None else f'_h{k}'}_{method}_{seed}_{order}"
                s = optimize_design(scene, out=out / name, seed=seed, design=design,
                                    workers=a.anneal_workers if method == "anneal" else 1, method=method,
                                    simulation=sim, contact=contact).to_json()
                mc = s.get("mesh_check") or {}
                rows.append({"scene": scene, "handles": s["handles"]["active"], "method": method, "seed": seed,
                             "element_order": order, "friction": a.friction,
                             "insertions": s.get("insertions_total", s["insertions"]),
                             "gradient_evaluations": s["gradient_evaluations"],
                             "seconds": time.perf_counter() - t0, "E_L": s["E_L"], "rms_error_N": s.get("rms_error"),
                             "feasible": s["feasible"], "met_mesh_check": mc.get("feasible_fine"),
                             "rms_error_fine_N": _finest_rms(mc),
                             "correction_rounds": len(s.get("correction_rounds", [])),
                             "optimizer_message": s.get("optimizer_message"),
                             "nonsmooth_events": s.get("nonsmooth_events")})
    return {"benchmark": "design_methods", "rows": rows,
            "units": {"seconds": "s", "E_L": "-", "rms_error_N": "N", "rms_error_fine_N": "N"}}
