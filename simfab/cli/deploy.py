"""simfab deploy: deploy flat beam patterns with rigid inserts (discrete elastic rods + MuJoCo inserts).

    simfab deploy                      # the unit cell (scenes/deploy/unit_cell.xml)
    simfab deploy surface TARGET       # target surface -> laser-cut pattern -> deployment

surface TARGET: TARGET is a scene TOML (scenes/deploy/dome.toml, saddle.toml, mixed.toml,
or a bundled name: dome, saddle, mixed, cap80, saddle_steep, petal) or a disk-topology mesh
(OBJ/STL/PLY, --units). It flattens the target (BFF, u = 0 on the boundary; with cone
singularities and cuts when the scene's [cuts] max_cones > 0), lays out the beam / spring /
insert pattern with gaps from the area distortion, writes the laser-cut SVG + DXF (mm), deploys the pattern
(rods + free inserts), compares it with the target after the best rigid alignment, and writes a
MuJoCo scene that simulates (it opens on the deployed state; the flat pattern is the springs'
rest state and keyframe 'flat'), checked for stability and against simfab's equilibrium.
Outputs in --out: pattern.svg, pattern.dxf, flattening.png, pattern.png, deviation.png,
deploy.usda, deployed.xml, inserts.csv (bill of materials: inserts per size), surface.json.

Unit cell: for every insert body of the scene (default scenes/deploy/unit_cell.xml) the spokes are drawn
onto the insert in quasi-static increments; writes per insert a USD timeline (rods as curves, the insert
an animated rigid mesh, a time code per increment), the deployed MJCF (python -m mujoco.viewer) and a
PNG, and reports the sign of the discrete Gaussian curvature (dome / saddle) and the stability.

--json keys: scene, summary_json (path), inserts {BODY: insert_half_size, gap_half_size [m],
  relation (larger/smaller than the gap), kind (dome/saddle), gaussian_curvature and the other
  curvature figures [1/m^2], stable, increments, newton_iterations (per increment), energy [J],
  gaussian_curvature_per_increment, max_bending_strain, outputs {usd, mjcf, png}}.
"""

from __future__ import annotations

import os

HELP = "deploy flat beam patterns with rigid inserts: the unit cell, or 'surface TARGET' (target -> laser-cut pattern)"
DESCRIPTION = __doc__.split("\n\n", 1)[1] if __doc__ else HELP


def add_args(p) -> None:
    p.add_argument("action", nargs="?", choices=["surface"], help="'surface': deploy a pattern onto a target surface")
    p.add_argument("target", nargs="?", help="surface: scene TOML, bundled name (dome, saddle, mixed, "
                   "cap80, saddle_steep, petal) or mesh file")
    g = p.add_argument_group("surface options (override the scene's)")
    g.add_argument("--units", choices=["m", "mm", "cm"], default=None, help="units of a target mesh file (default m)")
    g.add_argument("--spacing", type=float, help="pattern grid spacing [m]")
    g.add_argument("--beam-width", type=float, help="beam width in the sheet [m]")
    g.add_argument("--beam-thickness", type=float, help="sheet thickness [m]")
    g.add_argument("--insert-size", type=float, help="insert half-size r (clamp distance from its centre) [m]")
    g.add_argument("--young", type=float, help="Young's modulus of the sheet [Pa]")
    g.add_argument("--tune", type=int, metavar="STEPS", help="Gauss-Newton steps tuning the gaps on the deployed "
                   "shape (0: none; scene [tune] iterations)")
    g.add_argument("--no-mujoco-check", action="store_true",
                   help="skip stepping the MuJoCo scene (stability / relaxation)")
    p.add_argument("--scene", default=None, help="unit-cell MJCF scene (default scenes/deploy/unit_cell.xml)")
    p.add_argument("--insert", nargs="+", metavar="BODY",
                   help="insert bodies to deploy (default: all 'insert*' bodies)")
    p.add_argument("--increments", type=int, default=None,
                   help="quasi-static increments (default: scene's cell_increments)")
    p.add_argument("--mjcf-rods", choices=["capsules", "chain", "flexcomp"], default="capsules",
                   help="rods in the deployed MJCF: static capsule chains (default), 'chain': a scene MuJoCo "
                        "simulates (opens on the deployed state; flat rest state of the hinge springs; free insert "
                        "welded to the rods), "
                        "or inextensible MuJoCo 1D flexcomp cables")


def run(args) -> dict:
    if getattr(args, "action", None) == "surface":
        return run_surface(args)
    if getattr(args, "target", None):
        from simfab.errors import InputError

        raise InputError(f"unexpected argument {args.target!r} (did you mean 'simfab deploy surface TARGET'?)")
    return run_cell(args)


def run_surface(args) -> dict:
    import warnings

    import simfab.deploy
    from simfab.deploy import api
    from simfab.errors import InputError

    if not args.target:
        raise InputError("needs a TARGET: scene TOML, bundled name (dome, saddle, mixed, cap80, saddle_steep, "
                         "petal) or mesh file",
                         where="simfab deploy surface")
    from simfab.io.tables import flag_overrides

    flags = flag_overrides({k: getattr(args, k, None) for k in api.OVERRIDES})
    try:
        res = simfab.deploy.run(args.target, out=args.out, device=args.device, units=args.units,
                                progress=None if args.quiet else True,
                                mujoco_check=not getattr(args, "no_mujoco_check", False), **flags)
    except InputError as e:
        if e.where in api.OVERRIDES:  # a keyword of run() is a flag here
            raise InputError(e.message, where=f"--{e.where.replace('_', '-')}") from None
        raise
    summary = res.to_json()
    if res.missed:  # a missed bound is said, with what would help
        warnings.warn(f"{summary['scene']}: deployment bound missed: " + "; ".join(res.missed), stacklevel=2)
    return summary


def format_text(summary: dict) -> str:
    """Compact table of a surface run (the unit-cell run prints key: value lines)."""
    if "deviation" not in summary:
        import json

        return "\n".join(f"{k}: {json.dumps(v) if isinstance(v, (dict, list)) else v}" for k, v in summary.items())
    s, dv, dp, lc = summary, summary["deviation"], summary["deployment"], summary["lasercut"]
    rows = [f"target            {s['target']} ({s['vertices']} vertices)",
            f"flattening        u in [{s['u_min']:.4g}, {s['u_max']:.4g}], area ratio in "
            f"[{s['area_ratio_min']:.4g}, {s['area_ratio_max']:.4g}]",
            f"pattern           {s['quads']} quads, {s['beams']} beams, {s['springs']} springs, {s['inserts']} inserts "
            f"(gaps {s['gap_min_mm']:.3g}..{s['gap_max_mm']:.3g} mm, {len(s['unreachable_gaps'])} unreachable)",
            "inserts (r)       " + ", ".join(f"{b['count']} x {b['half_size_mm']:.3g} mm"
                                             + (f" ({b['size_class']})" if len(s['bill_of_materials']) > 1 else "")
                                             for b in s["bill_of_materials"]),
            f"laser cut         {lc['parts']} parts, cut length {lc['cut_length_mm'] / 1e3:.4g} m, sheet "
            f"{lc['sheet_mm'][0]:.0f} x {lc['sheet_mm'][1]:.0f} mm",
            f"deployed          {dp['kind']} (inserts' local K: {dp['curvature_sign_at_inserts']['positive']} > 0, "
            f"{dp['curvature_sign_at_inserts']['negative']} < 0, target's sign at "
            f"{100 * dp.get('curvature_sign_agreement', float('nan')):.3g} %; quadric fit K "
            f"{dp['quadric_gaussian_curvature']:.4g} 1/m^2), stable: {dp['stable']}",
            f"springs           bulge {s['spring_bulge_min']:.3g}..{s['spring_bulge_max']:.3g} for quad growth up to "
            f"{s['quad_growth_max']:.3g}; {len(s['springs_short_of_slack'])} quads short of the slack",
            f"deviation         RMS {dv['rms'] * 100:.3g} % ({dv['rms_mm']:.3g} mm), "
            f"Hausdorff {dv['hausdorff'] * 100:.3g} % ({dv['hausdorff_mm']:.3g} mm) of D = {dv['diameter_mm']:.0f} mm; "
            f"height {dv['deployed_height_mm']:.3g} mm (target {dv['target_height_mm']:.3g} mm)"]
    cu = s.get("cuts")
    if cu:
        rows.append(f"cuts              {cu['cones']} cones (angle defects "
                    + ", ".join(f"{c['cone_defect_deg']:.3g}" for c in cu["seams"])
                    + f" deg), seams {'joined by ' + str(cu['seam_ties']) + ' ties' if cu['seams_joined'] else 'free'}"
                    f"; pattern covers {100 * cu['flat_area_covered']:.3g} % of the cut flat domain")
    tn = s.get("tuning")
    if tn:
        rows.append(f"tuned gaps        {tn['steps']} Gauss-Newton steps ({tn['solves']} solves), RMS "
                    f"{100 * tn['rms_before']:.3g} % -> {100 * dv['rms']:.3g} %, Hausdorff "
                    f"{100 * tn['hausdorff_before']:.3g} % -> {100 * dv['hausdorff']:.3g} %, gaps changed by up to "
                    f"{tn['gap_change_max_mm']:.3g} mm")
    mj = s.get("mujoco") or {}
    if mj:
        st, rl = mj["stability"], mj["relaxation"]
        rest = "at rest" if st.get("settled") else f"not at rest within {st.get('max_seconds', st['seconds']):.3g} s"
        rows.append(f"MuJoCo            dt {mj['timestep']:.3g} s, {st['seconds']:.3g} s from the key ({rest}, "
                    f"{st['wall_s']:.3g} s wall): "
                    f"{'finite' if st['finite'] else 'BLEW UP'}, max drift {st['max_drift_m'] * 1e3:.3g} mm; "
                    f"relaxed vs simfab: RMS {rl['rms_m'] * 1e3:.3g} mm = {100 * (rl['rms_rel'] or 0):.3g} % of the "
                    f"{rl['out_of_plane_extent_m'] * 1e3:.3g} mm height")
    if s["unreachable_gaps"]:
        rows.append("unreachable gaps  " + ", ".join(
            f"{g['insert']}{g['size_class']}: {g['required_mm']:.3g} mm needed, {g['cut_mm']:.3g} cut "
            f"(deviation there {g['deviation_mm']:.3g} mm)" for g in s["unreachable_gaps"][:8])
            + (f", ... ({len(s['unreachable_gaps'])} in all, surface.json)" if len(s["unreachable_gaps"]) > 8 else ""))
    df = s.get("defaults")
    if df:
        rows.append(f"defaults          decided {', '.join(df['decided']) or 'nothing'}; cuts "
                    f"{'needed' if df['needs_cuts'] else 'not needed'} (uncut growth up to "
                    f"{df['uncut_growth_max']:.3g})")
    bd = s.get("bounds")
    if bd:
        rows.append(f"bounds            RMS {100 * bd['rms']:.3g} % (<= {100 * bd['rms_bound']:g}), height "
                    f"{100 * bd['height_error']:+.3g} % (within {100 * bd['height_bound']:g}), "
                    f"{bd['unreachable_gaps']} gaps unreachable, {bd['springs_short']} springs short of their reach "
                    f"({bd.get('springs_below_slack', 0)} within reach, below the slack margin): "
                    + ("met" if not bd["missed"] else "MISSED - " + "; ".join(bd["missed"])))
    rows.append("seconds           " + ", ".join(f"{k} {v:.3g}" for k, v in s["seconds"].items()))
    rows.append(f"outputs           {os.path.dirname(s['outputs']['json'])}/")
    return "\n".join(rows)


#: keyword of :func:`simfab.deploy.cell` -> its flag (errors name the flag)
CELL_FLAGS = {"increments": "--increments", "inserts": "--insert", "mjcf_rods": "--mjcf-rods"}


def run_cell(args) -> dict:
    import simfab.deploy
    from simfab.errors import InputError

    try:
        res = simfab.deploy.cell(args.scene, out=args.out, inserts=args.insert, increments=args.increments,
                                 mjcf_rods=args.mjcf_rods, device=args.device, progress=None if args.quiet else True)
    except InputError as e:
        if e.where in CELL_FLAGS:
            raise InputError(e.message, where=CELL_FLAGS[e.where]) from None
        raise
    return res.to_json()


def demo(ctx) -> dict:
    """The bundled unit cell with its larger and smaller insert, and the dome surface scene
    (flattening, laser-cut pattern, deployment, deviation, simulatable MJCF; the MuJoCo stepping
    check is left to ``simfab deploy surface dome``, it takes minutes)."""
    import argparse

    args = argparse.Namespace(out=ctx.out, seed=ctx.seed, device=ctx.device, quiet=ctx.quiet, json=False,
                              action=None, target=None, scene=None, insert=None, increments=None, mjcf_rods="capsules")
    res = run(args)
    out = dict(out=ctx.out, **{k: dict(kind=v["kind"], gaussian_curvature=v["gaussian_curvature"], stable=v["stable"],
                                       usd=v["outputs"]["usd"]) for k, v in res["inserts"].items()})
    sargs = argparse.Namespace(out=os.path.join(ctx.out, "surface_dome"), seed=ctx.seed, device=ctx.device,
                               quiet=ctx.quiet, json=False, action="surface", target="dome", units=None, spacing=None,
                               beam_width=None, beam_thickness=None, insert_size=None, young=None, tune=None,
                               no_mujoco_check=True)
    sres = run(sargs)
    out["surface_dome"] = dict(kind=sres["deployment"]["kind"], rms=sres["deviation"]["rms"],
                               hausdorff=sres["deviation"]["hausdorff"], inserts=sres["inserts"],
                               svg=sres["outputs"]["svg"], mjcf=sres["outputs"]["mjcf"])
    return out
