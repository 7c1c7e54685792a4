"""simfab grow: generative support structures (space colonization), skinned for printing.

    simfab grow SCENE.xml [--attractors N --influence D --kill D --branch-length L
                           --mode volume|surface|profile --symmetric --smooth-iterations K]
    simfab grow new OBJECT... --root X,Y,Z --target X,Y,Z ... [--mass KG ...] --out DIR
    simfab grow edit SKELETON.json --stroke STROKE.json --camera CAMERA.json [--chain K]
    simfab grow check SKELETON.json [--load TARGET=FX,FY,FZ ...] [--strengthen SF [--thin]]
    simfab grow SCENE.xml --check [--load ...] [--strengthen SF [--thin]]

SCENE is an MJCF file with a companion TOML (see scenes/growth/README.md). Outputs under
--out: skin STL + PLY (mm), skeleton JSON, USD growth replay, MJCF of objects + grown part,
PNG preview and the preview's camera (JSON, the --camera of 'grow edit'). 'edit' moves one
skeleton chain onto the surface of rays through a 2D stroke and re-skins the result.
'check' (or --check after growing) tetrahedralizes the skin, clamps it where it meets the object
under its roots, loads it with the supported objects' weights, its own weight and [loads] /
--load, and reports the safety factor against yield, the peak von Mises stress, each target's
deflection and the mass (USD stage and stress PNG under --out); --strengthen SF thickens the
overloaded branches (and with --thin thins the over-strong ones) until the safety factor is SF.
"""

from __future__ import annotations

import glob
import os
from pathlib import Path

from simfab._bundled import scenes_dir

#: units of summary keys for the plain-text table (the skin files themselves are in mm: skin_units)
UNITS = {"buckling_factor": "-", "influence": "m", "kill": "m", "branch_length": "m", "volume": "m³",
         "overlap_volume": "m³", "penetration": "m", "seconds_growth": "s", "seconds_skin": "s", "safety_factor": "-",
         "max_von_mises_Pa": "Pa", "max_point_von_mises_Pa": "Pa", "yield_stress_Pa": "Pa", "mass_kg": "kg",
         "critical_distance_m": "m", "max_deflection_m": "m", "seconds_check": "s", "max_move": "m"}

HELP = "grow a support structure between objects (space colonization) and skin it for 3D printing"
DESCRIPTION = (
    "Grow an organic support structure from root sites to target sites of an MJCF scene by space "
    "colonization with target attractors (volume, surface or extruded-profile attractors, optional mirror "
    "symmetry, obstacle avoidance), prune, smooth and skin it into one watertight printable mesh. Writes skin "
    "STL/PLY, skeleton JSON, a USD growth replay, an MJCF of objects + grown part and a PNG preview. "
    "'simfab grow edit SKELETON_JSON --stroke FILE --camera FILE' moves one skeleton chain onto the surface of "
    "rays through a 2D stroke and re-skins it. Scene format: scenes/growth/README.md.\n\n"
    "A sample edit: 'simfab grow scenes/growth/phone_stand.xml' then 'simfab grow edit "
    "simfab-out/grow/phone_stand_skeleton.json --stroke scenes/growth/phone_stand_stroke.json --camera "
    "simfab-out/grow/phone_stand_preview_camera.json' (the stroke is drawn in the preview PNG's pixels).\n\n"
    "--json keys (grow): scene, mode, symmetric, seed, attractors, influence, kill, branch_length [m], steps, "
    "stop_reasons, targets_total, targets_reached, targets_unreached (names), nodes, segments, nodes_grown, "
    "collisions_resolved, collisions_unresolved, dead_ends, dropped_oscillating, seconds_growth [s], watertight, "
    "is_volume, bodies, volume [m^3], nodes_in_skin, overlap_volume [m^3], penetration [m], skin_attempts, "
    "objects_subtracted, objects_not_manifold, seconds_skin [s], skin_units, and the paths skin_stl, skin_ply, "
    "skeleton_json, usd, mjcf, png, camera_json, and outputs (label -> path of every file written).\n\n"
    "--json keys (edit): chain, segments_colliding and the other edit figures, nodes, segments, watertight, bodies, "
    "volume [m^3], skin_units, skeleton_json, skin_stl, skin_ply, png (the edit seen through --camera, the "
    "stroke in red).\n\n"
    "--json keys (check, and grow --check under 'check'): safety_factor, max_von_mises_Pa (critical-distance "
    "mean), peak_point_m, max_point_von_mises_Pa, deflection_m (per target), max_deflection_m, mass_kg, volume_m3, "
    "material, yield_stress_Pa, critical_distance_m, target_forces_N, targets (per load point: object, touching, "
    "gap_m, contact_area_m2, min_contact_area_m2, load_N), supported_objects (per object: mass_kg, mass_source, "
    "weight_N, carried_by), dropped_weight_N, mesher, tets, fem_nodes, seconds_check, check_usd, "
    "check_png, with --buckling buckling_factor; with --strengthen also 'strengthened' (the same figures of the "
    "final design plus target_safety_factor, reached, checks, safety_factor_before/after, volume_before/after_m3, "
    "volume_change, skeleton_json, skin_stl, check_usd, check_png)."
)

SCENES_DIR = scenes_dir("growth")


def add_args(p):
    p.add_argument("scene", metavar="SCENE", help="growth scene (MJCF .xml), or the word 'edit' (sketch edit) or "
                                                  "'check' (structural check of a skeleton)")
    p.add_argument("skeleton", nargs="?", metavar="SKELETON_JSON",
                   help="(edit, check) skeleton JSON written by simfab grow")
    g = p.add_argument_group("growth")
    g.add_argument("--attractors", type=int, metavar="N", help="number of random attractors (default 2000)")
    g.add_argument("--influence", type=float, metavar="D", help="attractor influence distance [m]")
    g.add_argument("--kill", type=float, metavar="D", help="attractor kill distance [m]")
    g.add_argument("--branch-length", type=float, metavar="L", help="branch length per growth step [m]")
    g.add_argument("--mode", choices=["volume", "surface", "profile"], help="attractor placement")
    g.add_argument("--symmetric", action="store_true", default=None, help="mirror-symmetric growth")
    g.add_argument("--smooth-iterations", type=int, metavar="K", help="smoothing iterations (0 = none)")
    g.add_argument("--max-steps", type=int, metavar="K", help="growth step cap (default: the scene's)")
    g.add_argument("--best-effort", action="store_true",
                   help="keep and write a structure that leaves targets unreached, and check a support that "
                        "leaves a supported object's weight without a load path (default: both fail, exit 1, "
                        "nothing written; with it: a warning, the summary names the dropped weight)")
    c = p.add_argument_group("structural check")
    c.add_argument("--check", action="store_true", help="check the grown support under its loads (see 'check')")
    c.add_argument("--load", action="append", metavar="TARGET=FX,FY,FZ",
                   help="extra force [N] on a target site, world frame (repeatable; replaces the scene's [loads] "
                        "entry for that target)")
    c.add_argument("--strengthen", type=float, metavar="SF",
                   help="thicken overloaded branches until the safety factor against yield is at least SF")
    c.add_argument("--thin", action="store_true", help="(with --strengthen) also thin over-strong branches down to SF")
    c.add_argument("--buckling", action="store_true",
                   help="also the linearized buckling factor of the loads (critical loads = factor x loads)")
    e = p.add_argument_group("edit")
    e.add_argument("--stroke", metavar="FILE", help="(edit) stroke: JSON {\"points\": [[x, y], ...]} or CSV, pixels")
    e.add_argument("--camera", metavar="FILE|JSON", help="(edit) camera: eye, target, up, fovy_deg, width, height")
    e.add_argument("--chain", type=int, metavar="K", help="(edit) chain index (default: the one nearest the stroke)")
    from simfab.cli import grow_new

    grow_new.add_args(p)  # simfab grow new OBJECT... --root --target: a scene from the user's meshes


#: upper bounds of the count options (beyond them a run would exhaust memory rather than finish)
COUNT_LIMITS = {"--attractors": 1_000_000, "--max-steps": 100_000}


def _positive(name, v):
    from simfab.errors import InputError

    if v is not None and not (v > 0 and v < float("inf")):
        raise InputError(f"must be a positive finite number, got {v}", where=name)
    if v is not None and name in COUNT_LIMITS and v > COUNT_LIMITS[name]:
        raise InputError(f"must be at most {COUNT_LIMITS[name]}, got {v}", where=name)
    return v


def run(args) -> dict:
    from simfab.cli import grow_new
    from simfab.errors import InputError
    from simfab.growth import run as grow_run
    from simfab.progress import log

    if args.scene == "new":
        return grow_new.run(args)
    if grow_new.misused(args):
        raise InputError("OBJECT..., --root, --target, --mass, --no-plate and --name belong to 'simfab grow new'")
    if args.scene == "edit":
        if args.check or args.load or args.strengthen is not None or args.thin or args.buckling:
            raise InputError("--check, --load, --strengthen, --thin and --buckling do not apply to 'edit'")
        return _run_edit(args)
    if args.scene == "check":
        return _run_check(args)
    if args.skeleton is not None or args.stroke or args.camera or args.chain is not None:
        raise InputError("SKELETON_JSON, --stroke, --camera and --chain belong to 'simfab grow edit'")
    loads, target = _check_options(args)
    res = grow_run(args.scene, out=args.out, seed=args.seed, progress=lambda m: log(m, quiet=args.quiet),
                   check=bool(args.check), best_effort=args.best_effort, loads=loads, strengthen=target,
                   thin=args.thin, buckling=args.buckling, symmetric=args.symmetric, **growth_overrides(args))
    return summary_json(res)


def growth_overrides(args) -> dict:
    """The growth flags given, as :class:`simfab.io.tables.Override` s named after their flags
    (a refused value, alone or against a scene value, is blamed on the flag)."""
    from simfab.io.tables import Override, flag_overrides

    ov = flag_overrides({"attractors": _positive("--attractors", args.attractors),
                         "influence": _positive("--influence", args.influence), "kill": _positive("--kill", args.kill),
                         "branch_length": _positive("--branch-length", args.branch_length), "mode": args.mode,
                         "max_steps": _positive("--max-steps", args.max_steps)})
    if args.smooth_iterations is not None:
        ov["smoothing_iterations"] = Override(_nonneg(args.smooth_iterations), "--smooth-iterations")
    return ov


#: keys left out of the --json object when None (they do not apply to that run)
OPTIONAL_KEYS = ("check", "buckling_factor", "strengthened", "skeleton", "scene")


def summary_json(res) -> dict:
    """The ``--json`` object of a GrowthResult / CheckResult: its ``to_json()`` without the
    :data:`OPTIONAL_KEYS` that are None (no check, no buckling, no strengthening, no skeleton file)."""

    def prune(d: dict) -> dict:
        return {k: prune(v) if k in ("check", "strengthened") and isinstance(v, dict) else v
                for k, v in d.items() if not (k in OPTIONAL_KEYS and v is None)}

    return prune(res.to_json())


def _check_options(args):
    """(--load forces name -> (3,) [N], --strengthen SF or None), validated."""
    from simfab.errors import InputError

    if args.thin and args.strengthen is None:
        raise InputError("--thin goes with --strengthen SF", where="--thin")
    target = args.strengthen
    if target is not None and not (0 < target < float("inf")):
        raise InputError(f"must be a positive finite number, got {target}", where="--strengthen")
    loads = {}
    for item in args.load or []:
        name, sep, vec = item.partition("=")
        try:
            f = [float(v) for v in vec.split(",")]
        except ValueError:
            f = []
        if not sep or not name or len(f) != 3 or not all(abs(v) < float("inf") for v in f):
            raise InputError(f"expected TARGET=FX,FY,FZ (newtons), got {item!r}", where="--load")
        loads[name.strip()] = tuple(f)
    return loads, target


def _run_check(args) -> dict:
    from simfab.errors import InputError
    from simfab.growth import check
    from simfab.progress import log

    if args.skeleton is None:
        raise InputError("simfab grow check needs SKELETON_JSON")
    for name in ("attractors", "influence", "kill", "branch_length", "mode", "symmetric", "smooth_iterations",
                 "max_steps", "stroke", "camera", "chain"):
        if getattr(args, name, None) not in (None, False):
            raise InputError(f"--{name.replace('_', '-')} does not apply to 'check'")
    loads, target = _check_options(args)
    res = check(args.skeleton, out=args.out, loads=loads, strengthen=target, thin=args.thin, buckling=args.buckling,
                best_effort=args.best_effort, progress=lambda m: log(m, quiet=args.quiet))
    d = summary_json(res)
    return {"skeleton": d.pop("skeleton", str(args.skeleton)), "scene": d.pop("scene", None), **d}


def _nonneg(v):
    from simfab.errors import InputError

    if v is not None and v < 0:
        raise InputError(f"must be >= 0, got {v}", where="--smooth-iterations")
    return v


def _run_edit(args) -> dict:
    from simfab.errors import InputError
    from simfab.growth import edit
    from simfab.progress import log

    if args.skeleton is None:
        raise InputError("simfab grow edit needs SKELETON_JSON")
    if not args.stroke or not args.camera:
        raise InputError("simfab grow edit needs --stroke FILE and --camera FILE|JSON")
    for name in ("attractors", "influence", "kill", "branch_length", "mode", "symmetric", "smooth_iterations"):
        if getattr(args, name) is not None:
            raise InputError(f"--{name.replace('_', '-')} applies to growth, not to 'edit'")
    res = edit(args.skeleton, stroke=args.stroke, camera=args.camera, chain=args.chain, out=args.out,
               progress=lambda m: log(m, quiet=args.quiet))
    return res.to_json()


def bundled_scenes() -> list[Path]:
    """The growth scenes shipped in ``scenes/growth``."""
    return sorted(Path(p) for p in glob.glob(str(SCENES_DIR / "*.xml")))


def demo(ctx) -> dict:
    """Grow and skin every bundled scene (outputs in ctx.out/<scene>/), then the sample sketch
    edit of the phone stand (scenes/growth/phone_stand_stroke.json over its preview)."""
    import argparse

    from simfab.growth import run as grow_run
    from simfab.progress import log

    res = {}
    for path in bundled_scenes():
        log(f"  grow {path.stem}", quiet=ctx.quiet)
        s = summary_json(grow_run(path, out=os.path.join(ctx.out, path.stem), seed=ctx.seed))
        res[path.stem] = {k: s[k] for k in ("targets_total", "targets_reached", "nodes", "segments", "watertight",
                                            "bodies", "volume", "seconds_growth", "seconds_skin", "png", "usd")}
        if path.stem == "phone_stand":
            camera, skeleton = s["camera_json"], s["skeleton_json"]
    log("  grow edit phone_stand (sample stroke)", quiet=ctx.quiet)
    args = argparse.Namespace(scene="edit", skeleton=skeleton, stroke=str(SCENES_DIR / "phone_stand_stroke.json"),
                              camera=camera, chain=None, out=os.path.join(ctx.out, "phone_stand_edit"),
                              quiet=ctx.quiet, **{k: None for k in ("attractors", "influence", "kill", "branch_length",
                                                                     "mode", "symmetric", "smooth_iterations")})
    e = _run_edit(args)
    return {"scenes": res, "edit": {k: e[k] for k in ("chain", "max_move", "watertight", "bodies", "skin_stl")}}
