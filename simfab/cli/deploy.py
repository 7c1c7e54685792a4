"""simfab deploy: deploy a flat beam unit cell with rigid inserts (discrete elastic rods + MuJoCo inserts).

For every insert body of the scene (default scenes/deploy/unit_cell.xml) the cell's spokes
are drawn onto the insert in quasi-static increments; writes per insert a USD timeline (rods as
curves, the insert as an animated rigid mesh, one time code per increment), the deployed MJCF
(opens in python -m mujoco.viewer) and a PNG preview, and reports the sign of the discrete
Gaussian curvature (dome / saddle) and whether the deployed state is stable.

--json keys: scene, summary_json (path), inserts {BODY: insert_half_size, gap_half_size [m],
  relation (larger/smaller than the gap), kind (dome/saddle), gaussian_curvature and the other
  curvature figures [1/m^2], stable, increments, newton_iterations (per increment), energy [J],
  gaussian_curvature_per_increment, max_bending_strain, outputs {usd, mjcf, png}}.
"""

from __future__ import annotations

import os

HELP = "deploy a flat beam cell with rigid inserts; report dome vs saddle (USD + MJCF + PNG)"
DESCRIPTION = __doc__.split("\n\n", 1)[1] if __doc__ else HELP


def add_args(p) -> None:
    p.add_argument("--scene", default=None, help="unit-cell MJCF scene (default scenes/deploy/unit_cell.xml)")
    p.add_argument("--insert", nargs="+", metavar="BODY", help="insert bodies to deploy (default: all 'insert*' bodies)")
    p.add_argument("--increments", type=int, default=None, help="quasi-static increments (default: scene's cell_increments)")
    p.add_argument("--mjcf-rods", choices=["capsules", "flexcomp"], default="capsules",
                   help="rods in the deployed MJCF: static capsule chains (default) or MuJoCo 1D flexcomp cables")


def run(args) -> dict:
    import dataclasses

    from simfab.deploy import export, unitcell
    from simfab.errors import InputError
    from simfab.io.atomic import atomic_paths, write_json
    from simfab.progress import log

    import simfab.rods  # noqa: F401  (quiet Warp start-up before simfab._warp initializes it)
    from simfab._warp import device as _device

    dev = _device(args.device)
    scene = args.scene or unitcell.default_scene_path()
    cfg, inserts = unitcell.load_cell_scene(scene)
    if args.increments is not None:
        if args.increments < 1:
            raise InputError(f"must be >= 1 (got {args.increments})", where="--increments")
        cfg = dataclasses.replace(cfg, increments=args.increments)
    names = args.insert or sorted(inserts)
    for n in names:
        if n not in inserts:
            raise InputError(f"no insert body {n!r} in the scene (have: {', '.join(sorted(inserts))})", where="--insert")
    out = os.path.abspath(args.out)
    deployments = {}
    for n in names:
        ins = inserts[n]
        log(f"deploy: {n} (half-size {ins.r * 1e3:.1f} mm, gap half-size {cfg.gap * 1e3:.1f} mm)", quiet=args.quiet)
        deployments[n] = unitcell.deploy(cfg, ins, device=dev, quiet=args.quiet)
    # every file of every insert plus the summary appear together (none if any write fails)
    paths = {(n, kind): os.path.join(out, n, f) for n in names
             for kind, f in (("usd", "deploy.usda"), ("mjcf", "deployed.xml"), ("png", "deployed.png"))}
    paths["json"] = os.path.join(out, "deploy.json")
    results = {}
    with atomic_paths(paths) as tmp:
        for n, d in deployments.items():
            ins = d.insert
            export.write_usd(tmp[n, "usd"], d)
            export.write_mjcf(tmp[n, "mjcf"], d, name=f"deployed_{n}", rods=args.mjcf_rods)
            export.write_png(tmp[n, "png"], tmp[n, "mjcf"])
            results[n] = dict(insert_half_size=ins.r, gap_half_size=cfg.gap,
                              relation="larger" if ins.r > cfg.gap else "smaller",
                              **d.curvature, stable=d.stable, increments=len(d.iterations),
                              newton_iterations=d.iterations, energy=d.energy,
                              gaussian_curvature_per_increment=d.curvature_history,
                              max_bending_strain=float(export.bending_strain(d.cell.model, d.states[-1]).max()),
                              outputs={k: paths[n, k] for k in ("usd", "mjcf", "png")})
        summary = dict(scene=str(scene), inserts=results, summary_json=paths["json"])
        write_json(tmp["json"], summary)
    return summary


def demo(ctx) -> dict:
    """The bundled unit cell with its larger and smaller insert (about 10 s)."""
    import argparse

    args = argparse.Namespace(out=ctx.out, seed=ctx.seed, device=ctx.device, quiet=ctx.quiet, json=False,
                              scene=None, insert=None, increments=None, mjcf_rods="capsules")
    res = run(args)
    return dict(out=ctx.out, **{k: dict(kind=v["kind"], gaussian_curvature=v["gaussian_curvature"], stable=v["stable"],
                                        usd=v["outputs"]["usd"]) for k, v in res["inserts"].items()})
