"""Frictional contact: the snap-fit against the wedge formula, the energy balance, and the bundled
coupling scenes with and without friction.

``python tools/bench.py friction [--alphas 20,30,40] [--mus 0.1,0.3,0.5] [--scenes cclamp2d,...] [--mu 0.3]
[--double-steps]``

- ``snapfit``: per face angle alpha and coefficient mu (simfab.verification.snapfit, 2D, 24 steps,
  and 3D at alpha 30, mu 0.3), over the deflected travel (min and max over its records): the contact
  law F / F_lat against (tan a + mu) / (1 - mu tan a) on insertion and (tan a - mu) / (1 + mu tan a)
  on removal; the insertion ratio F(mu) / F(0) at equal lateral force and at equal position against
  (tan a + mu) / (tan a (1 - mu tan a)); worst relative errors; the energy balance. A combination
  with mu tan a >= 1 is expected to jam.
- ``scenes``: each bundled scene at mu = 0 and at ``--mu`` (default 0.3, mid-range of printed PLA on
  PLA or on metal): category, E_max, F_in, F_rm, F_hold, seconds, Newton iterations (insertion and
  removal), lagging solves per step, energy balance over both traversals (fraction of E_max), and the
  cost ratios: the frictional insertion over the frictionless one (insert_ratio_seconds, _newton: the
  budget is 2x) and insertion + removal over the frictionless insertion (cost_ratio_*).
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np


def _snapfit_row(alpha: float, mu: float, dim: int, steps: int) -> dict:
    from simfab.coupling.settle import energy_balance
    from simfab.coupling.simulate import simulate_insertion
    from simfab.verification.snapfit import GAP, contact_law, ratio_formula, snapfit_model

    r0 = simulate_insertion(snapfit_model(alpha, 0.0, dim=dim, steps=steps))
    t0 = time.perf_counter()
    r1 = simulate_insertion(snapfit_model(alpha, mu, dim=dim, steps=steps))
    secs = time.perf_counter() - t0
    row = {"alpha_deg": alpha, "mu": mu, "dim": dim, "mu_tan_alpha": round(mu * np.tan(np.radians(alpha)), 3),
           "seconds": round(secs, 2)}
    if r1.jammed_at is not None:
        return {**row, "jammed_at_mm": round(r1.jammed_at * 1e3, 4)}
    s = r0.column("s")
    sel = s >= GAP + 0.2 * (s[-1] - GAP)
    keys = np.round(s[sel], 12)

    def law(records):  # -F / F_lat per record (F_lat: the face's push across the beam, -reaction_x)
        return np.array([r.path_force / r.reaction[0] for r in records])

    law0 = law(r0.steps)[sel]
    law_in = law(r1.steps)[sel]
    rm = {round(r.s, 12): r for r in r1.removal}
    rm = [rm[k] for k in keys if k in rm]
    law_rm = law(rm)  # the force pushing the box back out over the lateral force (both signs flip)
    raw = r1.column("path_force")[sel] / r0.column("path_force")[sel]
    c_in, c_rm = contact_law(alpha, mu, "insert"), contact_law(alpha, mu, "remove")
    f_in = ratio_formula(alpha, mu, "insert")

    def span(v):
        return [round(float(v.min()), 4), round(float(v.max()), 4)]

    bal = energy_balance(r1.steps, r1.removal)
    return {**row, "contact_law_insert": span(law_in), "formula_insert": round(c_in, 4),
            "contact_law_remove": span(law_rm), "formula_remove": round(c_rm, 4),
            "contact_law_worst_rel_error": round(float(max(np.abs(law_in / c_in - 1).max(),
                                                           np.abs(law_rm / c_rm - 1).max())), 4),
            "ratio_at_equal_lateral_force": span(law_in / law0), "ratio_formula": round(f_in, 4),
            "ratio_at_equal_lateral_force_rel_error": round(float(np.abs(law_in / law0 / f_in - 1).max()), 4),
            "ratio_at_equal_position": span(raw),
            "ratio_at_equal_position_rel_error": round(float(np.abs(raw / f_in - 1).max()), 4),
            "energy_balance": round(bal["total"], 5)}


def _scene_row(scene: str, mu: float) -> dict:
    from simfab.coupling.config import ContactConfig
    from simfab.coupling.profile import analyze_run
    from simfab.coupling.scene import load_coupling_scene
    from simfab.coupling.settle import energy_balance
    from simfab.coupling.simulate import simulate_insertion

    out = {}
    for m in (0.0, mu):
        cm = load_coupling_scene(scene)
        cm = dataclasses.replace(cm, contact=ContactConfig(friction=m))
        marks = {}

        def mark(k, rec, marks=marks):  # the clock at the last insertion record
            if rec.phase == "insert":
                marks["insert"] = time.perf_counter()

        t0 = time.perf_counter()
        res = simulate_insertion(cm, callback=mark)
        secs = time.perf_counter() - t0
        p = analyze_run(res)
        records = [*res.steps, *res.removal]
        out[f"mu={m:g}"] = {
            "category": p.category, "E_max_J": float(f"{p.E_max:.4g}"), "F_in_N": float(f"{p.F_in:.4g}"),
            "F_rm_N": float(f"{p.F_rm:.4g}"), "F_hold_N": float(f"{p.F_hold:.4g}"), "seconds": round(secs, 2),
            "seconds_insert": round(marks["insert"] - t0, 2),
            "newton_insert": int(sum(r.iterations for r in res.steps)),
            "newton_remove": int(sum(r.iterations for r in res.removal)),
            "steps_insert": len(res.steps), "steps_remove": len(res.removal),
            "lag_solves_per_step": round(float(np.mean([r.lag_solves for r in records[1:]])), 2) if m > 0 else 0,
            "energy_balance": round(energy_balance(res.steps, res.removal)["total"], 5),
            "jammed_at_m": res.jammed_at,
        }
    a, b = out["mu=0"], out[f"mu={mu:g}"]
    out["cost_ratio_seconds"] = round(b["seconds"] / a["seconds"], 2)
    out["cost_ratio_newton"] = round((b["newton_insert"] + b["newton_remove"]) / a["newton_insert"], 2)
    # the budget: the frictional insertion <= 2x the frictionless one, the removal on top
    out["insert_ratio_seconds"] = round(b["seconds_insert"] / a["seconds_insert"], 2)
    out["insert_ratio_newton"] = round(b["newton_insert"] / a["newton_insert"], 2)
    return {"scene": scene, **out}


def _refined_row(scene: str, mu: float) -> dict:
    """The scene at ``mu`` with twice its planned steps: F_in, F_rm, F_hold and the energy balance
    (their change from the bundled steps is the step discretization's share of the figures)."""
    from simfab.coupling.profile import analyze_run
    from simfab.coupling.scene import load_coupling_scene
    from simfab.coupling.settle import energy_balance
    from simfab.coupling.simulate import simulate_insertion

    steps = 2 * load_coupling_scene(scene).options.steps
    cm = load_coupling_scene(scene, overrides={"simulation": {"steps": steps}, "contact": {"friction": mu}})
    res = simulate_insertion(cm)
    p = analyze_run(res)
    return {"steps": steps, "F_in_N": float(f"{p.F_in:.4g}"), "F_rm_N": float(f"{p.F_rm:.4g}"),
            "F_hold_N": float(f"{p.F_hold:.4g}"),
            "energy_balance": round(energy_balance(res.steps, res.removal)["total"], 5)}


def run(argv) -> dict:
    ap = argparse.ArgumentParser(prog="bench friction")
    ap.add_argument("--alphas", default="20,30,40")
    ap.add_argument("--mus", default="0.1,0.3,0.5")
    ap.add_argument("--scenes", default="cclamp2d,clip2d_loose,clip2d_eject,block2d_tight,standside2d,alligator2d")
    ap.add_argument("--mu", type=float, default=0.3)
    ap.add_argument("--no-snapfit", action="store_true")
    ap.add_argument("--double-steps", action="store_true", help="each scene at --mu also at twice its steps")
    a = ap.parse_args(argv)
    snap = []
    if not a.no_snapfit:
        for alpha in (float(x) for x in a.alphas.split(",")):
            for mu in (float(x) for x in a.mus.split(",")):
                snap.append(_snapfit_row(alpha, mu, 2, 24))
        snap.append(_snapfit_row(30.0, 0.3, 3, 12))
        snap.append(_snapfit_row(70.0, 0.5, 2, 24))  # mu tan a = 1.37: jams
    scenes = [_scene_row(s, a.mu) for s in a.scenes.split(",") if s]
    if a.double_steps:
        for row in scenes:
            row["double_steps"] = _refined_row(row["scene"], a.mu)
    worst = {k: max((r[k] for r in snap if k in r), default=None)
             for k in ("contact_law_worst_rel_error", "ratio_at_equal_lateral_force_rel_error",
                       "ratio_at_equal_position_rel_error", "energy_balance")}
    return {"benchmark": "friction", "snapfit": snap, "snapfit_worst": worst, "snapfit_target": 0.05,
            "scenes": scenes,
            "cost_target": "frictional insertion <= 2x the frictionless insertion (insert_ratio_*), the removal on top"}
