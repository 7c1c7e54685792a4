"""Insertion on linear vs quadratic (P2) elements: the profile figures, wall time and Newton
iterations of each, against a mesh-converged reference.

``python tools/bench.py p2_insertion [--scenes cclamp2d,knocker3d] [--coarse 450] [--no-reference]``

Per scene, runs (35-40 steps as bundled):
- ``p1`` / ``p2``: the bundled mesh with ``element_order`` 1 / 2;
- ``p1_coarse`` / ``p2_coarse`` (``--coarse N``, scenes meshed from ``target_elements`` only): the
  same at N elements;
- ``p1_red``: linear elements on the red refinement of the bundled mesh (every simplex split
  into 4 / 8; the same nodes as the P2 lift, so the same unknowns);
- ``reference``: Richardson extrapolation of ``p1`` and ``p1_red`` (h and h/2) with order 2,
  f_inf = f_red + (f_red - f_p1) / 3 (energies of conforming linear elements converge like h^2
  for smooth solutions; the 2D convergence study observes 1.5-1.7 for cclamp2d, which would put
  f_inf 0.5-1% of f further out: the stated errors carry that uncertainty).
Each run reports its figures, ``seconds``, ``newton_iterations`` and ``error`` (relative to the
reference) per figure. F_grip is read where the object comes to rest, where the grip jumps: its
error is noisier than the others'.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

FIGURES = ("E_max", "E_ss", "F_in", "F_rm", "F_grip")


def _red_refined(scene):
    """The linear coupling model on the red refinement of the scene's mesh: built from the P2 lift
    (whose node numbering the red refinement shares, fixed region included)."""
    from simfab.coupling.scene import load_coupling_scene
    from simfab.coupling.simulate import make_coupling_model
    from simfab.fem.model import make_model

    p2 = load_coupling_scene(scene, overrides={"simulation": {"element_order": 2}})
    fem = make_model(p2.fem.rest, p2.display_elements, p2.fem.material, thickness=p2.fem.thickness,
                     device=p2.fem.device)
    return make_coupling_model(name=p2.name, fem=fem, field=p2.field, path=p2.path, fixed_vertices=p2.fixed_vertices,
                               options=dataclasses.replace(p2.options, element_order=1),
                               object_vertices=p2.object_vertices, object_faces=p2.object_faces)


def _run(cm) -> dict:
    from simfab.coupling.outputs import summarize
    from simfab.coupling.simulate import simulate_insertion

    t0 = time.perf_counter()
    res = simulate_insertion(cm)
    dt = time.perf_counter() - t0
    _, d = summarize(res)
    return {"elements": int(cm.fem.n_elements), "nodes": int(cm.fem.n_vertices),
            "element_order": int(cm.options.element_order), "seconds": dt,
            "newton_iterations": d["newton_iterations"], "category": d["category"],
            "warnings": d["warnings"], **{k: float(d[k]) for k in FIGURES}}


def run(argv) -> dict:
    from simfab.coupling.scene import load_coupling_scene, read_scene_toml, scene_paths

    ap = argparse.ArgumentParser(prog="bench p2_insertion")
    ap.add_argument("--scenes", default="cclamp2d,knocker3d")
    ap.add_argument("--coarse", type=int, default=450, help="also run both orders at this element count "
                    "(scenes meshed from target_elements only; 0: skip)")
    ap.add_argument("--no-reference", action="store_true", help="skip the red-refined linear run")
    a = ap.parse_args(argv)
    out = {"benchmark": "p2_insertion", "scenes": {}}
    for scene in a.scenes.split(","):
        runs = {}
        for order in (1, 2):
            runs[f"p{order}"] = _run(load_coupling_scene(scene, overrides={"simulation": {"element_order": order}}))
        comp = read_scene_toml(scene_paths(scene)[1]).get("compliant", {})
        if a.coarse and "mesh_file" not in comp and comp.get("target_elements"):
            for order in (1, 2):
                ov = {"simulation": {"element_order": order}, "compliant": {"target_elements": a.coarse}}
                runs[f"p{order}_coarse"] = _run(load_coupling_scene(scene, overrides=ov))
        rep = {"runs": runs}
        if not a.no_reference:
            runs["p1_red"] = _run(_red_refined(scene))
            ref = {k: runs["p1_red"][k] + (runs["p1_red"][k] - runs["p1"][k]) / 3.0 for k in FIGURES}
            rep["reference"] = ref
            for r in runs.values():
                r["error"] = {k: (r[k] - ref[k]) / ref[k] if ref[k] else None for k in FIGURES}
        out["scenes"][scene] = rep
    return out
