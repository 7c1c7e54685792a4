"""Benchmark: ``simfab deploy surface`` end to end, and how the deployment's cost grows with the inserts.

``python tools/bench.py deploy [--scene dome] [--scales 1 1.4 2] [--no-scaling] [--no-cli]
[--baseline DIR [--pairs 3] [--ab-scale 2]]``

End to end: ``python -m simfab deploy surface SCENE --out TMP`` as a user runs it (a fresh
process: imports, flattening, layout, laser-cut files, deployment, comparison, the MuJoCo scene
built, stepped until at rest and checked against simfab's equilibrium, every output file written);
its wall time and the CPU time the process used (the machine is shared: wall time moves with the
load, CPU time less), and the per-stage seconds from its surface.json. Target (issue 33): the
bundled dome <= 10 s end to end; ``ratio`` = wall / target.

Scaling: the dome scene's cap scaled by s (sphere radius x s, same angle and spacing, so ~s^2 x
the inserts), in this process (imports excluded): inserts, rod DOFs, Newton iterations, the
deploy stage's wall seconds, the CPU seconds of the pipeline without and of the MuJoCo check,
and the MuJoCo check's counts (bodies, nv, welds, steps to rest, the compile's mj_setConst work
:func:`setconst_work`); ``growth_exponents``: slope of log(cost) over log(inserts). Target (issue
33): a 150-insert pattern (s = 2) deployed in <= 20 s. Beside the runs: the machine's momentary
speed (``_machine.machine_reference_ms``).

A/B (``--baseline DIR``: another copy of simfab, e.g. ``git archive main | tar -x -C DIR``): the end
to end run and the scaled case ``--ab-scale`` (pipeline + MuJoCo check, in a fresh process each),
alternating baseline and this checkout ``--pairs`` times, so that both sides see the same drift of
the shared machine; ``ab`` holds every run's wall and CPU seconds, the medians and the median of
the per-pair ratios (this / baseline), and whether both sides ended at the same deployed shape.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

from benchmarks._machine import machine_reference_ms

TARGET_END_TO_END_S = 10.0
TARGET_150_INSERTS_DEPLOY_S = 20.0


ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
TOOLS = os.path.join(ROOT, "tools")


def _cli(scene: str, root: str = ROOT) -> dict:
    """``python -m simfab deploy surface SCENE`` in a fresh process run from checkout ``root``."""
    with tempfile.TemporaryDirectory() as tmp:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        p = subprocess.run([sys.executable, "-m", "simfab", "deploy", "surface", scene, "--out", tmp, "--quiet"],
                           cwd=root, capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=root))
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if p.returncode != 0:
            raise RuntimeError(f"simfab deploy surface {scene} failed: {p.stderr.strip()[-400:]}")
        s = json.loads(open(os.path.join(tmp, "surface.json")).read())
    st = (s.get("mujoco") or {}).get("stability", {})
    return dict(wall_s=wall, cpu_s=(after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
                stages_s=s["seconds"], inserts=s["inserts"], rms=s["deviation"]["rms"],
                hausdorff=s["deviation"]["hausdorff"], newton_iterations=sum(s["deployment"]["newton_iterations"]),
                mujoco_at_rest=st.get("settled"), mujoco_steps=st.get("steps"))


def _scaled_process(root: str, scene_name: str, s: float) -> dict:
    """:func:`_scaled` in a fresh process with simfab from checkout ``root`` (this file's
    benchmark code); adds the process's wall and CPU seconds (imports included)."""
    code = ("import json; from benchmarks.deploy import _scaled; "
            f"print(json.dumps(_scaled({scene_name!r}, {float(s)!r})))")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True,
                       env=dict(os.environ, PYTHONPATH=os.pathsep.join([root, TOOLS])))
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        raise RuntimeError(f"scaled deployment (s = {s}) from {root} failed: {p.stderr.strip()[-400:]}")
    row = json.loads(p.stdout.strip().splitlines()[-1])
    row.update(process_wall_s=wall,
               process_cpu_s=(after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime))
    return row


def _ab(baseline: str, scene: str, scale: float, pairs: int) -> dict:
    """Interleaved A/B: baseline, this, baseline, this, ... for the end to end run and the scaled case."""
    out = {"baseline": os.path.abspath(baseline), "pairs": pairs}
    for name, run, keys in (
            ("end_to_end", lambda root: _cli(scene, root), ("wall_s", "cpu_s")),
            (f"scaled_{scale:g}", lambda root: _scaled_process(root, "dome", scale),
             ("process_wall_s", "process_cpu_s", "pipeline_cpu_s", "mujoco_cpu_s", "deploy_s"))):
        runs = {"baseline": [], "this": []}
        for _ in range(pairs):
            runs["baseline"].append(run(baseline))
            runs["this"].append(run(ROOT))
        summary = {}
        for k in keys:
            a = np.array([r[k] for r in runs["baseline"]])
            b = np.array([r[k] for r in runs["this"]])
            summary[k] = dict(baseline_median=float(np.median(a)), this_median=float(np.median(b)),
                              ratio_median=float(np.median(b / a)), baseline=a.tolist(), this=b.tolist())
        summary["rms_baseline"] = [r["rms"] for r in runs["baseline"]]
        summary["rms_this"] = [r["rms"] for r in runs["this"]]
        summary["inserts"] = runs["this"][0]["inserts"]
        summary["mujoco_at_rest_this"] = [r.get("mujoco_at_rest") for r in runs["this"]]
        summary["mujoco_steps"] = dict(baseline=[r.get("mujoco_steps") for r in runs["baseline"]],
                                       this=[r.get("mujoco_steps") for r in runs["this"]])
        out[name] = summary
    return out


def _scaled(scene_name: str, s: float) -> dict:
    from simfab.deploy import pipeline, scene, surface

    sc = scene.load_scene(scene.bundled_path(scene_name))
    tgt = sc.target
    if s != 1.0:  # the bundled dome's cap with the sphere radius scaled (spherical_cap: apex at the origin)
        R = _sphere_radius(tgt)
        theta = float(np.arccos(1 + tgt.V[:, 2].min() / R))
        tgt = surface.spherical_cap(R * s, theta, int(round(24 * s)))
        sc = dataclasses.replace(sc, target=tgt)
    t0, c0 = time.perf_counter(), time.process_time()
    res = pipeline.run(sc, quiet=True, mujoco_check=False)
    c1 = time.process_time()
    sim, check = pipeline.mujoco_check_run(res.network, res.deployment, res.pattern, sc)
    c2 = time.process_time()
    total = time.perf_counter() - t0
    res.sim, res.sim_check = sim, check
    sm = pipeline.summary(res)
    mj = sm["mujoco"]
    m = sim.model
    return dict(scale=s, inserts=sm["inserts"], rod_dofs=int(res.network.model.n_nodes * 3 + res.network.model.n_edges),
                newton_iterations=sum(sm["deployment"]["newton_iterations"]), deploy_s=sm["seconds"]["deploy"],
                pipeline_cpu_s=c1 - c0, mujoco_cpu_s=c2 - c1, mujoco_step_wall_s=mj["stability"]["wall_s"],
                mujoco_bodies=int(m.nbody), mujoco_nv=mj["nv"], mujoco_welds=mj["welds"],
                mujoco_setconst_work=setconst_work(m), mujoco_steps=mj["stability"]["steps"],
                mujoco_relaxed_rms_rel=mj["relaxation"]["rms_rel"],
                mujoco_at_rest=mj["stability"]["settled"], total_s=total, rms=sm["deviation"]["rms"])


def setconst_work(m) -> int:
    """Machine-independent count of MuJoCo's compile-time constants (mj_setConst): body_invweight0
    solves M^-1 for the 6 Jacobian rows of every body that is not a simple point mass and
    dof_invweight0 for every dof's unit vector, each a sparse LDL solve over all nv dofs touching
    nnz(L) = sum over dofs of their ancestor dofs (+1): work = (6 n_body + nv) nnz(L). Both factors
    grow with the network, hence the compile's quadratic growth."""
    par = np.asarray(m.dof_parentid)
    depth = np.zeros(m.nv, dtype=np.int64)
    for i in range(m.nv):  # parents come before their children
        depth[i] = 1 + (depth[par[i]] if par[i] >= 0 else 0)
    general = int(np.sum(np.asarray(m.body_simple[1:]) != 2))
    return int((6 * general + m.nv) * depth.sum())


def _growth_exponent(rows, key) -> float | None:
    """Least-squares slope of log(rows[key]) against log(inserts) (cost ~ inserts^slope)."""
    x = np.log([r["inserts"] for r in rows])
    y = np.log([max(float(r[key]), 1e-12) for r in rows])
    return float(np.polyfit(x, y, 1)[0]) if len(rows) >= 2 and np.ptp(x) > 0 else None


def _sphere_radius(tgt) -> float:
    """Sphere radius of a ``spherical_cap`` target (apex at the origin, centre at (0, 0, -R))."""
    # |p - c|^2 = R^2 with c = (0, 0, -R): x^2 + y^2 + z^2 + 2 R z = 0 -> R = -(x^2 + y^2 + z^2) / (2 z)
    V = tgt.V[tgt.V[:, 2] < -1e-9]
    return float(np.median(-(np.sum(V**2, axis=1)) / (2 * V[:, 2])))


def run(argv) -> dict:
    p = argparse.ArgumentParser(prog="bench deploy")
    p.add_argument("--scene", default="dome")
    p.add_argument("--scales", type=float, nargs="+", default=[1.0, 1.4, 2.0])
    p.add_argument("--no-scaling", action="store_true")
    p.add_argument("--no-cli", action="store_true")
    p.add_argument("--baseline", metavar="DIR", help="another simfab checkout to compare with (interleaved A/B)")
    p.add_argument("--pairs", type=int, default=3, help="A/B pairs (baseline, this) per case")
    p.add_argument("--ab-scale", type=float, default=2.0, help="scale of the dome's cap in the A/B (2: 165 inserts)")
    a = p.parse_args(argv)
    out = dict(benchmark="deploy", machine_reference_ms_before=machine_reference_ms())
    if a.baseline:
        out["ab"] = _ab(a.baseline, a.scene, a.ab_scale, a.pairs)
    if not a.no_cli:
        e2e = _cli(a.scene)
        out.update(end_to_end=e2e, target_end_to_end_s=TARGET_END_TO_END_S, ratio=e2e["wall_s"] / TARGET_END_TO_END_S)
    if not a.no_scaling and a.scene == "dome":
        rows = [_scaled(a.scene, s) for s in a.scales]
        out["scaling"] = rows
        out["growth_exponents"] = {k: _growth_exponent(rows, k) for k in (
            "newton_iterations", "pipeline_cpu_s", "mujoco_cpu_s", "mujoco_setconst_work", "mujoco_bodies")}
        big = [r for r in rows if r["inserts"] >= 140]
        out["target_150_inserts_deploy_s"] = TARGET_150_INSERTS_DEPLOY_S
        out["ratio_150_inserts"] = big[0]["deploy_s"] / TARGET_150_INSERTS_DEPLOY_S if big else None
        # the same by CPU seconds of the whole pipeline without the MuJoCo check (the wall time moves with the load)
        out["ratio_150_inserts_cpu"] = big[0]["pipeline_cpu_s"] / TARGET_150_INSERTS_DEPLOY_S if big else None
    out["machine_reference_ms_after"] = machine_reference_ms()
    out["reference"] = None
    out["reference_note"] = "no published figure for this pipeline in figures.json; targets from issue 33"
    try:
        out["load_average_1min"] = os.getloadavg()[0]
    except OSError:
        out["load_average_1min"] = None
    return out
