"""Benchmark: pinned elastica g/L = 0.8 at n = 80 segments to 0.1% rise accuracy, simfab vs PyElastica.

``python tools/bench.py rods [--n 80] [--g-over-L 0.8] [--repeat 5] [--pyelastica-cap 300] [--no-pyelastica]``

simfab: the same quasi-static Newton continuation as ``simfab validate buckling`` (beam
parameters from scenes/deploy/elastica.xml), timed after a warm-up run (Warp kernels loaded),
best of ``--repeat``. PyElastica (optional benchmark dependency, ``pip install pyelastica``):
damped Cosserat-rod dynamics relaxed until the rise is within 0.1% of the exact elastica and
settled, or until the wall-time cap; see ``_pyelastica_elastica.py``. Both are compared with the
exact elastica and with the published reference rise (figures.json, 5 decimals).
"""

from __future__ import annotations

import argparse
import time


def run(argv) -> dict:
    p = argparse.ArgumentParser(prog="bench rods")
    p.add_argument("--n", type=int, default=80)
    p.add_argument("--g-over-L", dest="r", type=float, default=0.8)
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--pyelastica-cap", type=float, default=300.0, help="wall-time cap of the PyElastica run [s]")
    p.add_argument("--no-pyelastica", action="store_true")
    a = p.parse_args(argv)

    from benchmarks._reference import figures
    from simfab.deploy import buckling as bk
    from simfab.deploy import elastica
    from simfab.deploy import tolerances as tol

    rtol = tol.PINNED_RISE_RTOL
    exact = elastica.solve_elastica(a.r, "pinned")
    ref_rows = figures().get("elastica_first_mode", {}).get("rows", [])
    ref = next((row["delta_over_L"] for row in ref_rows if abs(row["g_over_L"] - a.r) < 1e-9), None)
    setup = bk.load_insert_scene(bk.elastica_scene_path()).setup
    bk.run_continuation(setup, "pinned", a.n, [a.r])  # warm-up: Warp module load, first factorization
    times, row = [], None
    for _ in range(max(1, a.repeat)):
        t0 = time.perf_counter()
        row = bk.run_continuation(setup, "pinned", a.n, [a.r])[0]
        times.append(time.perf_counter() - t0)
    ours = dict(seconds=min(times), seconds_all=times, delta_over_L=row["delta_over_L"], rel_err=row["rel_err"],
                within_tolerance=row["rel_err"] <= rtol, newton_iterations=row["newton_iterations"],
                increments=row["increments"], force_rel_err=row["force_rel_err"])
    out = dict(case=dict(support="pinned", g_over_L=a.r, n=a.n, rise_rtol=rtol),
               exact_delta_over_L=exact.delta_over_L, reference_delta_over_L=ref,
               reference_vs_exact=(abs(ref - exact.delta_over_L) if ref is not None else None),
               simfab=ours)
    if not a.no_pyelastica:
        try:
            from benchmarks._pyelastica_elastica import run as run_pe
        except ImportError as e:  # pragma: no cover - optional dependency
            out["pyelastica"] = dict(error=f"PyElastica not installed ({e})")
        else:
            try:
                pe = run_pe(a.n, a.r, exact.delta_over_L, rtol=rtol, cap_seconds=a.pyelastica_cap)
            except ImportError as e:
                pe = dict(error=f"PyElastica not installed ({e})")
            out["pyelastica"] = pe
            if "seconds" in pe:
                out["speedup"] = pe["seconds"] / ours["seconds"]
                out["speedup_note"] = ("PyElastica reached the tolerance" if pe["converged"] else
                                       f"PyElastica did NOT reach {rtol:g} within the {a.pyelastica_cap:g} s cap "
                                       f"(rel_err {pe['rel_err']:.2e}); speedup is a lower bound")
                out["target_speedup"] = 100.0
                out["meets_target"] = out["speedup"] >= out["target_speedup"]
    return out
