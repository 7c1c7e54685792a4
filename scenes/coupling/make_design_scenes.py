#!/usr/bin/env python
"""Regenerate the bundled rest-shape design scenes (``simfab couple optimize NAME``).

``python scenes/coupling/make_design_scenes.py`` writes, per scene, ``NAME.xml`` (MJCF: the
object, its path, the fixed region and keep sites), ``NAME.toml`` (part, material, simulation and
the ``[design]`` brief) and the part's outline ``NAME_outline.csv`` (x, y in metres, counter-
clockwise). The scenes reproduce the design results of the thesis' coupling chapter:

- standside2d   a square block with a bore and a slot (stiff: yields, large forces) that the
                optimizer turns into a C-clamp-like tight grip on a 20 mm cylinder (the stand side
                of the paddle holder; the AutoConnect comparison)
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))
sys.path.insert(0, str(HERE))

from make_scenes import R_CYL, write_toml  # noqa: E402

T2D = 0.005  # plane-strain thickness [m]


def _ccw(ring: np.ndarray) -> np.ndarray:
    x, y = ring[:, 0], ring[:, 1]
    return ring if np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y) > 0 else ring[::-1]


def polygon_ring(shape) -> np.ndarray:
    shape = shape.buffer(0)
    if shape.geom_type != "Polygon" or len(shape.interiors):
        raise ValueError("design outline must be one polygon without holes")
    return _ccw(np.asarray(shape.exterior.coords)[:-1])


def square_clamp(*, half: float, bore: float, mouth: float, segments: int = 64) -> np.ndarray:
    """Square block [-half, half]^2 with a circular bore of radius ``bore`` at the origin and a slot
    of width ``mouth`` from the bore to the +x face."""
    from shapely.geometry import Point, box

    sq = box(-half, -half, half, half)
    hole = Point(0, 0).buffer(bore, quad_segs=segments // 4)
    slot = box(0.0, -mouth / 2, half + 1e-3, mouth / 2)
    return polygon_ring(sq.difference(hole).difference(slot))


def write_outline(name: str, ring: np.ndarray) -> str:
    from simfab.io.atomic import write_text

    fname = f"{name}_outline.csv"
    write_text(HERE / fname, "".join(f"{x:.9g},{y:.9g}\n" for x, y in ring))
    return fname


def design_scene(name: str, *, doc: str, ring: np.ndarray, target: int, object_geoms, keys, fixed_center,
                 fixed_half, obj: dict, sim: dict, design: dict, material: str = "PLA", keep_sites=(),
                 extra_assets=()):
    from simfab.coupling.geometry import extrude
    from simfab.io.mjcf import MJCFBuilder

    part_mesh = extrude(ring, T2D)
    b = MJCFBuilder(name)
    for aname, V, F in extra_assets:
        b.mesh_asset(aname, V, F)
    b.mesh_asset("part", part_mesh.vertices, part_mesh.faces)
    part = b.body("part")
    b.geom(part, type="mesh", mesh="part", rgba=[0.85, 0.55, 0.25, 1], contype=0, conaffinity=0)
    b.site(part, "fixed", pos=list(fixed_center), size=list(fixed_half), type="box", rgba=[0.2, 0.2, 0.9, 0.4])
    for sname, c, h in keep_sites:
        b.site(part, sname, pos=list(c), size=list(h), type="box", rgba=[0.9, 0.5, 0.1, 0.4])
    p0, q0 = keys[0]
    o = b.body("object", pos=p0, quat=q0, mocap=True)
    for g in object_geoms:
        b.geom(o, contype=0, conaffinity=0, rgba=[0.5, 0.6, 0.7, 1], **g)
    for i, (p, q) in enumerate(keys):
        b.key(f"k{i}", mpos=p, mquat=q)
    b.save(HERE / f"{name}.xml")
    comp = dict(generator="outline", outline=write_outline(name, ring), target_elements=target, thickness=T2D)
    write_toml(HERE / f"{name}.toml", doc, {"name": name, "dim": 2},
               {"material": {"name": material}, "compliant": comp, "object": obj, "fixed": {"site": "fixed"},
                "simulation": sim, "design": design})


def standside(name: str = "standside2d", *, half: float = 0.013, bore: float = 0.0095, mouth: float = 0.017,
              brief: dict | None = None) -> None:
    """Stand side: square block [-half, half]^2, bore slightly smaller than the cylinder, a slot
    narrower than it; the cylinder is pushed in along -x."""
    ring = square_clamp(half=half, bore=bore, mouth=mouth)
    x0 = half + math.sqrt(R_CYL**2 - (mouth / 2) ** 2) + 0.0005  # the cylinder clears the slot's outer corners
    design_scene(
        name,
        doc="Stand side of a paddle holder: a square block with a bore and a slot (initial shape: too stiff,\n"
            "yields) optimized into a tight grip on a 20 mm cylinder within PLA's yield stress.",
        ring=ring, target=450, object_geoms=[dict(type="cylinder", size=[R_CYL, 0.01])],
        keys=[([x0, 0, 0], [1, 0, 0, 0]), ([R_CYL - bore + 0.0002, 0, 0], [1, 0, 0, 0])],
        fixed_center=[-half, 0, 0], fixed_half=[0.0006, half + 0.001, 0.01],
        obj=dict(body="object", samples=50), sim=dict(steps=35),
        design=brief or dict(grip="tight", grip_force=[2.0, float("inf")], insertion_force=[0.0, 30.0], handles=4))


def main() -> None:
    standside()


if __name__ == "__main__":
    main()
