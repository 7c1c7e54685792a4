"""Benchmark: ``simfab deploy surface`` end to end, and how the deployment's cost grows with the inserts.

``python tools/bench.py deploy [--scene dome] [--scales 1 1.4 2] [--no-scaling] [--no-cli]
[--baseline DIR [--pairs 3] [--ab-scale 2]]``; ``python tools/bench.py deploy --family [--rings 12 24]
[--members NAME ...] [--rows FILE.jsonl] [--table]``

Family (issue 42, :mod:`simfab.deploy.families`): every member written as a bare mesh (OBJ) and
deployed by ``python -m simfab deploy surface MESH --out TMP`` - no scene file, no flags: the
defaults decide spacing, cuts, catalogue, layout and tuning - one at a time, each a fresh process;
per member RMS and Hausdorff (of the diameter), height error, unreachable gaps, springs short,
cones, inserts per size, covered flat area, MuJoCo at rest, wall / CPU seconds, and which targets
it meets (RMS <= 1 %, height within 3 %, no gap unreachable, MuJoCo at rest, <= 60 s for <= 150
inserts). ``--rows``: each row appended as it finishes (a long run keeps what it measured);
``--table``: also the Markdown table of scenes/deploy/README.md.

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

    sc = scene.load_deploy_scene(scene.bundled_path(scene_name))
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


TARGET_FAMILY_S = 60.0  # <= 150 inserts, end to end


def _family_row(name: str) -> dict:
    """One family member deployed on the defaults, as a bare mesh, by the CLI in a fresh process."""
    import trimesh

    from simfab.deploy import families

    t = families.member(name)
    with tempfile.TemporaryDirectory() as tmp:
        mesh = os.path.join(tmp, "target.obj")
        trimesh.Trimesh(t.V, t.F, process=False).export(mesh)
        out = os.path.join(tmp, "out")
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        p = subprocess.run([sys.executable, "-m", "simfab", "deploy", "surface", mesh, "--out", out, "--quiet"],
                           cwd=ROOT, capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=ROOT))
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if p.returncode != 0:
            return dict(member=name, error=p.stderr.strip().splitlines()[-1][-300:] if p.stderr.strip() else "")
        s = json.loads(open(os.path.join(out, "surface.json")).read())
    st = (s.get("mujoco") or {}).get("stability", {})
    bd, df = s["bounds"], s["defaults"] or {}
    row = dict(member=name, vertices=len(t.V), spacing_mm=df.get("spacing_mm"), layout=s["layout"],
               rms=s["deviation"]["rms"], hausdorff=s["deviation"]["hausdorff"], height_error=bd["height_error"],
               unreachable_gaps=bd["unreachable_gaps"], springs_short=bd["springs_short"],
               cones=(s.get("cuts") or {}).get("cones", 0), inserts=s["inserts"],
               inserts_per_size={f"{b['half_size_mm']:g} mm": b["count"] for b in s["bill_of_materials"]},
               covered=s["flat_area_covered"], tuning_steps=(s.get("tuning") or {}).get("steps", 0),
               tuning_stop=(s.get("tuning") or {}).get("stop"), mujoco_at_rest=st.get("settled"),
               wall_s=wall, cpu_s=(after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
               stages_s=s["seconds"], missed=bd["missed"])
    row["meets"] = dict(rms=row["rms"] <= bd["rms_bound"], height=abs(row["height_error"]) <= bd["height_bound"],
                        gaps=row["unreachable_gaps"] == 0, mujoco=bool(row["mujoco_at_rest"]),
                        seconds=row["inserts"] > 150 or wall <= TARGET_FAMILY_S)
    return row


def family_table(rows) -> str:
    """The Markdown table of the family rows (scenes/deploy/README.md)."""
    head = ("| member | spacing [mm] | layout | RMS [%] | Hausdorff [%] | height [%] | unreachable gaps "
            "| springs short | cones | inserts per size | covered [%] | tuning steps (stop) | MuJoCo at rest "
            "| wall / CPU [s] | misses |")
    lines = [head, "|" + "---|" * 15]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['member']} | failed: {r['error']} |" + " |" * 13)
            continue
        miss = ", ".join(k for k, ok in r["meets"].items() if not ok) or "-"
        lines.append(f"| {r['member']} | {r['spacing_mm']:g} | {r['layout']} | {100 * r['rms']:.3g} | "
                     f"{100 * r['hausdorff']:.3g} | {100 * r['height_error']:+.3g} | {r['unreachable_gaps']} | "
                     f"{r['springs_short']} | {r['cones']} | "
                     + ", ".join(f"{n} x {k}" for k, n in r["inserts_per_size"].items())
                     + f" | {100 * r['covered']:.1f} | {r['tuning_steps']} ({r['tuning_stop']}) | "
                     f"{'yes' if r['mujoco_at_rest'] else 'no'} | {r['wall_s']:.0f} / {r['cpu_s']:.0f} | {miss} |")
    return "\n".join(lines)


def _family(a) -> dict:
    from simfab.deploy import families

    rows = []
    members = [m for arg in a.members or [] for m in arg.split(",") if m] or families.names(tuple(a.rings))
    for m in members:
        try:
            families.member(m)
        except ValueError as e:
            print(f"bench deploy --members: {e}", file=sys.stderr)
            raise SystemExit(2) from None
    for name in members:
        row = _family_row(name)
        rows.append(row)
        if a.rows:
            with open(a.rows, "a") as f:
                f.write(json.dumps(row) + "\n")
    out = dict(benchmark="deploy --family", rows=rows, target_s=TARGET_FAMILY_S,
               members_meeting_all=sum(1 for r in rows if "meets" in r and all(r["meets"].values())),
               members=len(rows))
    if a.table:
        out["table"] = family_table(rows)
    return out


def run(argv) -> dict:
    p = argparse.ArgumentParser(prog="bench deploy")
    p.add_argument("--family", action="store_true", help="the target families on the defaults (issue 42)")
    p.add_argument("--rings", type=int, nargs="+", default=[12, 24], help="--family: the resolutions")
    p.add_argument("--members", nargs="+", help="--family: only these members (shape@rings, spaces or commas between)")
    p.add_argument("--rows", help="--family: append each row to this JSONL file as it finishes")
    p.add_argument("--table", action="store_true", help="--family: also the Markdown table")
    p.add_argument("--scene", default="dome")
    p.add_argument("--scales", type=float, nargs="+", default=[1.0, 1.4, 2.0])
    p.add_argument("--no-scaling", action="store_true")
    p.add_argument("--no-cli", action="store_true")
    p.add_argument("--baseline", metavar="DIR", help="another simfab checkout to compare with (interleaved A/B)")
    p.add_argument("--pairs", type=int, default=3, help="A/B pairs (baseline, this) per case")
    p.add_argument("--ab-scale", type=float, default=2.0, help="scale of the dome's cap in the A/B (2: 165 inserts)")
    a = p.parse_args(argv)
    if a.family:
        out = _family(a)
        out["load_average_1min"] = os.getloadavg()[0]
        return out
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
