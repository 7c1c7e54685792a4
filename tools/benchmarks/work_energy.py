"""Work against energy, step by step: the bundled 2D scenes at several step counts
(simfab.coupling.settle.work_energy_mismatch).

``python tools/bench.py work_energy [--scenes cclamp2d,clip2d_loose,clip2d_eject] [--steps 35,70,140]``

Per scene and step count: the largest mismatch between the work of the path force over a step
(trapezoidal rule) and the change of stored energy E + B, relative to E_max (over all steps and over
steps that added refinement points), and the same mismatch per unit step length relative to the
peak force (F against -dE/ds), over all steps and over smooth steps (the planned steps, not the
rest search's bracket around the seat; in contact at both ends, no sign change of the force, the
barrier energy within a factor 4: a contact starting, ending or a new contact zone engaging inside
a step is a kink the trapezoidal rule resolves only to first order in the step). Target: 1% each.
"""

from __future__ import annotations

import argparse
import time


def run(argv) -> dict:
    from simfab.coupling.scene import load_coupling_scene
    from simfab.coupling.settle import work_energy_mismatch
    from simfab.coupling.simulate import simulate_insertion

    ap = argparse.ArgumentParser(prog="bench work_energy")
    ap.add_argument("--scenes", default="cclamp2d,clip2d_loose,clip2d_eject")
    ap.add_argument("--steps", default="35,70,140")
    a = ap.parse_args(argv)
    rows = []
    for scene in a.scenes.split(","):
        for n in (int(x) for x in a.steps.split(",")):
            t0 = time.perf_counter()
            res = simulate_insertion(load_coupling_scene(scene, overrides={"simulation": {"steps": n}}))
            m = work_energy_mismatch(res.steps, planned=len(res.model.s_steps))
            rows.append({"scene": scene, "steps": n, "records": len(res.steps),
                         "seconds": round(time.perf_counter() - t0, 2),
                         **{k: (round(v, 5) if isinstance(v, float) else v) for k, v in m.items()}})
    worst = {k: max(r[k] for r in rows) for k in ("work", "work_refined", "force", "force_smooth")}
    return {"benchmark": "work_energy", "rows": rows, "worst": worst, "target": 0.01,
            "meets_target": {k: v <= 0.01 for k, v in worst.items()}}
