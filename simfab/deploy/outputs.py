"""The files of a surface deployment (``simfab deploy surface --out DIR``) and of a unit-cell run
(``simfab deploy``), and their names.

:data:`NAMES` maps each output's label to its file name; :func:`write_all` writes them all
together (none if any write fails): the laser-cut pattern (SVG, DXF), the flattening, pattern
and deviation PNGs, the USD timeline, the simulatable MuJoCo scene, the bill of materials and
the JSON summary. :data:`CELL_NAMES` / :func:`write_cell`: per insert of the unit cell its USD
timeline, deployed MJCF and PNG preview, and the run's ``deploy.json``.
"""

from __future__ import annotations

import os

NAMES = dict(svg="pattern.svg", dxf="pattern.dxf", flat_png="flattening.png", pattern_png="pattern.png",
             deviation_png="deviation.png", usd="deploy.usda", mjcf="deployed.xml", bom="inserts.csv",
             json="surface.json")


def paths(out: str) -> dict:
    """The output files of a surface deployment.

    Args:
        out: the output folder.

    Returns:
        Label -> path of every output in ``out``.
    """
    out = os.path.abspath(out)
    return {k: os.path.join(out, v) for k, v in NAMES.items()}


def write_all(res, summary: dict, out: str) -> dict:
    """Write every output of a run into ``out`` (atomically: all or none).

    Args:
        res: the :class:`simfab.deploy.pipeline.SurfaceRun` of the run.
        summary: its JSON summary (:func:`simfab.deploy.pipeline.summary`, with ``outputs``).
        out: the output folder.

    Returns:
        Label -> path of the files written.
    """
    from simfab.deploy import mjcf_sim, pipeline
    from simfab.deploy import surface_outputs as so
    from simfab.deploy.lasercut import write_dxf, write_svg
    from simfab.io.atomic import atomic_paths, write_json

    p = paths(out)
    with atomic_paths(p) as tmp:
        write_svg(tmp["svg"], res.cut)
        write_dxf(tmp["dxf"], res.cut)
        so.write_flattening_png(tmp["flat_png"], res)
        so.write_pattern_png(tmp["pattern_png"], res)
        so.write_deviation_png(tmp["deviation_png"], res)
        so.write_usd(tmp["usd"], res)
        so.write_bom_csv(tmp["bom"], res)
        sim = res.sim
        if sim is None:
            sc = res.scene
            sim = mjcf_sim.build(res.network.model, res.network.state, res.deployment.final,
                                 density=sc.deploy.density, cfg=sc.mujoco, name="deployed_surface",
                                 body_geoms=pipeline.insert_geoms(res.pattern, res.network))
        sim.save(tmp["mjcf"])
        write_json(tmp["json"], summary)
    return p


#: label -> file name of each insert's outputs of a unit-cell run (in ``out/<insert body>/``)
CELL_NAMES = dict(usd="deploy.usda", mjcf="deployed.xml", png="deployed.png")
#: the unit-cell run's JSON summary (in ``out``)
CELL_JSON = "deploy.json"


def cell_paths(out: str, inserts) -> dict:
    """The output files of a unit-cell run.

    Args:
        out: the output folder.
        inserts: the insert body names.

    Returns:
        (insert, label) -> path of every insert's output, and "json" -> the summary's path.
    """
    out = os.path.abspath(out)
    p = {(n, k): os.path.join(out, n, f) for n in inserts for k, f in CELL_NAMES.items()}
    p["json"] = os.path.join(out, CELL_JSON)
    return p


def write_cell(res, paths: dict, *, mjcf_rods: str = "capsules") -> dict:
    """Write every output of a unit-cell run (atomically: all inserts' files and the summary, or none).

    Args:
        res: the :class:`simfab.deploy.api.CellResult` of the run (its JSON form is the summary).
        paths: :func:`cell_paths` of the output folder.
        mjcf_rods: rods in the deployed MJCF ("capsules", "chain" or "flexcomp").

    Returns:
        ``paths``.
    """
    from simfab.deploy import export
    from simfab.io.atomic import atomic_paths, write_json

    with atomic_paths(paths) as tmp:
        for n, ins in res.inserts.items():
            d = ins.deployment
            export.write_usd(tmp[n, "usd"], d)
            export.write_mjcf(tmp[n, "mjcf"], d, name=f"deployed_{n}", rods=mjcf_rods)
            export.write_png(tmp[n, "png"], tmp[n, "mjcf"])
        write_json(tmp["json"], res.to_json())
    return paths
