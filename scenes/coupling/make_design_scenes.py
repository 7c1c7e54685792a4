#!/usr/bin/env python
"""Regenerate the bundled rest-shape design scenes (``simfab couple optimize NAME``).

``python scenes/coupling/make_design_scenes.py`` writes, per scene, ``NAME.xml`` (MJCF: the
object, its path, the fixed region and keep sites), ``NAME.toml`` (part, material, simulation and
the ``[design]`` brief) and the part's outline ``NAME_outline.csv`` (x, y in metres, counter-
clockwise); profile2d's target profile is simulated only when ``profile2d_target.csv`` is missing
or ``--retarget`` is given (the documented profile2d results were obtained against the stored
one). The scenes reproduce the design results of the thesis' coupling chapter:

- standside2d   a square block with a bore and a slot (stiff: yields, large forces) that the
                optimizer turns into a C-clamp-like tight grip on a 20 mm cylinder (the stand side
                of the paddle holder; the AutoConnect comparison)
- alligator2d, alligator3d   an asymmetric clip (thick upper, thin lower jaw) that yields on an
                8 mm rod, to be made to hold it tightly without yielding (3D: the section extruded)
- block2d_loose, block2d_tight, block2d_tighter   one socket around a 20 mm ball (its base kept
                unchanged) optimized to three grips; revolve the results into 3D
- profile2d     the C-clamp with a target force profile to match (profile2d_target.csv)
- knocker3d_design   a stiff clip holding the door-knocker ring (rotating path), to be made loose
                with a small insertion force and no yielding

3D parts are tetrahedralized once into NAME_part.npz (kept unless --remesh; fTetWild is not
bit-reproducible).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))
sys.path.insert(0, str(HERE))

from make_scenes import R_CYL  # noqa: E402

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


def design_scene(name: str, *, doc: str, ring: np.ndarray, target: int, design: dict, **kw):
    """A 2D design scene: the outline as NAME_outline.csv, meshed to ``target`` triangles by the
    scene loader; ``kw`` as for make_scenes.scene (object, path, fixed region, keep sites...)."""
    from make_scenes import scene

    from simfab.coupling.geometry import extrude

    comp = dict(generator="outline", outline=write_outline(name, ring), target_elements=target, thickness=T2D)
    scene(name, doc=doc, dim=2, comp=comp, part_mesh=extrude(ring, T2D), design=design, **kw)


def standside(name: str = "standside2d", *, half: float = 0.0125, bore: float = 0.0095, mouth: float = 0.018,
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


def alligator_outline(*, rod: float, body=(-0.022, 0.008, -0.005, 0.008), pocket: float, mouth: float,
                      hinge: float = 0.0008, hinge_depth: float = 0.016) -> np.ndarray:
    """Alligator clip section: a block x0..x1, y0..y1 with a pocket of radius ``pocket`` at the
    origin, a mouth of width ``mouth`` from the pocket to the +x face and a hinge slot of width
    ``2 hinge`` from the pocket back to x = -hinge_depth; the upper jaw (y > 0) is thicker than the
    lower one (y0 closer to the axis): an asymmetric clip."""
    from shapely.geometry import Point, box

    x0, x1, y0, y1 = body
    blk = box(x0, y0, x1, y1)
    cut = Point(0, 0).buffer(pocket, quad_segs=16)
    cut = cut.union(box(0.0, -mouth / 2, x1 + 1e-3, mouth / 2)).union(box(-hinge_depth, -hinge, 0.0, hinge))
    return polygon_ring(blk.difference(cut))


def alligator2d() -> None:
    rod = 0.004
    body = (-0.022, 0.008, -0.005, 0.008)
    ring = alligator_outline(rod=rod, body=body, pocket=0.0038, mouth=0.0036)
    x0 = body[1] + math.sqrt(rod**2 - 0.0018**2) + 0.0005
    design_scene(
        "alligator2d",
        doc="Alligator clip (2D, PLA): an asymmetric clip (thick upper jaw, thin lower jaw) whose initial shape\n"
            "yields when an 8 mm rod is pushed in; optimized to hold the rod tightly without yielding. Held\n"
            "only along the insertion axis, the clip may shift sideways as the thesis prescribes.",
        ring=ring, target=420, object_geoms=[dict(type="cylinder", size=[rod, 0.01])],
        keys=[([x0, 0, 0], [1, 0, 0, 0]), ([rod - 0.0038 + 0.0001, 0, 0], [1, 0, 0, 0])],
        fixed_center=[body[0], 0, 0], fixed_half=[0.0006, 0.009, 0.01],
        obj=dict(body="object", samples=50), sim=dict(steps=35),
        design=dict(grip="tight", grip_force=[5.0, float("inf")], insertion_force=[0.0, 40.0], handles=5))


def block2d(name: str, doc: str, brief: dict) -> None:
    """Building block: a socket (C-shape) around a 20 mm ball whose base stays unchanged (keep
    site at the arms' roots): the same start for the loose, tight and tighter designs."""
    from simfab.coupling.geometry import c_clamp_outline

    clamp = dict(inner_radius=0.0098, width=0.0028, opening_deg=62.0, base_depth=0.004, base_height=0.02)
    ring = c_clamp_outline(**clamp, segments=48)
    ro = clamp["inner_radius"] + clamp["width"]
    a = math.radians(clamp["opening_deg"])
    tx, ty = clamp["inner_radius"] * math.cos(a), clamp["inner_radius"] * math.sin(a)
    x0 = tx + math.sqrt(max(R_CYL**2 - ty**2, 0.0)) + 0.001
    xb = -ro - clamp["base_depth"]
    design_scene(
        name, doc=doc, ring=ring, target=450, object_geoms=[dict(type="sphere", size=[R_CYL])],
        keys=[([x0, 0, 0], [1, 0, 0, 0]), ([R_CYL - clamp["inner_radius"] + 0.0002, 0, 0], [1, 0, 0, 0])],
        fixed_center=[xb, 0, 0], fixed_half=[0.0006, 0.011, 0.01],
        keep_sites=[("keep", [xb + 0.5 * (clamp["base_depth"] + 0.5 * clamp["width"]), 0, 0],
                     [0.5 * (clamp["base_depth"] + 0.5 * clamp["width"]) + 1e-4, 0.0101, 0.01])],
        obj=dict(body="object", samples=50), sim=dict(steps=25), design=dict(brief, keep=["keep"]))


def profile2d() -> None:
    """Profile matching: the bundled C-clamp's start; the target is the force profile of another
    clamp (thinner arm, larger inner radius) simulated along the same path - a target that some
    shape reaches, so the RMS error measures how close the handles can come."""

    from make_scenes import CLAMP_TIGHT, X_SEATED, x_start

    from simfab.coupling.geometry import c_clamp_outline
    from simfab.coupling.scene import load_coupling_scene
    from simfab.coupling.simulate import simulate_insertion
    from simfab.io.atomic import write_text

    clamp = dict(CLAMP_TIGHT)
    ring = c_clamp_outline(**clamp, segments=48)
    ro = clamp["inner_radius"] + clamp["width"]
    xb = -ro - clamp["base_depth"]
    keys = [([x_start(clamp), 0, 0], [1, 0, 0, 0]), ([X_SEATED, 0, 0], [1, 0, 0, 0])]
    common = dict(ring=ring, target=450, object_geoms=[dict(type="cylinder", size=[R_CYL, 0.01])], keys=keys,
                  fixed_center=[xb, 0, 0], fixed_half=[0.0006, 0.011, 0.01], obj=dict(body="object", samples=50),
                  sim=dict(steps=35))
    # the target: the same path through a clamp of inner radius 9.8 mm and arm width 2.1 mm; kept
    # unless --retarget (the documented profile2d results were obtained against the stored one)
    if not (HERE / "profile2d_target.csv").exists() or "--retarget" in sys.argv:
        variant = dict(clamp, inner_radius=0.0098, width=0.0021)
        design_scene("_profile_target", doc="temporary", **dict(common, ring=c_clamp_outline(**variant, segments=48)),
                     design=dict(grip="any"))
        res = simulate_insertion(load_coupling_scene(HERE / "_profile_target.xml"))
        for suffix in (".xml", ".toml", "_outline.csv"):
            (HERE / f"_profile_target{suffix}").unlink()
        write_text(HERE / "profile2d_target.csv",
                   "distance_m,force_N\n" + "".join(f"{r.s:.9g},{r.force:.9g}\n" for r in res.steps))
    design_scene(
        "profile2d",
        doc="Profile matching (2D C-clamp, PLA): change the clamp until its insertion force profile matches\n"
            "profile2d_target.csv (least squares); compare --handles 2, 4 and 8.",
        **common, design=dict(grip="any", target_profile="profile2d_target.csv", handles=4, placement="spatial"))


def knocker_design() -> None:
    """Door knocker (3D, rotating path): the ring of knocker3d, a clip with thick arms (stiff: the
    initial design needs large forces and yields)."""
    from make_scenes import KNOCK_GEOM, KNOCK_SDF, KNOCK_r, quat_z, scene, x_start

    from simfab.coupling import geometry as G

    # thick, tall arms (thesis-like: the initial clip needs kilonewtons and yields several times over)
    clamp = dict(inner_radius=0.0032, width=0.006, opening_deg=55.0, base_depth=0.003, base_height=0.02)
    hk = 0.012
    ro = clamp["inner_radius"] + clamp["width"]
    xk = x_start(clamp, margin=0.0005, radius=KNOCK_r)
    xs = max(KNOCK_r - clamp["inner_radius"], 0.0) + 0.0001
    name = "knocker3d_design"
    scene(name, doc="Door knocker (design): the knocker ring snapped into a stiff clip and rotated about its bar; the\n"
                    "initial clip needs large forces and yields. Optimize: insertion force <= 20 N, below yield, and\n"
                    "a snap that holds the ring: >= 1 N to push it in, >= 1 N to pull it out.",
          dim=3, comp=dict(generator="extruded_clamp", target_elements=1500, height=hk, **clamp),
          part_mesh=G.extruded_clamp(height=hk, **clamp), sdf_assets=[KNOCK_SDF], object_geoms=[KNOCK_GEOM],
          keys=[([xk, 0, 0], [1, 0, 0, 0]), ([xs, 0, 0], [1, 0, 0, 0]), ([xs, 0, 0], quat_z(-np.pi / 2))],
          fixed_center=[-ro - clamp["base_depth"], 0, 0], fixed_half=[0.0004, 0.011, 0.0065],
          obj=dict(body="object", rot_length_scale=0.005), sim=dict(steps=40, fix_all_axes=True),
          mesh_options=dict(coarsen=True, tol=0.1, tries=6),
          # the thesis' brief (at most 20 N to push the ring in, below yield) and a snap that holds
          # the ring: at least 1 N to pull it out (3x the weight of a 30 g brass ring of this size)
          # and 1 N to push it in. Without an insertion floor the annealer settles on a clip that no
          # longer touches the ring (F_in = F_rm = 0: one flat penalty, lower than a snap's stress
          # penalties on the way). With the exact torus a 2 N floor was not met below yield (600
          # iterations: F_in 1.51 N at 58.9 MPa, P2 8x); with the sampled ring's fattened bar 2 N
          # were, and a 5 N floor was not (2.5-2.8 N at 59-60 MPa)
          design=dict(grip="loose", insertion_force=[1.0, 20.0], removal_force=[1.0, math.inf], handles=5))


def alligator3d() -> None:
    """The 2D alligator's section extruded 6 mm: the 3D version of the same design problem."""
    from make_scenes import scene

    from simfab.coupling.geometry import extrude

    rod, body = 0.004, (-0.022, 0.008, -0.005, 0.008)
    ring = alligator_outline(rod=rod, body=body, pocket=0.0038, mouth=0.0036)
    x0 = body[1] + math.sqrt(rod**2 - 0.0018**2) + 0.0005
    name = "alligator3d"
    scene(name, doc="Alligator clip (3D, PLA): the alligator2d section extruded 6 mm, on an 8 mm rod; held only along\n"
                    "the insertion axis (the original's boundary condition).",
          dim=3, comp=dict(generator="mesh", target_elements=1040), part_mesh=extrude(ring, 0.006),
          object_geoms=[dict(type="cylinder", size=[rod, 0.006])],
          # the path ends 2 mm before the pocket's centre, where the initial clip still draws the rod in: every
          # design is continued to its rest point (the rest search), whereas a planned step past a design's seat
          # pushes the rod into the pocket's back and its grip reads that reaction (docs/decisions.md)
          keys=[([x0, 0, 0], [1, 0, 0, 0]), ([0.002, 0, 0], [1, 0, 0, 0])],
          fixed_center=[body[0], 0, 0], fixed_half=[0.0006, 0.009, 0.004],
          obj=dict(body="object", samples=1154), sim=dict(steps=35), mesh_options=dict(coarsen=True, tol=0.1, tries=6),
          design=dict(grip="tight", grip_force=[5.0, float("inf")], insertion_force=[0.0, 40.0], handles=5,
                      iterations=150, patience=40))


def paddleside() -> None:
    """Paddle side: a U-channel that matches the paddle blade's rounded edge exactly (no contact,
    no grip) - the optimizer must create the grip, with a removal force below the stand side's."""
    from shapely.geometry import Point, box

    r, wall, depth, base = 0.003, 0.0025, 0.012, 0.004  # blade half-thickness, wall, channel depth, base
    c = 1e-4  # "perfect match": 0.1 mm clearance all around (the barrier acts within ~0.01 mm)
    slot = box(0.0, -r - c, depth + 1e-3, r + c).union(Point(0.0, 0.0).buffer(r + c, quad_segs=16))
    blk = box(-r - base, -r - wall, depth, r + wall)
    ring = polygon_ring(blk.difference(slot))
    half_len = 0.015  # the blade's straight part beyond its rounded end [m]
    # the blade: a capsule along x (rounded end centres at the body origin -+ half_len); seated, its
    # near end's centre is the channel bottom's centre (the origin)
    x_end = half_len
    x0 = x_end + depth + 0.001
    design_scene(
        "paddleside2d",
        doc="Paddle side of a paddle holder: a U-channel exactly matching the blade's rounded 6 mm edge (no grip);\n"
            "optimized to grip the blade tightly with a removal force below the stand side's.",
        ring=ring, target=2000,  # thin bending walls: ~4 triangles across (500 gave a grip 3x too stiff)
        object_geoms=[dict(type="capsule", size=[r, half_len], quat=[0.7071067811865476, 0, 0.7071067811865476, 0])],
        keys=[([x0, 0, 0], [1, 0, 0, 0]), ([x_end, 0, 0], [1, 0, 0, 0])],
        fixed_center=[-r - base, 0, 0], fixed_half=[0.0006, r + wall + 0.001, 0.01],
        obj=dict(body="object", samples=400), sim=dict(steps=35),
        # firm grip (>= 5 N: friction holds the blade) that lets go with less than 10 N (the stand
        # side's removal force is ~30 N): the thesis' "removal force smaller than the stand side's"
        design=dict(grip="tight", grip_force=[5.0, float("inf")], removal_force=[0.0, 10.0], handles=4,
                    placement="spatial"))


def main() -> None:
    standside()
    paddleside()
    profile2d()
    knocker_design()
    alligator3d()
    alligator2d()
    doc = ("Building block (2D section, PLA): a socket that barely holds a 20 mm ball; its base (keep site)\n"
           "stays unchanged. Optimized to a {} grip; revolve the result into 3D with\n"
           "simfab couple optimize {} --revolve-axis x.")
    block2d("block2d_loose", doc.format("loose", "block2d_loose"), dict(grip="loose", handles=4))
    block2d("block2d_tight", doc.format("tight", "block2d_tight"),
            dict(grip="tight", grip_force=[3.0, 5.0], handles=4))
    block2d("block2d_tighter", doc.format("tighter (more grip, lower insertion and removal forces than the tight\n"
                                          "design)", "block2d_tighter"),
            # tighter: more grip than the tight design's 3-5 N with lower insertion and removal forces
            # than its (mesh-converged, seed 0) 4.5 N and 4.8 N
            dict(grip="tight", grip_force=[6.0, float("inf")], insertion_force=[0.0, 4.0],
                 removal_force=[0.0, 4.0], handles=4))


if __name__ == "__main__":
    main()
