"""Mesh-convergence study of the bundled coupling scenes (the figures at 4-5 refinements, their
extrapolated values and the error of each scene's default mesh; see simfab.coupling.converge).
Default: the three 2D scenes; 3D ones by name, e.g. ``--scenes clip3d --factors 0.25,0.5,1,2``
(an extruded part is refined in its section and its layers alike; a shipped fTetWild mesh is used
at factor 1 and meshed again from the generator at the others).

``python tools/bench.py converge [--scenes cclamp2d,...] [--factors 0.125,0.25,0.5,1,2]``

Factors multiply each scene's target element count (the bundled 2D scenes: ~4,800 triangles; the
original's size, ~450, is 0.094). Reported per scene: levels (elements, seconds per run, category),
per figure the values, the extrapolated value, the observed order in h and the relative errors,
and ``error_of_default`` (the factor-1 level's).
"""

from __future__ import annotations

import argparse


def run(argv) -> dict:
    from simfab.coupling.converge import convergence_study, format_table

    ap = argparse.ArgumentParser(prog="bench converge")
    ap.add_argument("--scenes", default="cclamp2d,clip2d_loose,clip2d_eject")
    ap.add_argument("--factors", default="0.094,0.1875,0.375,0.75,1,1.5")
    a = ap.parse_args(argv)
    factors = tuple(float(f) for f in a.factors.split(","))
    out = {"benchmark": "converge", "factors": factors, "scenes": {}}
    for scene in a.scenes.split(","):
        rep = convergence_study(scene, factors)
        out["scenes"][scene] = {**rep.to_json(), "table": format_table(rep)}
    return out
