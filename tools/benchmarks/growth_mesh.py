"""Mesh sweep of the growth structural check: safety factor, peak stress, deflection and tet count
of one grown support at several tet edge lengths (multiples of the thinnest branch radius).

    python tools/bench.py growth_mesh [--scene phone_stand] [--seed 0] [--edges 2,1.4,1]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path


def run(argv) -> dict:
    from simfab.cli.grow import SCENES_DIR
    from simfab.growth import grow
    from simfab.growth.structure import CheckConfig, check_structure

    ap = argparse.ArgumentParser(prog="bench growth_mesh")
    ap.add_argument("--scene", default="phone_stand")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--edges", default="2,1.4,1", help="edge lengths in thinnest radii, comma separated")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory():
        res = grow(Path(SCENES_DIR) / f"{a.scene}.xml", seed=a.seed)
    sk, scene = res.skeleton, res.scene
    r_min = float(sk.radius.min())
    rows = []
    for k in (float(v) for v in a.edges.split(",")):
        t = time.perf_counter()
        c = check_structure(sk, scene, options=CheckConfig(edge_length=k * r_min))
        rows.append({"edge_per_rmin": k, "tets": c.tets, "safety_factor": c.safety_factor,
                     "max_von_mises_Pa": c.max_von_mises_Pa, "peak_point_m": [float(v) for v in c.peak_point],
                     "max_deflection_m": max(c.deflection_m.values(), default=0.0),
                     "seconds": time.perf_counter() - t})
    return {"scene": a.scene, "seed": a.seed, "r_min_m": r_min, "rows": rows}
