"""``simfab validate <validation>``: simulators checked against analytic mechanics.

Each validation is a function of :mod:`simfab.validate` (``buckling``); this module parses its
flags, calls it, prints its table and exits 1 (:class:`simfab.errors.ValidationFailed`) when a
case misses its tolerance. Validations are registered in :data:`VALIDATIONS`.
"""

from __future__ import annotations

from simfab.deploy import tolerances as _tol
from simfab.errors import InputError

HELP = "validate simulators against analytic mechanics (buckling, ...)"
DESCRIPTION = "Run a validation against closed-form mechanics; see 'simfab validate VALIDATION --help'."

BUCKLING_HELP = "discrete elastic rods vs the exact elastica (rise, force, convergence order, critical load)"
BUCKLING_DESCRIPTION = (
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


def add_buckling_args(p) -> None:
    p.add_argument("--g-over-L", dest="g_over_L", nargs="+", type=_float_list, metavar="R",
                   help="gap ratios g/L in (0, 1) (default 0.99 0.95 0.90 0.80 0.60)")
    p.add_argument("--n", nargs="+", type=_int_list, metavar="N",
                   help="segment counts (even, >= 4; default 20 40 80 160)")
    p.add_argument("--support", choices=["pinned", "clamped", "both"], default="both",
                   help="end conditions of the beam (default both)")
    p.add_argument("--path", choices=["direct", "insert", "both"], default="both",
                   help="end displacement applied directly, through the rigid insert, or both (default)")
    p.add_argument("--scene", default=None, help="elastica MJCF scene (default scenes/deploy/elastica.xml)")


def buckling_kwargs(args) -> dict:
    """``simfab validate buckling``'s flags as :func:`simfab.validate.buckling`'s keyword arguments."""
    return dict(g_over_L=args.g_over_L, n=args.n, support=args.support, path=args.path, scene=args.scene,
                seed=args.seed, device=args.device)


def run_buckling(args) -> dict:
    import os

    from simfab.errors import ValidationFailed
    from simfab.validate import buckling

    r = buckling(out=args.out, progress=not args.quiet, **buckling_kwargs(args))
    if not args.json and not args.quiet:
        _print_table(r.rows)
    if not r.passed:
        raise ValidationFailed(f"{len(r.failures)} case(s) missed tolerance: {'; '.join(r.failures)} "
                               f"(outputs in {os.path.abspath(args.out)})")
    d = r.to_json()
    if not args.json:
        d.pop("rows")
    return d


def _print_table(rows) -> None:
    print(f"{'support':8} {'path':6} {'g/L':>5} {'n':>4} {'delta/L':>9} {'exact':>9} {'rel_err':>9} {'order':>6} "
          f"{'P/P_ex-1':>9} {'sec':>6}")
    for r in rows:
        o = f"{r['order']:.2f}" if r["order"] is not None else "-"
        print(f"{r['support']:8} {r['path']:6} {r['g_over_L']:5.2f} {r['n']:4d} {r['delta_over_L']:9.6f} "
              f"{r['delta_over_L_exact']:9.6f} {r['rel_err']:9.2e} {o:>6} {r['force_rel_err']:9.2e} "
              f"{r['seconds']:6.2f}")


#: validation name -> (help, description, add_args, run)
VALIDATIONS = {
    "buckling": (BUCKLING_HELP, BUCKLING_DESCRIPTION, add_buckling_args, run_buckling),
}


def add_args(p) -> None:
    from simfab.cli import add_common_args

    sub = p.add_subparsers(dest="validation", metavar="VALIDATION", parser_class=type(p))
    for name, (help_, description, add, run_) in VALIDATIONS.items():
        sp = sub.add_parser(name, help=help_, description=description)
        add_common_args(sp)
        add(sp)
        sp.set_defaults(_validation=run_)


def run(args) -> dict:
    run_ = getattr(args, "_validation", None)
    if run_ is None:
        raise InputError(f"choose a validation: {', '.join(VALIDATIONS)}", where="simfab validate")
    return run_(args)


def demo(ctx) -> dict:
    """The buckling validation on a small table (n = 20, 40, 80; g/L = 0.9, 0.6; both supports,
    direct and through the insert): a table small enough for a demo."""
    import argparse

    args = argparse.Namespace(out=ctx.out, seed=ctx.seed, device=ctx.device, quiet=ctx.quiet, json=True,
                              g_over_L=[0.9, 0.6], n=[20, 40, 80], support="both", path="both", scene=None)
    res = run_buckling(args)
    return {"buckling": {k: res[k] for k in ("passed", "convergence_order", "critical_load", "outputs")}}
