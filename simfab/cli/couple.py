"""simfab couple: quasi-static insertion simulation of a rigid object into a compliant part.

Usage:

    simfab couple simulate SCENE [--steps N | --h-in H] [--L-max L] [--fix-all-axes | --fixed-axes AXES] [--no-refine]
                                 [--element-order 1|2] [--friction MU]
    simfab couple optimize SCENE [--grip tight|loose] [--insertion-force LO HI] ... [--iterations N]
    simfab couple study handles SCENE [--counts K ...] [--random N]
    simfab couple converge SCENE [--factors 0.25,0.5,1,1.5] [--element-order 1|2] [--friction MU]
    simfab couple scenes
    simfab couple new PART OBJECT --into AXIS_OR_POINT [--fixed REGION] [--depth D | --to-rest] --out DIR

SCENE is a coupling scene: NAME.xml (MJCF: the object O as the mocap body 'object' with
keyframes for its path, the box site 'fixed') plus NAME.toml (the compliant part A, its
material and the simulation options); a bare NAME refers to a bundled scene in
scenes/coupling ('simfab couple scenes' lists them). Scene format: scenes/coupling/README.md.

Outputs under --out: NAME_profile.csv (one row per record: distance along the path [m], energy [J],
forces [N], stress [Pa], penetration [m], Newton iterations, phase, ...; every column's meaning is
in NAME_summary.json's profile_columns), NAME_summary.json (the --json summary), NAME_profile.png
(energy solid, force dashed, markers at E_max and E_ss), NAME.usda (A's deforming mesh with a
von_mises primvar, O's animated transform) and NAME.xml (MJCF for the viewer: A at the steady
state, O with one keyframe per step). Described in docs/guide/coupling.rst, "Outputs".
"""

from __future__ import annotations

import argparse
from pathlib import Path

SIMULATE_DESCRIPTION = """Run an insertion simulation of a coupling scene and write its deformation profile
(CSV, JSON, PNG), a USD replay and an MJCF scene for the viewer under --out.

--json keys: scene, category (tight/loose/.../none: no contact), E_max, E_ss [J], coupling_ratio [%], F_in, F_rm,
  F_grip [N], s_max, s_ss [m] (path length at E_max / steady state), max_von_mises [Pa] (the raw
  element maximum over the insertion), averaged_von_mises [Pa] (the von Mises stress averaged over
  stress_radius [m] around each element, the figure the design's yield constraint reads: the
  scene's [design] stress_radius, default 0.5 mm), yield_stress [Pa], max_penetration,
  penetration_tolerance [m], min_det_F, steps, newton_iterations,
  elements, element_order, nodes, kappa_initial, kappa_final [N/m], dhat [m], object_samples, seconds [s],
  time_split [s] per resource (assembly, factorization, solves, contact_field, barrier, line_search,
  predictor, total), phase_split [s] per
  phase of the insertion loop (warm_start, newton, facet_check, record, rigid_check, other),
  friction [-] (the Coulomb coefficient used: [contact] friction or --friction, 0 = frictionless),
  F_hold [N] (with friction: the force to start sliding O out of its seat), removal_steps,
  newton_iterations_removal, dissipated [J] (work friction dissipated over both traversals),
  energy_balance [-] (|work on the part - stored - dissipated| / E_max over both traversals),
  lag_solves_per_step, jammed_at [m] (where a frictional insertion self-locked, else null),
  warnings, units {key: unit}, profile_columns {CSV column: meaning, unit and sign convention},
  and the output paths profile_csv, plot_png, usd, mjcf,
  profile_json. With friction F_rm is read from the removal and the category may be "jams" or
  "held by friction"."""

HELP = "simulate inserting a rigid object into a compliant part (deformation profile, grip, forces)"
DESCRIPTION = __doc__


def add_args(p):
    sub = p.add_subparsers(dest="couple_command", metavar="ACTION", parser_class=type(p))
    s = sub.add_parser("simulate", help="run an insertion simulation of a coupling scene",
                       description=SIMULATE_DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    s.add_argument("scene", metavar="SCENE", help="NAME.xml (+ NAME.toml) or a bundled scene name")
    s.add_argument("--steps", type=int, metavar="N", help="number of insertion steps (overrides the scene)")
    s.add_argument("--h-in", type=float, metavar="H", help="insertion step along the path [m]")
    s.add_argument("--L-max", dest="L_max", type=float, metavar="L", help="insertion length [m] (default: whole path)")
    s.add_argument("--fix-all-axes", action="store_true", default=None, help="fix the fixed region in all axes")
    s.add_argument("--fixed-axes", metavar="AXES",
                   help='axes the fixed region is held along, e.g. "xz" (must include the insertion axis)')
    s.add_argument("--no-refine", action="store_true", help="no refinement points on boundary edges/faces")
    s.add_argument("--element-order", type=int, choices=(1, 2), metavar="{1,2}",
                   help="1: linear elements, 2: quadratic (6-node triangles / 10-node tets, no bending "
                        "locking) on the scene's mesh (overrides the scene's [simulation] element_order)")
    s.add_argument("--friction", type=float, metavar="MU",
                   help="Coulomb friction coefficient between object and part (overrides the scene's [contact] "
                        "friction; 0: frictionless; printed PLA: ~0.2-0.5)")
    conv = sub.add_parser("converge", help="mesh-convergence study of a coupling scene",
                          description="Run a scene at refined meshes (element count x each factor; an extruded "
                                      "part's layers x factor^(1/3)) and report the profile figures, their "
                                      "extrapolated values and the error of the scene's own mesh. Writes "
                                      "NAME_converge.json (the report), NAME_converge.csv (one row per level: "
                                      "each figure's value and relative error) and NAME_converge.png (each "
                                      "figure's error against the element count) to --out.\n\n--json keys: "
                                      "scene, levels (factor, elements, seconds, category; layers for an "
                                      "extruded part), figures (per figure: values, extrapolated, order, "
                                      "relative_error), error_of_default, warnings (levels that are the same "
                                      "mesh, levels an extrusion's whole layers refine unequally, fits that are "
                                      "no power law), "
                                      "table, outputs {json, csv, png}.",
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    conv.add_argument("scene", metavar="SCENE", help="NAME.xml (+ NAME.toml) or a bundled scene name")
    conv.add_argument("--factors", default="0.25,0.5,1,1.5",
                      help="refinement factors of the scene's element count (default 0.25,0.5,1,1.5)")
    conv.add_argument("--element-order", type=int, choices=(1, 2), metavar="{1,2}",
                      help="element order at every level (default: the scene's)")
    conv.add_argument("--friction", type=float, metavar="MU",
                      help="Coulomb friction coefficient at every level (default: the scene's [contact] friction)")
    listing = sub.add_parser("scenes", help="list the bundled coupling scenes",
                             description="List the bundled coupling scenes (scenes/coupling); each runs with "
                                         "'simfab couple simulate NAME'. Writes nothing.\n\n--json keys: scenes "
                                         "(list of scene names).")
    from simfab.cli import add_common_args, couple_design

    o = sub.add_parser("optimize", help="optimize the part's rest shape for the scene's design brief",
                       description=couple_design.OPTIMIZE_DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    couple_design.add_optimize_args(o)
    st = sub.add_parser("study", help="handle-placement study (displacement vs spatial vs random)",
                        description=couple_design.STUDY_DESCRIPTION,
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    couple_design.add_study_args(st)
    from simfab.cli import couple_new

    couple_new.register(sub, add_common_args)  # simfab couple new: a scene from the user's meshes
    for q in (s, conv, listing, o, st):
        add_common_args(q)  # e.g. 'simfab couple scenes --json'


def run(args) -> dict:
    from simfab.errors import InputError

    cmd = getattr(args, "couple_command", None)
    if cmd == "scenes":
        from simfab.coupling.scene import bundled_dir

        return {"scenes": sorted(p.stem for p in bundled_dir().glob("*.xml"))}
    if cmd == "new":
        from simfab.cli import couple_new

        return couple_new.run(args)
    if cmd in ("optimize", "study"):
        from simfab.cli import couple_design

        return couple_design.run_optimize(args) if cmd == "optimize" else couple_design.run_study(args)
    if cmd == "converge":
        import simfab.couple
        from simfab.coupling.converge import format_table
        from simfab.io.tables import flag_overrides
        from simfab.progress import log

        try:
            factors = tuple(float(f) for f in args.factors.split(","))
        except ValueError:
            raise InputError(f"must be comma-separated numbers, got {args.factors!r}", where="--factors") from None
        flags = flag_overrides({"element_order": args.element_order, "friction": args.friction})
        rep = simfab.couple.converge(args.scene, factors=factors, out=args.out, device=args.device,
                                     progress=not args.quiet, **flags)
        for w in rep.warnings:  # warnings show even with --quiet
            log(f"simfab: warning: {w}")
        return {**rep.to_json(), "table": "\n" + format_table(rep)}
    if cmd != "simulate":
        raise InputError("choose an action: 'simfab couple simulate SCENE', 'optimize SCENE', 'study handles SCENE' "
                         "or 'scenes'")
    return simulate_summary(args.scene, out=args.out, device=args.device, quiet=args.quiet, **simulate_overrides(args))


def simulate_overrides(args) -> dict:
    """``simfab couple simulate``'s flags as the scene overrides of :func:`simfab.coupling.run`."""
    from simfab.errors import InputError

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
    if args.element_order is not None:
        sim["element_order"] = args.element_order
    from simfab.io.tables import flag_overrides

    contact = flag_overrides({"friction": args.friction})
    return {"simulation": sim, "contact": contact}


def api_call(args):
    """The area function a ``couple`` command line calls (for sweeps), or None."""
    from simfab.sweep.runs import ApiCall

    cmd = getattr(args, "couple_command", None)
    if cmd == "simulate":
        return ApiCall(command="couple simulate", args=(args.scene,),
                       kwargs=dict(seed=args.seed, device=args.device, **simulate_overrides(args)))
    if cmd == "optimize":
        from simfab.cli import couple_design

        return ApiCall(command="couple optimize", args=(args.scene,),
                       kwargs=dict(seed=args.seed, device=args.device, **couple_design.optimize_kwargs(args)))
    return None


def simulate_summary(scene, *, out, device: str, quiet: bool, **overrides) -> dict:
    """``simfab.coupling.run`` with the CLI's logging: its warnings on stderr (also with --quiet)."""
    from simfab.coupling import run
    from simfab.progress import log

    result = run(scene, out=out, device=device, progress=not quiet, **overrides)
    for m in result.warnings:  # warnings show even with --quiet
        log(f"simfab: warning: {m}")
    return result.to_json()


#: Iteration cap of the demo's design run (the scene's brief allows 300; the gradient method, the default,
#: stops at simfab.design.gradient.MAX_ITERATIONS).
DEMO_DESIGN_ITERATIONS = 80


def demo(ctx) -> dict:
    """The 2D C-clamp (tight grip) and the 3D clip on a cylinder; then the building block's rest
    shape (block2d_tight, 450 triangles) optimized for its design brief (tight, 3-5 N grip,
    below the yield stress) by the default method (gradient), checked on refined
    meshes (and corrected, if it misses the brief there)."""
    from simfab.design import run as design
    from simfab.progress import log

    out = Path(ctx.out)
    a = simulate_summary("cclamp2d", out=out, device=ctx.device, quiet=ctx.quiet)
    b = simulate_summary("clip3d", out=out, device=ctx.device, quiet=ctx.quiet)
    keys = ("category", "E_max", "E_ss", "coupling_ratio", "F_in", "F_rm", "F_grip", "max_von_mises",
            "averaged_von_mises", "yield_stress", "seconds", "usd", "plot_png", "mjcf")
    r = design("block2d_tight", out=out / "design", iterations=DEMO_DESIGN_ITERATIONS, device=ctx.device,
               progress=not ctx.quiet)
    for w in r.warnings:  # warnings show even with --quiet
        log(f"simfab: warning: {w}")
    d = r.to_json()
    design = {k: d[k] for k in ("feasible", "E_L", "iterations", "simulations", "seconds")}
    design["constraints"] = {k: v["satisfied"] for k, v in d["constraints"].items()}
    design["feasible_mesh_converged"] = d["mesh_check"]["feasible_fine"]
    design.update({k: d["outputs"][k] for k in ("profile_png", "shape_png", "scene_xml", "part_stl")})
    return {"cclamp2d": {k: a[k] for k in keys}, "clip3d": {k: b[k] for k in keys}, "block2d_tight_design": design}
