"""P2 vs linear elements: cantilever convergence (accuracy per second) and kernel cost per element.

``python tools/bench.py p2 [--dims 2,3] [--levels2-3d 1,2,4 ...] [--no-cost] [--no-knocker] [--table] [--plot P.png]``

Cantilever (simfab.verification.cantilever): L/h = 10, clamped, tip shear load for a 1e-3 L deflection,
n cells through the height (structured: 6-tet cubes / two triangles per square). Per dimension,
element order and level: elements, free dofs, delta / Timoshenko, the error against the
mesh-converged value (Richardson extrapolation of the three finest P2 levels; its difference from
Timoshenko is the clamp's restraint of the Poisson contraction, which beam theory ignores), the
static-solve seconds (Newton with exact-first Hessians, CHOLMOD) and Newton iterations. Summary per
dimension: seconds to get within 2% of the converged value for each order (None: not reached
at the levels run) and linear's error at P2's time to 2%.

Large deflection ("large_deflection"): the same beam with P2 (1 and 2 cells through the height)
under alpha = P L^2 / (E' I) = 1 (tip deflection ~30% of L), for each quadrature rule: tip
deflection over the inextensible elastica's 0.30172 L (Bisshopp & Drucker; shear adds ~+0.5% at
L/h = 10), Newton iterations and seconds: how much the higher-degree rule changes a strongly
nonlinear answer, for its cost.

Real geometry ("knocker3d_opening"): the bundled knocker3d clip (scenes/coupling/knocker3d_part.npz,
4880 linear tets) clamped on its base's back face and opened by a smooth body force on its arms
(+-y, growing quadratically from x = 1 mm to the tips, 0.05 N per arm; consistent loads,
simfab.fem.loads), without contact. Reported: the work of the loads f.u [J] (twice the stored
energy; proportional to the compliance) for linear tets on the scene's mesh and on its red
refinement (8x tets) and for P2 on the scene's mesh (``--knocker-reference`` adds P2 on the
refinement: 180k dofs, minutes). Conforming displacement FEM is too stiff, so every figure is a
lower bound of the true work: the largest is the best estimate, and ratio = work / that one.
The figures of a ``--knocker-reference`` run are in docs/decisions.md ("P2 reference work").

Cost: median wall time per element [us] of ``energy_gradient`` and ``energy_gradient_hessian``
(PSD-projected, assembled into CSR) for linear and P2 (both quadrature rules) on the same corner
mesh (3D: 6-tet box of 3840 tets; 2D: 1280 triangles), slightly stretched (F = 1.01 I).
No published reference figure exists for this comparison (issue 15 quotes 50/79/93% of
Timoshenko's deflection for 2/4/8 linear tets through the thickness).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

TARGET = 0.02  # accuracy target of the summary: within 2% of the converged deflection


def _median_us_per_element(fn, m: int, repeat: int = 5) -> float:
    fn()
    t = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        t.append(time.perf_counter() - t0)
    return round(float(np.median(t)) / m * 1e6, 3)


def _cost(dim: int) -> dict:
    from simfab.fem import elastic
    from simfab.fem.p2 import RULES, to_p2
    from simfab.verification.cantilever import cantilever_model

    lin = cantilever_model(dim, 4 if dim == 3 else 8)
    x1 = lin.rest * 1.01
    m1 = lin.n_elements
    out = {"elements": m1,
           "linear": {"grad_us": _median_us_per_element(lambda: elastic.energy_gradient(lin, x1), m1),
                      "hess_us": _median_us_per_element(lambda: elastic.energy_gradient_hessian(lin, x1), m1)}}
    for (d, degree) in sorted(RULES):
        if d != dim:
            continue
        p2 = to_p2(lin, degree=degree)
        x2 = p2.rest * 1.01
        out[f"p2_degree{degree}"] = {
            "quadrature_points": p2.n_quadrature,
            "grad_us": _median_us_per_element(lambda: elastic.energy_gradient(p2, x2), p2.n_elements),
            "hess_us": _median_us_per_element(lambda: elastic.energy_gradient_hessian(p2, x2), p2.n_elements)}
        out[f"p2_degree{degree}"]["hess_ratio_to_linear"] = round(
            out[f"p2_degree{degree}"]["hess_us"] / out["linear"]["hess_us"], 1)
    return out


def _richardson(levels: list[int], values: list[float]) -> float:
    """Extrapolated limit of values at cell counts n (h ~ 1/n), from the three finest levels with
    the observed order (falls back to the finest value when the sequence is not monotone)."""
    (n1, n2, n3), (v1, v2, v3) = levels[-3:], values[-3:]
    d1, d2 = v2 - v1, v3 - v2
    if d1 == 0 or d2 / d1 <= 0 or d2 / d1 >= 1:
        return v3
    r = n2 / n1
    p = np.log(d1 / d2) / np.log(r)  # assumes n3 / n2 == n2 / n1
    return v3 + d2 / ((n3 / n2) ** p - 1)


def _study(dim: int, levels1: list[int], levels2: list[int], degree: int | None) -> dict:
    from simfab.verification.cantilever import cantilever_model, solve_cantilever

    rows = {1: [], 2: []}
    solve_cantilever(cantilever_model(dim, 1, order=2, degree=degree))  # warm-up: kernel loads
    solve_cantilever(cantilever_model(dim, 2, order=1))
    for order, levels in ((1, levels1), (2, levels2)):
        for n in levels:
            model = cantilever_model(dim, n, order=order, degree=degree)
            r = solve_cantilever(model)
            rows[order].append(dict(order=order, cells_through=n, elements=model.n_elements, dofs=r.dofs,
                                    ratio_timoshenko=r.ratio, seconds=r.seconds, newton_iterations=r.iterations))
    p2 = rows[2]
    converged = _richardson([r["cells_through"] for r in p2], [r["ratio_timoshenko"] for r in p2])
    summary = {"converged_over_timoshenko": round(converged, 5)}
    for order in (1, 2):
        for r in rows[order]:
            r["error_vs_converged"] = r["ratio_timoshenko"] / converged - 1
        ok = [r["seconds"] for r in rows[order] if abs(r["error_vs_converged"]) <= TARGET]
        summary[f"{'linear' if order == 1 else 'p2'}_seconds_to_2pct"] = round(min(ok), 4) if ok else None
    t2 = summary["p2_seconds_to_2pct"]
    if t2 is not None:
        # linear's best error among its runs that took no longer than P2 at 2%
        errs = [abs(r["error_vs_converged"]) for r in rows[1] if r["seconds"] <= t2]
        summary["linear_error_at_p2_time"] = round(min(errs), 4) if errs else None
    t1 = summary["linear_seconds_to_2pct"]
    summary["speedup_to_2pct"] = round(t1 / t2, 1) if (t1 and t2) else None
    table = []
    for r in rows[1] + rows[2]:
        table.append({k: (round(v, 5) if isinstance(v, float) else v) for k, v in r.items()})
    return {"rows": table, "summary": summary}


def _large_deflection(dim: int) -> list[dict]:
    from simfab.fem.p2 import RULES
    from simfab.verification.cantilever import cantilever_model, solve_cantilever

    elastica = 0.3017207738  # tip deflection / L at alpha = 1 (tests/fem/test_fem_statics.py shoots it)
    rows = []
    for n in (1, 2):
        for degree in sorted(d for (dd, d) in RULES if dd == dim):
            r = solve_cantilever(cantilever_model(dim, n, order=2, degree=degree), rel_deflection=1.0 / 3.0)
            rows.append(dict(cells_through=n, quadrature_degree=degree,
                             delta_over_elastica=round(r.delta / elastica, 5),
                             newton_iterations=r.iterations, seconds=round(r.seconds, 4)))
    return rows


def _knocker3d(reference: bool) -> dict:
    from simfab.coupling.scene import bundled_dir
    from simfab.fem.loads import body_force_loads
    from simfab.fem.model import make_model
    from simfab.fem.p2 import to_p2
    from simfab.fem.subdivide import subdivide
    from simfab.verification.cantilever import static_solve

    data = np.load(bundled_dir() / "knocker3d_part.npz")
    P, T = data["points"], data["elements"]
    x0, x_tip = 1.0e-3, float(P[:, 0].max())

    def density(X):  # +-y on the arms, quadratic ramp from x0 to the tips [N/m^3, scaled below]
        w = np.clip((X[:, 0] - x0) / (x_tip - x0), 0, None) ** 2
        return np.c_[np.zeros(len(X)), np.sign(X[:, 1]) * w, np.zeros(len(X))]

    def solve(model, label):
        X = model.rest
        fixed = X[:, 0] < X[:, 0].min() + 1e-6  # nodes within 1 um of the base's back face
        f = body_force_loads(model, density)
        f *= 0.05 / f[X[:, 1] > 0, 1].sum()  # 0.05 N resultant per arm
        t0 = time.perf_counter()
        x, res = static_solve(model, X, ~fixed, f)
        return dict(model=label, elements=model.n_elements, dofs=int((~fixed).sum() * 3),
                    work_J=float(np.sum(f * (x - X))), seconds=round(time.perf_counter() - t0, 3),
                    newton_iterations=res.iterations)

    lin0 = make_model(P, T, "PLA")
    P1, T1, _ = subdivide(P, T)
    lin1 = make_model(P1, T1, "PLA")
    rows = [solve(lin0, "linear, scene mesh"), solve(lin1, "linear, refined once"),
            solve(to_p2(lin0), "P2, scene mesh")]
    if reference:
        rows.append(solve(to_p2(lin1), "P2, refined once"))
    best = max(r["work_J"] for r in rows)
    for r in rows:
        r["ratio_to_best"] = round(r["work_J"] / best, 4)
        r["work_J"] = float(f"{r['work_J']:.5g}")
    return {"rows": rows, "note": "conforming displacement FEM underestimates the work: each value is a lower bound"}


def _plot(out: dict, path: str) -> str:
    """|error vs the converged deflection| against solve seconds, linear and P2, per dimension."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    from simfab.io.atomic import atomic_path

    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), constrained_layout=True)
    for ax, dim in zip(axes, (2, 3)):
        study = out.get(f"cantilever_{dim}d")
        if study is None:
            ax.set_visible(False)
            continue
        for order, style, label in ((1, "o-", "linear (P1)"), (2, "s-", "quadratic (P2)")):
            rows = [r for r in study["rows"] if r["order"] == order]
            t = [r["seconds"] for r in rows]
            err = [100 * abs(r["error_vs_converged"]) for r in rows]
            ax.loglog(t, err, style, label=label)
            for r, ti, ei in zip(rows, t, err):
                ax.annotate(f"{r['cells_through']}", (ti, ei), textcoords="offset points", xytext=(4, 4), fontsize=7)
        ax.axhline(100 * TARGET, color="gray", ls="--", lw=1, label=f"{100 * TARGET:.0f}% target")
        ax.set_xlabel("static solve time [s]")
        ax.set_ylabel("|tip deflection error| vs mesh-converged [%]")
        ax.set_title(f"{dim}D cantilever L/h = 10 ({'6-tet cubes' if dim == 3 else '2 triangles per square'})\n"
                     "labels: cells through the height", fontsize=9)
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.grid(True, which="both", lw=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("Accuracy per second: linear vs P2 Neo-Hookean elements (python tools/bench.py p2)", fontsize=10)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)
    return path


def _print_table(study: dict, dim: int) -> None:
    import sys

    conv = study["summary"]["converged_over_timoshenko"]
    print(f"{dim}D cantilever, L/h = 10 (delta / Timoshenko; error vs the converged {conv})",
          file=sys.stderr)
    print(f"{'order':>5} {'n':>3} {'elements':>8} {'dofs':>7} {'delta/Tim':>9} {'error':>8} {'solve s':>8} {'its':>3}",
          file=sys.stderr)
    for r in study["rows"]:
        print(f"{'P' + str(r['order']):>5} {r['cells_through']:>3} {r['elements']:>8} {r['dofs']:>7} "
              f"{r['ratio_timoshenko']:>9.4f} {100 * r['error_vs_converged']:>7.2f}% {r['seconds']:>8.3f} "
              f"{r['newton_iterations']:>3}", file=sys.stderr)


def run(argv) -> dict:
    ap = argparse.ArgumentParser(prog="bench p2")
    ap.add_argument("--dims", default="2,3")
    ap.add_argument("--levels1-2d", default="1,2,4,8,16", help="linear, 2D: cells through the height")
    ap.add_argument("--levels2-2d", default="1,2,4,8", help="P2, 2D (ratio 2 between the last three)")
    ap.add_argument("--levels1-3d", default="1,2,3,4,6,8", help="linear, 3D")
    ap.add_argument("--levels2-3d", default="1,2,4", help="P2, 3D (ratio 2 between the last three)")
    ap.add_argument("--degree", type=int, default=None, help="P2 quadrature degree (default: the model default)")
    ap.add_argument("--no-cost", action="store_true", help="skip the per-element kernel cost")
    ap.add_argument("--table", action="store_true", help="also print readable tables on stderr")
    ap.add_argument("--plot", default=None, help="write the accuracy-per-second plot to this PNG")
    ap.add_argument("--no-knocker", action="store_true", help="skip the knocker3d real-geometry check")
    ap.add_argument("--knocker-reference", action="store_true", help="add P2 on the refined knocker mesh (minutes)")
    a = ap.parse_args(argv)
    from simfab.fem.p2 import DEFAULT_DEGREE
    from simfab.io.outpaths import check_out_file

    if a.plot:  # before the study runs (the plot is drawn after it)
        check_out_file(a.plot, where="--plot", suffixes=(".png",))

    out = {"benchmark": "p2", "target_error": TARGET}
    for dim in (int(d) for d in a.dims.split(",")):
        parse = lambda s: [int(v) for v in s.split(",")]  # noqa: E731
        l1 = parse(getattr(a, f"levels1_{dim}d"))
        l2 = parse(getattr(a, f"levels2_{dim}d"))
        study = _study(dim, l1, l2, a.degree)
        study["quadrature_degree"] = a.degree or DEFAULT_DEGREE[dim]
        if a.table:
            _print_table(study, dim)
        study["large_deflection"] = _large_deflection(dim)
        if not a.no_cost:
            study["cost_per_element"] = _cost(dim)
        out[f"cantilever_{dim}d"] = study
    if a.plot:
        out["plot"] = _plot(out, a.plot)
    if not a.no_knocker:
        out["knocker3d_opening"] = _knocker3d(a.knocker_reference)
        if a.table:
            import sys

            print("knocker3d opened by a body force on its arms (work f.u, lower bounds)", file=sys.stderr)
            for r in out["knocker3d_opening"]["rows"]:
                print(f"  {r['model']:<22} {r['elements']:>7} tets {r['dofs']:>7} dofs  work {r['work_J']:.4g} J  "
                      f"{100 * r['ratio_to_best']:6.1f}%  {r['seconds']:.2f} s", file=sys.stderr)
    return out
