"""``simfab validate buckling``: the elastica table (light module: heavy imports inside run)."""

from __future__ import annotations

import os

from simfab._warp import device as _device
from simfab.deploy import buckling as bk
from simfab.deploy import elastica
from simfab.deploy import tolerances as _tol
from simfab.deploy import tolerances as tol
from simfab.errors import InputError, ValidationFailed
from simfab.io.atomic import atomic_paths, save_figure, write_csv, write_json
from simfab.progress import log

HELP = "discrete elastic rods vs the exact elastica (rise, force, convergence order, critical load)"
DESCRIPTION = (
    "Push a beam of length L into gaps g < L (pinned or clamped ends) and compare the midspan rise and "
    "axial force with the exact elastica (g/L = 2E/K - 1, delta/L = k/K); also through the rigid-insert "
    "path (the moving end attached to the MuJoCo insert body of scenes/deploy/elastica.xml) and the "
    "critical load from the straight beam's Hessian. Writes buckling.csv, buckling.json and "
    "buckling_shapes.png to --out. Columns: rel_err = |delta - delta_exact| / delta_exact, order = observed "
    "convergence order against the next coarser n, force_rel_err = |P - P_exact| / P_exact, seconds = wall time "
    "of the quasi-static continuation from the straight beam to that g/L. "
    f"Exit status 1 when a case at n = {_tol.VALIDATION_N} misses its tolerance (pinned rise "
    f"{_tol.PINNED_RISE_RTOL:.1%}, clamped rise {_tol.CLAMPED_RISE_RTOL:.0%}, force {_tol.FORCE_RTOL:.0%}, "
    f"pinned critical load {_tol.CRITICAL_LOAD_RTOL:.1%}).\n\n"
    "--json keys: passed, failures (list), convergence_order {support: median order}, "
    "insert_vs_direct_max_rel_diff, critical_load (list per support: support, n, load figures [N], rel_err, "
    "tolerance), tolerances {n, pinned_rise, clamped_rise, force, critical_load}, beam (setup: lengths [m], "
    "young [Pa], poisson, ...), scene, "
    "outputs {csv, json, png}, rows (one per case, the CSV columns)."
)


def _float_list(text: str) -> float:

    try:
        return float(text)
    except ValueError:
        raise InputError(f"--g-over-L expects numbers, got {text!r}") from None


def _int_list(text: str) -> int:

    try:
        return int(text)
    except ValueError:
        raise InputError(f"--n expects integers, got {text!r}") from None


def add_args(p) -> None:
    p.add_argument("--g-over-L", dest="g_over_L", nargs="+", type=_float_list, metavar="R",
                   help="gap ratios g/L in (0, 1) (default 0.99 0.95 0.90 0.80 0.60)")
    p.add_argument("--n", nargs="+", type=_int_list, metavar="N",
                   help="segment counts (even, >= 4; default 20 40 80 160)")
    p.add_argument("--support", choices=["pinned", "clamped", "both"], default="both",
                   help="end conditions of the beam (default both)")
    p.add_argument("--path", choices=["direct", "insert", "both"], default="both",
                   help="end displacement applied directly, through the rigid insert, or both (default)")
    p.add_argument("--scene", default=None, help="elastica MJCF scene (default scenes/deploy/elastica.xml)")


def run(args) -> dict:
    import numpy as np


    ratios = list(args.g_over_L or bk.DEFAULT_RATIOS)
    ns = sorted(set(args.n or bk.DEFAULT_N))
    for r in ratios:  # checked before any work
        elastica.check_ratio(r)
    for n in ns:
        bk.check_segments(n)
    supports = elastica.SUPPORTS if args.support == "both" else (args.support,)
    paths = bk.PATHS if args.path == "both" else (args.path,)
    scene = bk.load_insert_scene(args.scene or bk.default_scene_path())
    setup = scene.setup
    import simfab.rods  # noqa: F401  (quiet Warp start-up before simfab._warp initializes it)

    dev = _device(args.device)

    rows, shapes = [], {}
    for support in supports:
        for path in paths:
            for n in ns:
                log(f"buckling: {support} {path} n={n}", quiet=args.quiet)
                for row in bk.run_continuation(setup, support, n, ratios, path=path, device=dev, keep_states=True):
                    shapes[(support, path, n, row["g_over_L"])] = row.pop("shape")
                    row["tolerance"] = tol.RISE_RTOL[support] if n == tol.VALIDATION_N else None
                    rows.append(row)
    rows.sort(key=lambda r: (r["support"], r["path"], -r["g_over_L"], r["n"]))

    # observed convergence order between consecutive n (per support, path, g/L)
    orders = []
    for r in rows:
        prev = [q for q in rows if (q["support"], q["path"], q["g_over_L"]) == (r["support"], r["path"], r["g_over_L"])
                and q["n"] < r["n"]]
        r["order"] = None
        if prev:
            q = max(prev, key=lambda q: q["n"])
            if q["rel_err"] > 0 and r["rel_err"] > 0:
                r["order"] = float(np.log(q["rel_err"] / r["rel_err"]) / np.log(r["n"] / q["n"]))
                orders.append((r["support"], r["order"]))
    order_summary = {s: float(np.median([o for ss, o in orders if ss == s])) for s in supports
                     if any(ss == s for ss, _ in orders)}

    # insert path vs direct path
    insert_vs_direct = None
    if len(paths) == 2:
        diffs = []
        for r in rows:
            if r["path"] == "insert":
                d = next(q for q in rows if q["path"] == "direct" and (q["support"], q["n"], q["g_over_L"]) ==
                         (r["support"], r["n"], r["g_over_L"]))
                diffs.append(abs(r["delta_over_L"] - d["delta_over_L"]) / d["delta_over_L"])
        insert_vs_direct = float(max(diffs))

    crit = []
    n_crit = tol.VALIDATION_N if tol.VALIDATION_N in ns else max(ns)
    for support in supports:
        c = bk.critical_load(setup, n_crit, support, device=dev)
        c["tolerance"] = tol.CRITICAL_LOAD_RTOL if support == "pinned" else None
        crit.append(c)

    failures = []
    for r in rows:
        if r["n"] == tol.VALIDATION_N:
            r["passed"] = bool(r["rel_err"] <= tol.RISE_RTOL[r["support"]] and r["force_rel_err"] <= tol.FORCE_RTOL)
            if not r["passed"]:
                failures.append(f"{r['support']} {r['path']} g/L={r['g_over_L']} (rise {r['rel_err']:.2e}, "
                                f"force {r['force_rel_err']:.2e})")
        else:
            r["passed"] = None
    for c in crit:
        if c["tolerance"] is not None and c["n"] == tol.VALIDATION_N and c["rel_err"] > c["tolerance"]:
            failures.append(f"critical load {c['support']} ({c['rel_err']:.2e})")
    if insert_vs_direct is not None and insert_vs_direct > tol.INSERT_VS_DIRECT_RTOL:
        failures.append(f"insert path differs from direct path by {insert_vs_direct:.2e}")

    out = os.path.abspath(args.out)
    header = ["support", "path", "g_over_L", "n", "delta_over_L", "delta_over_L_exact", "rel_err", "order", "force",
              "force_exact", "force_rel_err", "seconds", "newton_iterations", "tolerance", "passed"]
    outputs = dict(csv=os.path.join(out, "buckling.csv"), json=os.path.join(out, "buckling.json"),
                   png=os.path.join(out, "buckling_shapes.png"))
    summary = dict(passed=not failures, failures=failures, convergence_order=order_summary,
                   insert_vs_direct_max_rel_diff=insert_vs_direct, critical_load=crit,
                   tolerances=dict(n=tol.VALIDATION_N, pinned_rise=tol.PINNED_RISE_RTOL,
                                   clamped_rise=tol.CLAMPED_RISE_RTOL, force=tol.FORCE_RTOL,
                                   critical_load=tol.CRITICAL_LOAD_RTOL),
                   beam=dict(vars(setup)), scene=scene.path)
    with atomic_paths(outputs) as tmp:  # the three files appear together
        write_csv(tmp["csv"], header, [[r[h] for h in header] for r in rows])
        _plot(tmp["png"], shapes, rows, ratios, supports, paths, ns, setup.length)
        write_json(tmp["json"], dict(summary, rows=rows))
    if not args.json and not args.quiet:
        _print_table(rows)
    if failures:
        raise ValidationFailed(f"{len(failures)} case(s) missed tolerance: {'; '.join(failures)} (outputs in {out})")
    result = dict(summary, outputs=outputs)
    if args.json:
        result["rows"] = rows
    return result


def _print_table(rows) -> None:
    print(f"{'support':8} {'path':6} {'g/L':>5} {'n':>4} {'delta/L':>9} {'exact':>9} {'rel_err':>9} {'order':>6} "
          f"{'P/P_ex-1':>9} {'sec':>6}")
    for r in rows:
        o = f"{r['order']:.2f}" if r["order"] is not None else "-"
        print(f"{r['support']:8} {r['path']:6} {r['g_over_L']:5.2f} {r['n']:4d} {r['delta_over_L']:9.6f} "
              f"{r['delta_over_L_exact']:9.6f} {r['rel_err']:9.2e} {o:>6} {r['force_rel_err']:9.2e} "
              f"{r['seconds']:6.2f}")


def _plot(path, shapes, rows, ratios, supports, paths, ns, L):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt


    n_show = tol.VALIDATION_N if tol.VALIDATION_N in ns else max(ns)
    fig, axes = plt.subplots(len(supports), 1, figsize=(8, 3.2 * len(supports)), squeeze=False)
    for ax, support in zip(axes[:, 0], supports):
        for i, r in enumerate(sorted(set(ratios), reverse=True)):
            ex = elastica.solve(r, support).shape(1.0, 301)
            ax.plot(ex[:, 0], ex[:, 1], color=f"C{i}", lw=1.5, label=f"exact g/L={r:.2f}")
            sim = shapes.get((support, paths[0], n_show, r))
            if sim is not None:
                ax.plot(sim[:, 0] / L, sim[:, 1] / L, "o", color=f"C{i}", ms=2.5, mfc="none")
        ax.set_title(f"{support} ends: exact elastica (lines) vs DER n={n_show} (markers, {paths[0]} path)")
        ax.set_xlabel("x / L")
        ax.set_ylabel("z / L")
        ax.set_aspect("equal")
        ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    return save_figure(fig, path)
