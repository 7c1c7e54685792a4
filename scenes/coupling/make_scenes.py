#!/usr/bin/env python
"""Regenerate the bundled coupling scenes (MJCF + companion TOML) in this folder.

``python scenes/coupling/make_scenes.py [--remesh]`` rewrites every ``NAME.xml``/``NAME.toml`` pair
from the parameters below; 3D parts are tetrahedralized into ``NAME_part.npz`` only when that file
is missing or ``--remesh`` is given (fTetWild is not bit-reproducible). Lengths in metres. Each scene:

- MJCF: O as the mocap body ``object`` (its geoms, body frame), keyframes of O's path, the fixed
  region as the box site ``fixed`` and A's rest shape (body ``part``, display only);
- TOML: how A is generated (``simfab.coupling.geometry``), meshing target, material, O's
  sampling and the simulation options (see ``simfab.coupling.scene``).

Scenes
- cclamp2d      2D C-clamp snapped onto a cylinder, inner radius < R: tight grip (~4,800 tri, 35 steps)
- clip2d_loose  same clamp with inner radius > R: holds it loosely (zero steady-state energy)
- clip2d_eject  an arc that does not wrap past the cylinder's equator: pushes it out (no dip)
- clip3d        the C-clamp extruded to a 3D clip on a cylinder (4,692 10-node tets: 782 triangles in 2 layers, 35 steps)
- claw3d        four-finger claw (two crossed clamps) on a sphere (5,130 10-node tets, the ball an
                exact sphere, 25 steps)
- knocker3d     door-knocker ring: pushed horizontally into a clip, then rotated 90 degrees about
                its bar (rotating path, 8,181 10-node tets in 3 layers, 80 steps; the ring an exact torus)
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))

from simfab.io.mjcf import TORUS_PLUGIN  # noqa: E402

R_CYL = 0.010  # cylinder / sphere radius [m]

CLAMP_TIGHT = dict(inner_radius=0.0095, width=0.0025, opening_deg=60.0, base_depth=0.004, base_height=0.020)
CLAMP_LOOSE = dict(CLAMP_TIGHT, inner_radius=0.0106)
CLAMP_EJECT = dict(CLAMP_TIGHT, opening_deg=100.0)
#: Seated position of O's centre for the tight clamps: the cylinder/sphere just touches the back
#: of the clamp (R - inner radius) while the arm tips still squeeze it.
X_SEATED = R_CYL - CLAMP_TIGHT["inner_radius"] + 0.0002


def x_start(clamp: dict, margin: float = 0.001, radius: float = R_CYL) -> float:
    """O's start: ``margin`` before a circle of ``radius`` first touches the clamp's inner tip corners."""
    a = math.radians(clamp["opening_deg"])
    tx, ty = clamp["inner_radius"] * math.cos(a), clamp["inner_radius"] * math.sin(a)
    return tx + math.sqrt(max(radius**2 - ty**2, 0.0)) + margin
KNOCK_R, KNOCK_r = 0.020, 0.003  # ring major / tube radius [m]
#: The knocker ring: an exact torus (MuJoCo's SDF torus plugin; MJCF has no torus geom) with its axis
#: along y and its bar (nearest tube section) through the body origin. As a 96 x 24 facet mesh its
#: sampled contact field did not converge (the facets sit up to 26 um inside the tube).
KNOCK_SDF = ("ring", TORUS_PLUGIN, dict(radius1=KNOCK_R, radius2=KNOCK_r))
KNOCK_GEOM = dict(sdf="ring", pos=[KNOCK_R, 0, 0], quat=[math.sqrt(0.5), math.sqrt(0.5), 0, 0])
#: The knocker's clip holds the ring's bar loosely (0.3 mm clearance) behind a mouth narrower than the
#: bar (snap on insertion); the bar's curvature (offset y^2 / 2R = 0.225 mm at the clip's ends) still
#: clears the clip while the ring rotates: a loose coupling on a rotating path.
CLAMP_KNOCK = dict(inner_radius=0.0033, width=0.0015, opening_deg=60.0, base_depth=0.002, base_height=0.009)


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, float):
        return repr(v)
    return str(v)


def write_toml(path: Path, header: str, top: dict, tables: dict) -> None:
    lines = [f"# {line}" if line else "#" for line in header.strip().splitlines()]
    lines.append("")
    for k, v in top.items():
        lines.append(f"{k} = {_toml_value(v)}")
    for name, tab in tables.items():
        lines.append("")
        lines.append(f"[{name}]")
        for k, v in tab.items():
            lines.append(f"{k} = {_toml_value(v)}")
    from simfab.io.atomic import write_text

    write_text(path, "\n".join(lines) + "\n")


def quat_z(a: float):
    return [math.cos(a / 2), 0.0, 0.0, math.sin(a / 2)]


def tet_mesh(name: str, surface, target: int, tol: float = 0.1, coarsen: bool = False, tries: int = 4):
    """Tetrahedralize ``surface`` to about ``target`` tets (fTetWild, target rescaled up to ``tries``
    times, the count closest to the target kept) and store it as NAME_part.npz; returns the file name."""
    from simfab.fem.meshing import tetrahedralize

    fname = f"{name}_part.npz"
    if (HERE / fname).exists() and "--remesh" not in sys.argv:
        return fname  # fTetWild is not reproducible: keep the stored mesh unless asked to remesh
    t = target
    best = None
    for _ in range(tries):
        V, T = tetrahedralize(np.asarray(surface.vertices), np.asarray(surface.faces), target_tets=t, coarsen=coarsen)
        if best is None or abs(len(T) - target) < abs(len(best[1]) - target):
            best = (V, T)
        if abs(len(T) - target) <= tol * target:
            break
        t = max(8, int(round(t * target / len(T))))
    from simfab.io.atomic import atomic_path

    with atomic_path(HERE / fname) as tmp, open(tmp, "wb") as fh:  # a file object: savez adds no suffix
        np.savez_compressed(fh, points=best[0], elements=best[1].astype(np.int32))
    print(f"{name}: {len(best[1])} tets (target {target})")
    return fname


def scene(name: str, *, doc: str, dim: int, comp: dict, part_mesh, object_geoms, keys, fixed_center, fixed_half,
          obj: dict, sim: dict, material: str = "PLA", extra_assets=(), sdf_assets=(), mesh_options=None,
          keep_sites=(), design: dict | None = None):
    """Write NAME.xml + NAME.toml (and NAME_part.npz in 3D). sdf_assets: (name, plugin, config) SDF
    plugin instances for object geoms ``dict(sdf=name, ...)``; keep_sites: (name, centre, half
    extents) box sites of regions a design keeps unchanged; design: the TOML's [design] table."""
    from simfab.io.mjcf import MJCFBuilder

    if dim == 3 and "layers" not in comp:  # extrusions in layers are meshed reproducibly on load
        comp = dict(comp, mesh_file=tet_mesh(name, part_mesh, comp["target_elements"], **(mesh_options or {})))

    b = MJCFBuilder(name)
    for aname, V, F in extra_assets:
        b.mesh_asset(aname, V, F)
    for aname, plugin, config in sdf_assets:
        b.sdf_asset(aname, plugin, **config)
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
    write_toml(HERE / f"{name}.toml", doc, {"name": name, "dim": dim},
               {"material": {"name": material}, "compliant": comp, "object": obj, "fixed": {"site": "fixed"},
                "simulation": sim, **({"design": design} if design else {})})


def main() -> None:
    from simfab.coupling import geometry as G

    t2d = 0.005  # plane-strain thickness of the 2D parts [m]

    def clamp2d(name, clamp, doc, x_end, design=None):
        clamp = dict(clamp, segments=48)  # arc resolution compatible with ~450 triangles
        outline = G.c_clamp_outline(**clamp)
        ro = clamp["inner_radius"] + clamp["width"]
        xb = -ro - clamp["base_depth"]
        x0 = x_start(clamp)
        scene(name, doc=doc, dim=2,
              comp=dict(generator="c_clamp", target_elements=4800, thickness=t2d, **clamp),
              part_mesh=G.extrude(outline, t2d),
              object_geoms=[dict(type="cylinder", size=[R_CYL, 0.01])],
              keys=[([x0, 0, 0], [1, 0, 0, 0]), ([x_end, 0, 0], [1, 0, 0, 0])],
              fixed_center=[xb, 0, 0], fixed_half=[0.0006, 0.5 * clamp["base_height"] + 0.001, 0.01],
              obj=dict(body="object", samples=50), sim=dict(steps=35), design=design)

    clamp2d("cclamp2d", CLAMP_TIGHT, "2D C-clamp (plane strain, PLA) pushed onto a 20 mm cylinder: tight grip.",
            X_SEATED,  # simfab couple optimize cclamp2d: keep the tight grip, stay below PLA's yield stress
            design=dict(grip="tight", insertion_force=[0.0, 20.0], handles=5, iterations=300))
    clamp2d("clip2d_loose", CLAMP_LOOSE, "2D clip whose inner radius exceeds the cylinder's: loose coupling.", 0.0)
    clamp2d("clip2d_eject", CLAMP_EJECT, "2D arc that does not wrap past the cylinder's equator: ejects it.", 0.0)

    # 3D clip on a cylinder (extruded C-clamp)
    h3 = 0.008
    ro = CLAMP_TIGHT["inner_radius"] + CLAMP_TIGHT["width"]
    xb = -ro - CLAMP_TIGHT["base_depth"]
    x0 = x_start(CLAMP_TIGHT)
    scene("clip3d", doc="3D clip (extruded C-clamp, PLA) snapped onto a cylinder along -x.\n"
          "Quadratic (10-node) tets on a 782-triangle section in 2 layers (4,692 tets): within 0.6% of the\n"
          "same part refined to 4 layers and 1,000-1,800 triangles, where linear tets at 28,800 were 11%\n"
          "too stiff (see README.md, \"Mesh resolution\").", dim=3,
          # P2 on the section its outline allows (782 triangles) in 2 layers: within 1% of the
          # mesh-converged figures (F_grip 2%); linear tets needed 28,800 for 11%
          comp=dict(generator="extruded_clamp", target_elements=2700, layers=2, height=h3, **CLAMP_TIGHT),
          part_mesh=G.extruded_clamp(height=h3, **CLAMP_TIGHT),
          object_geoms=[dict(type="cylinder", size=[R_CYL, 0.008])],
          keys=[([x0, 0, 0], [1, 0, 0, 0]), ([X_SEATED, 0, 0], [1, 0, 0, 0])],
          fixed_center=[xb, 0, 0], fixed_half=[0.0006, 0.011, 0.01],
          # held along x only (the original's support): the clip's free slide along the
          # frictionless cylinder's axis z is pinned by the solver (simfab.coupling.rigid)
          obj=dict(body="object", samples=1154), sim=dict(steps=35, element_order=2))

    # larger 3D model: four-finger claw on a sphere
    hc = 0.006
    claw = G.cross_claw(height=hc, **CLAMP_TIGHT)
    # the ball is an exact sphere: as an icosphere mesh sampled at 10,000 points its IMLS field
    # took 2x the Newton iterations (237 against 117 at P2) and put F_in 2.7% high
    scene("claw3d", doc="Four-finger claw (two crossed clamps, PLA) latching onto a sphere (exact).\n"
          "Quadratic (10-node) tets on a stored fTetWild mesh of 5,130 tets: within 1.5% of P2 on 12,390\n"
          "tets, where linear tets on those 12,390 were 40-44% too stiff (see README.md, \"Mesh resolution\").", dim=3,
          comp=dict(generator="cross_claw", target_elements=5150, height=hc, **CLAMP_TIGHT),
          part_mesh=claw, object_geoms=[dict(type="sphere", size=[R_CYL])],
          keys=[([x0, 0, 0], [1, 0, 0, 0]), ([X_SEATED, 0, 0], [1, 0, 0, 0])],
          fixed_center=[xb, 0, 0], fixed_half=[0.0006, 0.011, 0.011],
          # held along x only: the claw's free turn on the frictionless sphere about the
          # insertion axis is pinned by the solver (simfab.coupling.rigid)
          obj=dict(body="object"), sim=dict(steps=25, element_order=2),
          mesh_options=dict(tol=0.05, tries=6))

    # door knocker: ring bar along z pushed into a clip along -x, then rotated 90 deg about z
    hk = 0.006
    rok = CLAMP_KNOCK["inner_radius"] + CLAMP_KNOCK["width"]
    xk = x_start(CLAMP_KNOCK, margin=0.0005, radius=KNOCK_r)
    xs = max(KNOCK_r - CLAMP_KNOCK["inner_radius"], 0.0) + 0.0001  # seated: the bar clears the back of the clip
    # 3 layers of the extruded section (8,181 10-node tets, meshed on load): within 1.4% of 8 layers
    # where the stored 4,880-tet fTetWild mesh it ran before (knocker3d_part.npz, still the fixed
    # real-geometry mesh of tools/bench.py p2 and linear_solvers) was up to 4.1% off
    scene("knocker3d", doc="Door-knocker ring (an exact torus): inserted horizontally into a clip, then rotated about its\n"
          "bar. Quadratic (10-node) tets on the clip's section extruded in 3 layers: linear tets were 57-74%\n"
          "too stiff (see README.md, \"Mesh resolution\").", dim=3,
          comp=dict(generator="extruded_clamp", target_elements=6885, layers=3, height=hk, **CLAMP_KNOCK),
          part_mesh=G.extruded_clamp(height=hk, **CLAMP_KNOCK), sdf_assets=[KNOCK_SDF], object_geoms=[KNOCK_GEOM],
          keys=[([xk, 0, 0], [1, 0, 0, 0]), ([xs, 0, 0], [1, 0, 0, 0]), ([xs, 0, 0], quat_z(-np.pi / 2))],
          fixed_center=[-rok - CLAMP_KNOCK["base_depth"], 0, 0], fixed_half=[0.0004, 0.005, 0.005],
          obj=dict(body="object", rot_length_scale=0.005),
          sim=dict(steps=80, element_order=2, fix_all_axes=True), mesh_options=dict(coarsen=True, tol=0.05, tries=8))


if __name__ == "__main__":
    main()
