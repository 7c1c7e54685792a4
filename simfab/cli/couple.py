"""``simfab couple``: quasi-static insertion simulation of a rigid object into a compliant part.

Usage::

    simfab couple simulate SCENE [--steps N | --h-in H] [--L-max L] [--fix-all-axes | --fixed-axes AXES] [--no-refine]
    simfab couple converge SCENE [--factors 0.25,0.5,1,1.5]
    simfab couple scenes

SCENE is a coupling scene: ``NAME.xml`` (MJCF: the object O as the mocap body ``object`` with
keyframes for its path, the box site ``fixed``) plus ``NAME.toml`` (the compliant part A, its
material and the simulation options); a bare NAME refers to a bundled scene in
``scenes/coupling`` (``simfab couple scenes`` lists them). See :mod:`simfab.coupling.scene`.

Outputs under ``--out``: NAME_profile.csv (per step: distance [m], energy [J], insertion force
[N] (support reactions along O's translation), path force [N] (work-conjugate force along the
path, = -dE/ds, also defined during rotations), grip [N], max von Mises [Pa], max penetration [m],
min det F, Newton iterations), NAME_summary.json
(category, E_max, E_ss [J], coupling_ratio [%], F_in, F_rm, F_grip [N], max_von_mises [Pa],
max_penetration [m], min_det_F, steps, newton_iterations, seconds, time_split [s] per resource
(assembly, factorization, contact), phase_split [s] per phase of the insertion loop (warm_start,
newton, facet_check, record, rigid_check, other) and the output paths),
NAME_profile.png (energy solid, force dashed, markers at E_max and E_ss), NAME.usda (A's deforming
mesh with a von_mises primvar, O's animated transform, one time code per step) and NAME.xml (MJCF
for the viewer: A at the steady state, O with one keyframe per step).
"""

from __future__ import annotations

from pathlib import Path

HELP = "simulate inserting a rigid object into a compliant part (deformation profile, grip, forces)"
DESCRIPTION = __doc__


def add_args(p):
    sub = p.add_subparsers(dest="couple_command", metavar="ACTION", parser_class=type(p))
    s = sub.add_parser("simulate", help="run an insertion simulation of a coupling scene",
                       description="Run an insertion simulation of a coupling scene and write its profile.")
    s.add_argument("scene", metavar="SCENE", help="NAME.xml (+ NAME.toml) or a bundled scene name")
    s.add_argument("--steps", type=int, metavar="N", help="number of insertion steps (overrides the scene)")
    s.add_argument("--h-in", type=float, metavar="H", help="insertion step along the path [m]")
    s.add_argument("--L-max", dest="L_max", type=float, metavar="L", help="insertion length [m] (default: whole path)")
    s.add_argument("--fix-all-axes", action="store_true", default=None, help="fix the fixed region in all axes")
    s.add_argument("--fixed-axes", metavar="AXES",
                   help='axes the fixed region is held along, e.g. "xz" (must include the insertion axis)')
    s.add_argument("--no-refine", action="store_true", help="no refinement points on boundary edges/faces")
    conv = sub.add_parser("converge", help="mesh-convergence study of a coupling scene",
                          description="Run a scene at refined meshes (element count x each factor) and report "
                                      "the profile figures, their extrapolated values and the error of the scene's own mesh.")
    conv.add_argument("scene", metavar="SCENE", help="NAME.xml (+ NAME.toml) or a bundled scene name")
    conv.add_argument("--factors", default="0.25,0.5,1,1.5",
                      help="refinement factors of the scene's element count (default 0.25,0.5,1,1.5)")
    listing = sub.add_parser("scenes", help="list the bundled coupling scenes")
    from simfab.cli import add_common_args

    add_common_args(s)
    add_common_args(conv)
    add_common_args(listing)  # e.g. 'simfab couple scenes --json'


def run(args) -> dict:
    from simfab.errors import InputError

    cmd = getattr(args, "couple_command", None)
    if cmd == "scenes":
        from simfab.coupling.scene import bundled_dir

        return {"scenes": sorted(p.stem for p in bundled_dir().glob("*.xml"))}
    if cmd == "converge":
        from simfab.coupling.converge import format_table, study

        try:
            factors = tuple(float(f) for f in args.factors.split(","))
        except ValueError:
            raise InputError(f"must be comma-separated numbers, got {args.factors!r}", where="--factors") from None
        if len(factors) < 2 or min(factors) <= 0:
            raise InputError("give at least two positive factors", where="--factors")
        rep = study(args.scene, factors, quiet=args.quiet)
        return {**rep, "table": "\n" + format_table(rep)}
    if cmd != "simulate":
        raise InputError("choose an action: 'simfab couple simulate SCENE' or 'simfab couple scenes'")
    sim = {}
    if args.steps is not None:
        if args.steps < 1:
            raise InputError(f"must be >= 1, got {args.steps}", where="--steps")
        sim["steps"] = args.steps
        sim["h_in"] = None
    if args.h_in is not None:
        if not args.h_in > 0:
            raise InputError(f"must be a positive length [m], got {args.h_in}", where="--h-in")
        sim["h_in"] = args.h_in
    if args.L_max is not None:
        if not args.L_max > 0:
            raise InputError(f"must be a positive length [m], got {args.L_max}", where="--L-max")
        sim["L_max"] = args.L_max
    if args.fix_all_axes:
        sim["fix_all_axes"] = True
        sim["fixed_axes"] = None  # overrides the scene's choice
    elif args.fixed_axes is not None:
        sim["fixed_axes"] = args.fixed_axes
        sim["fix_all_axes"] = False
    if args.no_refine:
        sim["refine"] = False
    return simulate_scene(args.scene, out=args.out, device=args.device, quiet=args.quiet, simulation=sim)


def simulate_scene(scene, *, out, device: str = "cpu", quiet: bool = True, simulation: dict | None = None,
                   stem: str | None = None) -> dict:
    """Load a coupling scene, run the insertion and write every output; returns the summary."""
    from simfab._warp import device as check_device  # quiet Warp initialization
    from simfab.coupling.outputs import write_all
    from simfab.coupling.scene import load_coupling_scene
    from simfab.coupling.simulate import check_start, simulate
    from simfab.progress import log

    dev = check_device(device)
    cm = load_coupling_scene(scene, overrides={"simulation": simulation or {}}, device=dev)
    check_start(cm)  # before the log line: bad input gives exactly one line on stderr
    log(f"couple: {cm.name}: {cm.fem.n_elements} elements, {len(cm.field.vertices)} object samples, "
        f"{len(cm.s_steps) - 1} steps", quiet=quiet)
    res = simulate(cm, quiet=quiet)
    for m in res.warnings:  # warnings show even with --quiet
        log(f"simfab: warning: {m}")
    return write_all(res, Path(out), stem=stem)


def demo(ctx) -> dict:
    """The 2D C-clamp (tight grip) and the 3D clip on a cylinder."""
    out = Path(ctx.out)
    a = simulate_scene("cclamp2d", out=out, device=ctx.device, quiet=ctx.quiet)
    b = simulate_scene("clip3d", out=out, device=ctx.device, quiet=ctx.quiet)
    keys = ("category", "E_max", "E_ss", "coupling_ratio", "F_in", "F_rm", "F_grip", "max_von_mises", "seconds",
            "usd", "plot_png", "mjcf")
    return {"cclamp2d": {k: a[k] for k in keys}, "clip3d": {k: b[k] for k in keys}}
