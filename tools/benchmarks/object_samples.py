"""Convergence of a coupling scene's figures in the sampling of a mesh object's contact field.

``python tools/bench.py object_samples --scene SCENE [--samples 2000,4000,8000,16000,32000]
[--element-order 1|2] [--steps N]``

An object given as a mesh is sampled (``[object] samples``) and its
contact field is the IMLS surface of those samples, with a kernel width sigma that shrinks with the
spacing; the IMLS surface departs from the mesh by about sigma^2 / r on a part of curvature radius
r (simfab.contact.imls). The mesh-convergence study (``bench converge``) refines the part's mesh
only; this one runs the scene as bundled (its mesh, elements and steps) at each sample count and
reports per count sigma [m], the profile figures (E_max, E_ss [J], F_in, F_rm, F_grip [N],
category), Newton iterations and seconds. Primitive objects (sphere, cylinder, capsule, box, torus)
use their exact signed distance and have nothing to converge (InputError); every bundled scene's
object is one, because sampled meshes of round objects converge slowly in the sample count (see
docs/decisions.md, "Objects as primitives").
"""

from __future__ import annotations

import argparse
import time


def run(argv) -> dict:
    from simfab.contact.sdf import PrimitiveField
    from simfab.coupling.profile import analyze_run
    from simfab.coupling.scene import load_coupling_scene
    from simfab.coupling.simulate import simulate_insertion
    from simfab.errors import InputError

    ap = argparse.ArgumentParser(prog="bench object_samples")
    ap.add_argument("--scene", required=True, help="a coupling scene whose object is a mesh")
    ap.add_argument("--samples", default="2000,4000,8000,16000,32000")
    ap.add_argument("--element-order", type=int, default=None, help="override the scene's element order")
    ap.add_argument("--steps", type=int, default=None, help="override the scene's steps")
    a = ap.parse_args(argv)
    sim = {k: v for k, v in (("element_order", a.element_order), ("steps", a.steps)) if v is not None}
    rows = []
    for n in (int(x) for x in a.samples.split(",")):
        cm = load_coupling_scene(a.scene, overrides={"object": {"samples": n}, "simulation": sim})
        if isinstance(cm.field, PrimitiveField):  # exact, not sampled
            raise InputError(f"{a.scene}'s object is made of primitives (exact signed distance): "
                             "no sampling to converge")
        t0 = time.perf_counter()
        res = simulate_insertion(cm)
        p = analyze_run(res)
        rows.append({"samples": n, "sigma_m": float(cm.field.sigma), "seconds": time.perf_counter() - t0,
                     "newton_iterations": int(sum(r.iterations for r in res.steps)), "category": p.category,
                     "E_max_J": float(p.E_max), "E_ss_J": float(p.E_ss), "F_in_N": float(p.F_in),
                     "F_rm_N": float(p.F_rm), "F_grip_N": float(p.F_grip)})
    return {"benchmark": "object_samples", "scene": a.scene, "rows": rows}
