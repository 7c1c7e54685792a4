"""Cost growth of an insertion with the mesh: ``python tools/bench.py insertion --scaling``.

Each level runs in a child process of its own (``--scaling-level SCENE:FACTOR:MU``), so that its
peak resident memory is that level's alone. A level is the insertion benchmark's case
(tools/benchmarks/insertion.py, P2 tets) with its part meshed at FACTOR times the tet count
(simfab.coupling.converge.level_mesh: an extrusion's layers grow as FACTOR^(1/3); claw3d's
generator, meshed by :func:`simfab.fem.meshing.tetrahedralize`, is asked for FACTOR x its stored mesh's tets).
Before its timed run a level runs the scene's 1x case once, untimed (the process's one-time costs:
loading the Warp modules and the libraries; ~0.9 s on clip3d, a third of a cold 1x run, which lowered
the fitted exponent when the timed run was the process's first). The timed run's own setup (its
workspace, its pattern's symbolic analysis) stays in its time. The warm-up's model is released and the
process's peak reset (Linux: ``/proc/self/clear_refs``) before the timed level's model is built, so
the peak memory (``VmHWM``) is the level's, not the warm-up's (where the reset is refused:
``ru_maxrss``, which at 1x holds both models).
Per level: tets, free dofs, steps, seconds (wall, CPU; scene loading and meshing excluded), peak
memory, Newton iterations (and per step), sparse factorizations (numeric, the exact-first attempts
included) and their share of the wall time, the solves lagged on an earlier factorization
(simfab.solve.linear.LagConfig) and their conjugate-gradient iterations (the failed attempts'
included), the solves by p-multigrid conjugate gradients (simfab.solve.pmg.MultigridConfig), their
iterations and coarse factorizations, the triangular solves' share, the assembly's, the factor's fill (entries of L over
entries of the lower triangle of the free Hessian) and the category and figures of the profile. Per
scene and friction: the exponent of a least-squares fit of log(seconds) against log(free dofs),
overall and between consecutive levels.
"""

from __future__ import annotations

import gc
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np

FIGURES = ("E_max", "F_in", "F_rm", "F_grip")


def level_overrides(scene: str, factor: float, base: dict) -> dict:
    """The ``[compliant]`` overrides of ``scene`` at ``factor`` times its benchmark case's tets."""
    from simfab.coupling.converge import level_mesh
    from simfab.coupling.scene import read_scene_toml, scene_paths

    comp = dict(read_scene_toml(scene_paths(scene)[1])["compliant"])
    comp.update(base.get("compliant", {}))
    if factor == 1.0:
        return dict(base.get("compliant", {}))
    out = dict(base.get("compliant", {}))
    if scene == "claw3d":
        # level 1 is the stored mesh: the generator is asked for factor times its tets
        stored = len(np.load(scene_paths(scene)[1].parent / comp["mesh_file"])["elements"])
        out.update(level_mesh(comp, factor * stored / comp["target_elements"]))
        out["mesh_file"] = None
    else:
        out.update(level_mesh(comp, factor))
    return out


def reset_peak_memory() -> bool:
    """Reset this process's peak resident memory (Linux ``clear_refs`` 5: VmHWM := VmRSS); False
    where the kernel refuses it."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def peak_memory_mib(reset: bool) -> float:
    """Peak resident memory [MiB] of this process since :func:`reset_peak_memory` (``reset``), else
    since it started (``ru_maxrss``)."""
    if reset:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def run_level(scene: str, factor: float, mu: float) -> dict:
    """One level in this process (see the module docstring)."""
    from benchmarks.insertion import ORIGINAL_SIZE
    from simfab.coupling.outputs import summarize
    from simfab.coupling.scene import load_coupling_scene
    from simfab.coupling.simulate import simulate_insertion
    from simfab.solve import linear

    base = {k: dict(v) for k, v in ORIGINAL_SIZE.get(scene, {}).items()}

    def model(f: float):
        over = {k: dict(v) for k, v in base.items()}  # (its tables copied: base serves both models)
        over["compliant"] = level_overrides(scene, f, base)
        over.setdefault("contact", {})["friction"] = mu
        return load_coupling_scene(scene, overrides=over)

    simulate_insertion(model(1.0))  # the process's one-time costs, untimed (see the module docstring)
    gc.collect()  # the warm-up's model and run, released before the peak is reset
    reset = reset_peak_memory()
    cm = model(factor)
    solvers = []
    orig = linear.SPDSolver.__init__

    def registered(self, *args, **kwargs):
        orig(self, *args, **kwargs)
        solvers.append(self)

    linear.SPDSolver.__init__ = registered
    try:
        t0, c0 = time.perf_counter(), time.process_time()
        res = simulate_insertion(cm)
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
    finally:
        linear.SPDSolver.__init__ = orig
    count = {k: sum(getattr(s, k, 0) for s in solvers)
             for k in ("factorizations", "lagged_solves", "pcg_iterations", "multigrid_solves", "multigrid_iterations",
                       "coarse_factorizations")}
    count["factorizations"] -= count["coarse_factorizations"]  # the coarse solvers are SPDSolvers too
    rss = peak_memory_mib(reset)
    _, summ = summarize(res)
    records = list(res.steps[1:]) + list(res.removal)
    iters = int(sum(r.iterations for r in records) + res.steps[0].iterations)
    t = dict(res.timings)
    fill = factor_fill(cm, res.steps[-1].x)
    return {
        "scene": scene, "factor": factor, "friction": mu, "tets": int(cm.fem.n_elements),
        "free_dofs": int(np.asarray(cm.free).sum()), "steps": len(records),
        "seconds": round(dt, 2), "cpu_seconds": round(dc, 2), "peak_memory_mib": round(rss, 1),
        "newton_iterations": iters, "newton_iterations_per_step": round(iters / max(1, len(records)), 2),
        "factorizations": count["factorizations"], "lagged_solves": count["lagged_solves"],
        "pcg_iterations": count["pcg_iterations"], "multigrid_solves": count["multigrid_solves"],
        "multigrid_iterations": count["multigrid_iterations"], "coarse_factorizations": count["coarse_factorizations"],
        "factorization_share": round(t.get("factorization", 0.0) / dt, 3),
        "solves_share": round(t.get("solves", 0.0) / dt, 3),
        "assembly_share": round(t.get("assembly", 0.0) / dt, 3),
        "ms_per_factorization": round(1e3 * t.get("factorization", 0.0) / max(1, count["factorizations"]), 1),
        **fill, "category": summ["category"], "figures": {k: float(summ[k]) for k in FIGURES if k in summ},
        "stage_seconds": {k: round(float(v), 2) for k, v in t.items()},
        "load_average_1min": round(os.getloadavg()[0], 2),
    }


def factor_fill(cm, x) -> dict:
    """Entries of the Cholesky factor of the run's free Hessian (CHOLMOD, supernodal, its own
    ordering) against those of the matrix's lower triangle."""
    import cvxopt

    from simfab.coupling.layout import regularize
    from simfab.fem.elastic import energy_gradient_hessian
    from simfab.solve.linear import SPDSolver, import_cholmod

    _, _, H = energy_gradient_hessian(cm.fem, np.asarray(x))
    regularize(cm, H)
    free = np.flatnonzero(np.asarray(cm.free).ravel())
    s = SPDSolver()
    s.solve_free(H, free, np.ones(len(free)))
    L = import_cholmod().getfactor(s._F)
    nnz_l = len(cvxopt.matrix(L.V)) if isinstance(L, cvxopt.spmatrix) else int(L.size[0] * L.size[1])
    nnz_a = len(s._factored)
    return {"factor_entries": int(nnz_l), "matrix_lower_entries": int(nnz_a), "fill": round(nnz_l / nnz_a, 2)}


def exponents(rows: list, key: str = "seconds") -> dict:
    """Least-squares slope of log(rows' ``key``) against log(free dofs), overall and per interval."""
    if len(rows) < 2:
        return {"overall": None, "intervals": []}
    n = np.log([r["free_dofs"] for r in rows])
    t = np.log([r[key] for r in rows])
    slope = float(np.polyfit(n, t, 1)[0])
    return {"overall": round(slope, 2),
            "intervals": [round(float((t[i + 1] - t[i]) / (n[i + 1] - n[i])), 2) for i in range(len(rows) - 1)]}


def plot_scaling(groups: list, path: str) -> None:
    """Log-log plot of CPU and wall seconds and of ms per factorization against free dofs (a group's
    optional "label" names its run, e.g. "main" against a branch: see :func:`main`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    from simfab.coupling.converge import plain_log_ticks

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.2))
    for g in groups:
        ok = [r for r in g["rows"] if "error" not in r]
        if not ok:
            continue
        n = np.array([r["free_dofs"] for r in ok], float)
        lab = f"{g['scene']} mu={g['friction']:g}" + (f" ({g['label']})" if g.get("label") else "")
        line = ax.loglog(n, [r["cpu_seconds"] for r in ok], "o-", label=f"{lab} CPU")[0]
        ax.loglog(n, [r["seconds"] for r in ok], "x--", color=line.get_color(), label=f"{lab} wall")
        fact = np.array([r["ms_per_factorization"] for r in ok], float)
        has = fact > 0  # a level solved by p-multigrid alone has no fine factorization to time
        bx.loglog(n[has], fact[has], "o-", color=line.get_color(), label=lab)
    allrows = [r for g in groups for r in g["rows"] if "error" not in r]
    if allrows:
        n0 = min(r["free_dofs"] for r in allrows)
        t0 = min(r["cpu_seconds"] for r in allrows if r["free_dofs"] == n0)
        nn = np.array([n0, max(r["free_dofs"] for r in allrows)], float)
        ax.loglog(nn, t0 * (nn / n0) ** 1.25, "k:", label="target: dofs^1.25")
    ax.set_xlabel("free dofs")
    ax.set_ylabel("insertion time [s]")
    ax.set_title("Insertion time against mesh size (P2 tets)")
    ax.legend(fontsize=7)
    bx.set_xlabel("free dofs")
    bx.set_ylabel("wall ms per CHOLMOD factorization")
    bx.set_title("Cost of one factorization (wall ms)")
    bx.legend(fontsize=7)
    for a in (ax, bx):
        a.grid(alpha=0.3, which="both")
        plain_log_ticks(a.xaxis, wide=True)  # (one labelled tick, 10000, on 7k-44k dofs before)
        plain_log_ticks(a.yaxis)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run_scaling(scenes, factors, frictions, timeout: float, plot: str | None = None, repeat: int = 1) -> dict:
    """Every level in a child process; rows grouped per (scene, friction) with their exponents. With
    ``repeat`` > 1 every level runs that many times, the levels' order reversed at each round (1, 2, 4, 8,
    8, 4, 2, 1, ...: no level always first or last on a machine whose speed drifts), and each row is its
    level's fastest run (wall), the runs' seconds beside it."""
    groups = []
    print(format_header(), file=sys.stderr, flush=True)  # the rows below as they run
    for scene in scenes:
        for mu in frictions:
            runs: dict = {f: [] for f in factors}
            failed = None
            for k in range(repeat):
                for f in (factors if k % 2 == 0 else factors[::-1]):
                    row = _run_child(scene, f, mu, timeout)
                    print(format_row(row), file=sys.stderr, flush=True)
                    if "error" in row:
                        failed = row
                        break
                    runs[f].append(row)
                if failed:
                    break
            rows = []
            for f in factors:
                if not runs[f]:
                    break
                best = dict(min(runs[f], key=lambda r: r["seconds"]))
                if repeat > 1:
                    best["seconds_runs"] = [r["seconds"] for r in runs[f]]
                    best["cpu_seconds_runs"] = [r["cpu_seconds"] for r in runs[f]]
                rows.append(best)
            if failed:
                rows.append(failed)
            ok = [r for r in rows if "error" not in r]
            groups.append({"scene": scene, "friction": mu, "repeat": repeat, "rows": rows,
                           "time_exponent_vs_dofs": exponents(ok),
                           "cpu_time_exponent_vs_dofs": exponents(ok, "cpu_seconds")})
    if plot:
        plot_scaling(groups, plot)
    table = format_table(groups)
    print(table, file=sys.stderr)  # for the reader: every group's rows with its exponents
    return {"benchmark": "insertion --scaling", "targets": "time ~ dof^<=1.25; clip3d 8x <= 300 s; peak <= 8 GiB",
            "groups": groups, "table": table}


def _run_child(scene: str, factor: float, mu: float, timeout: float) -> dict:
    """One level in a child process (its row, or a row with ``error``)."""
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    cmd = [sys.executable, os.path.join(here, "bench.py"), "insertion", "--scaling-level", f"{scene}:{factor:g}:{mu:g}"]
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"scene": scene, "factor": factor, "friction": mu, "error": f"over {timeout:g} s"}
    if p.returncode != 0:
        last = (p.stderr.strip().splitlines() or ["failed"])[-1]
        return {"scene": scene, "factor": factor, "friction": mu, "error": last}
    return json.loads(p.stdout.strip().splitlines()[-1])


def format_row(r: dict) -> str:
    if "error" in r:
        return f"{r['scene']:8s} {r['factor']:>4g} {r['friction']:>4g}  error: {r['error']}"
    return (f"{r['scene']:8s} {r['factor']:>4g} {r['friction']:>4g} {r['tets']:>7d} {r['free_dofs']:>8d} "
            f"{r['seconds']:>8.1f} {r['cpu_seconds']:>8.1f} {r['peak_memory_mib']:>8.0f} "
            f"{r['newton_iterations_per_step']:>6.2f} {r['factorizations']:>6d} {r.get('lagged_solves', 0):>6d} "
            f"{r.get('pcg_iterations', 0):>6d} {r.get('multigrid_solves', 0):>5d} "
            f"{r.get('multigrid_iterations', 0):>6d} {r['ms_per_factorization']:>8.0f} "
            f"{100 * r['factorization_share']:>6.0f} {100 * r['assembly_share']:>6.0f} {r['fill']:>6.1f}")


def format_header() -> str:
    return (f"{'scene':8s} {'x':>4s} {'mu':>4s} {'tets':>7s} {'dofs':>8s} {'wall s':>8s} {'cpu s':>8s} "
            f"{'peak MiB':>8s} {'it/st':>6s} {'facts':>6s} {'lagged':>6s} {'pcg':>6s} {'mg':>5s} {'mg it':>6s} "
            f"{'ms/fact':>8s} {'fact%':>6s} {'asm%':>6s} {'fill':>6s}")


def format_table(groups: list) -> str:
    lines = [format_header()]
    for g in groups:
        if g.get("repeat", 1) > 1:
            lines.append(f"  {g['scene']} mu={g['friction']:g}: each level's fastest of {g['repeat']} runs")
        lines += [format_row(r) for r in g["rows"]]
        e, c = g["time_exponent_vs_dofs"], g["cpu_time_exponent_vs_dofs"]
        if e["overall"] is None:
            lines.append(f"  {g['scene']} mu={g['friction']:g}: no exponent (fewer than two levels ran)")
            continue
        lines.append(f"  {g['scene']} mu={g['friction']:g}: wall ~ dofs^{e['overall']} (intervals {e['intervals']}),"
                     f" cpu ~ dofs^{c['overall']} (intervals {c['intervals']})")
    return "\n".join(lines)


def parse_level(spec: str) -> tuple[str, float, float]:
    from simfab.errors import InputError

    try:
        scene, f, mu = spec.split(":")
        return scene, float(f), float(mu)
    except ValueError:
        raise InputError(f"--scaling-level must be SCENE:FACTOR:MU, got {spec!r}") from None


def main(argv=None) -> int:
    """``python tools/benchmarks/_scaling.py --plot PNG RUN.json[:LABEL] ...``: one plot of several
    ``insertion --scaling`` outputs (e.g. main's and a branch's levels), each run's groups labelled."""
    import argparse

    ap = argparse.ArgumentParser(prog="_scaling.py", description=main.__doc__.split("\n")[0])
    ap.add_argument("--plot", required=True, help="PNG path")
    ap.add_argument("runs", nargs="+", help="JSON outputs of bench.py insertion --scaling, each optionally :LABEL")
    a = ap.parse_args(argv)
    from simfab.errors import InputError
    from simfab.io.outpaths import check_out_file

    try:
        check_out_file(a.plot, where="--plot", suffixes=(".png",))
    except InputError as e:
        print(f"_scaling.py: error: {e}", file=sys.stderr)
        return 2
    groups = []
    for spec in a.runs:
        path, _, label = spec.partition(":")
        try:
            with open(path) as f:
                run = json.loads(f.read().strip().splitlines()[-1])
        except (OSError, ValueError, IndexError) as e:
            print(f"_scaling.py: error: {path}: {e}", file=sys.stderr)
            return 2
        groups += [{**g, "label": label} for g in run.get("groups", [])]
    plot_scaling(groups, a.plot)
    return 0


if __name__ == "__main__":
    sys.exit(main())
