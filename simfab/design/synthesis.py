"""2D -> 3D synthesis of an optimized section: extrusion (plane strain) or revolution.

- extrusion: the section's triangles are extruded by the scene's thickness along z
  (:func:`simfab.coupling.outputs.extruded_slab`);
- revolution: the section's outline is revolved a full turn about an axis in its plane, the
  line x = ``offset`` (axis "y") or y = ``offset`` (axis "x"). The section must lie on one side
  of the axis (a part that crosses it would overlap itself); the outline is revolved with
  ``sections`` segments per turn (trimesh ``creation.revolve``), giving a closed, watertight
  surface for a closed outline. A full turn suits parts that are round by nature (a ring);
- revolved base with replicated arms (:func:`revolve_arms`, the thesis' building blocks: "we
  synthesized the 3D versions by revolving the base and replicating the optimized arms"): the
  section is cut across the axis at ``cut`` (axial coordinate); the base side is revolved, and
  the arm side, split along the axis into its two halves (the arms of a symmetric socket), is
  extruded ``width`` out of the plane into slabs placed at ``arms`` angles around the axis,
  alternating the two halves (2 arms: the section's own arms, in its own plane). A full turn of
  a socket would be a closed cup whose rim cannot open; slabs flex like the section's arms. The
  pieces are united by manifold3d (exact, watertight). The part stays in the scene's frame (the
  axis where it was, out-of-plane = z), so the 2D scene's object and path apply to it as they are.
"""

from __future__ import annotations

import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import manifold3d as m3
import numpy as np
import tomli_w

from simfab.coupling.scene import stored_part_table
from simfab.errors import InputError
from simfab.fem.meshing import tetrahedralize
from simfab.io.atomic import atomic_paths


def boundary_loops(facets: np.ndarray) -> list[np.ndarray]:
    """Closed vertex loops (each (k,) vertex indices, in edge order) of 2D boundary edges (f, 2)
    oriented with the body on their left (outer loop counter-clockwise, holes clockwise)."""
    nxt = {int(a): int(b) for a, b in np.asarray(facets)}
    loops, seen = [], set()
    for start in nxt:
        if start in seen:
            continue
        loop, v = [], start
        while v not in seen:
            seen.add(v)
            loop.append(v)
            v = nxt[v]
        loops.append(np.array(loop))
    loops.sort(key=len, reverse=True)
    return loops


def revolve_outline(loop_xy: np.ndarray, *, axis: str = "y", offset: float = 0.0, sections: int = 96):
    """Watertight trimesh of a closed outline (k, 2) [m] revolved a full turn about the in-plane
    axis (see module docstring); the revolution axis becomes the 3D z axis."""
    import trimesh  # deferred: about a second of start-up, for the 3D outputs only

    P = np.asarray(loop_xy, float)
    if axis == "y":
        r, z = P[:, 0] - offset, P[:, 1]
    elif axis == "x":
        r, z = P[:, 1] - offset, P[:, 0]
    else:
        raise InputError(f"revolution axis must be 'x' or 'y', got {axis!r}", where="--revolve-axis")
    if np.all(r <= 0):
        r = -r
    if np.any(r < 0):
        raise InputError("the section crosses the revolution axis (it would overlap itself); move the axis "
                         "(--revolve-offset) to one side of the part", where="--revolve-offset")
    line = np.c_[r, z]
    area = 0.5 * np.sum(line[:, 0] * np.roll(line[:, 1], -1) - np.roll(line[:, 0], -1) * line[:, 1])
    if area < 0:  # trimesh expects the profile counter-clockwise in (r, z) for outward normals
        line = line[::-1]
    line = np.vstack([line, line[:1]])
    mesh = trimesh.creation.revolve(line, sections=int(sections))
    mesh.merge_vertices()
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def revolve_arms(loops, *, axis: str = "x", offset: float = 0.0, cut: float, base_side: int = -1, arms: int = 4,
                 width: float, sections: int = 96):
    """Watertight trimesh [m] of a 2D section (see the module docstring) with its base revolved
    and its arms replicated.

    loops : the section's boundary loops, each (k, 2) [m] (outer and holes, any orientation)
    axis, offset : the revolution axis, the line y = offset ("x") or x = offset ("y")
    cut : axial coordinate [m] (x for axis "x") between the base and the arms
    base_side : -1 if the base is at axial coordinates below ``cut``, +1 above
    arms : slabs around the axis (>= 2), at angles 2 pi i / arms; even i carry the section's half on
        the positive side of the axis (+y for axis "x"), odd i the other half (mirrored)
    width : out-of-plane width of each slab [m] (the 2D scene's thickness)

    The 3D part is in the section's frame: axis "x": points (a, offset + r cos t, r sin t) with a
    the axial and r the radial coordinate; the section's plane is z = 0.
    """
    import trimesh  # deferred: about a second of start-up, for the 3D outputs only

    if axis not in ("x", "y"):
        raise InputError(f"revolution axis must be 'x' or 'y', got {axis!r}", where="--revolve-axis")
    if int(arms) < 2:
        raise InputError(f"arms must be >= 2, got {arms}", where="--revolve-arms")
    if not width > 0:
        raise InputError(f"arm width must be > 0, got {width}", where="thickness")
    # (r, a) coordinates: r radial (signed: the two halves), a axial
    rings = []
    for L in loops:
        P = np.asarray(L, float)
        r, a = (P[:, 1] - offset, P[:, 0]) if axis == "x" else (P[:, 0] - offset, P[:, 1])
        rings.append(np.c_[r, a])
    sec = m3.CrossSection(rings, m3.FillRule.EvenOdd)
    lo, hi = np.min(np.vstack(rings), axis=0), np.max(np.vstack(rings), axis=0)
    big = 2.0 * float(np.max(np.abs(np.r_[lo, hi]))) + 1.0
    if not lo[1] < cut < hi[1]:
        raise InputError(f"the cut between base and arms ({cut:.4g} m) is not inside the section "
                         f"({lo[1]:.4g} .. {hi[1]:.4g} m along the axis)", where="keep")

    def box(r0, r1, a0, a1):
        return m3.CrossSection.square((r1 - r0, a1 - a0)).translate((r0, a0))

    a_base = (-big, cut) if base_side < 0 else (cut, big)
    eps = 1e-3 * (hi[1] - lo[1])  # arms reach into the base: one solid after the union
    a_arms = (cut - eps, big) if base_side < 0 else (-big, cut + eps)
    base = (sec ^ box(0.0, big, *a_base)).revolve(int(sections))  # about the section's a axis -> z
    halves = [sec ^ box(0.0, big, *a_arms), (sec ^ box(-big, 0.0, *a_arms)).mirror((1.0, 0.0))]
    parts = [base]
    for i in range(int(arms)):
        half = halves[i % 2]
        if half.is_empty():
            continue
        slab = half.extrude(width).translate((0.0, 0.0, -0.5 * width))  # (r, a, t)
        slab = slab.rotate((90.0, 0.0, 0.0))  # (r, a, t) -> (r, -t, a): a along z like the base
        parts.append(slab.rotate((0.0, 0.0, 360.0 * i / int(arms))))
    solid = m3.Manifold.batch_boolean(parts, m3.OpType.Add)
    mesh = solid.to_mesh()
    V = np.asarray(mesh.vert_properties, float)[:, :3]
    F = np.asarray(mesh.tri_verts, np.int64)
    # (X, Y, Z) = (r cos t, r sin t, a) -> the section's frame
    out = np.c_[V[:, 2], offset + V[:, 0], V[:, 1]] if axis == "x" else np.c_[offset + V[:, 0], V[:, 2], V[:, 1]]
    if axis == "y":  # (x, y, z) = (r cos, a, r sin) from (X, Z, Y): a reflection, flip the winding
        F = F[:, ::-1]
    tm = trimesh.Trimesh(out, F, process=True)
    if tm.volume < 0:
        tm.invert()
    return tm


def revolved_scene(X: np.ndarray, fem, *, kept: np.ndarray, object_start: np.ndarray, scene_xml, scene_toml,
                   out, stem: str, axis: str, offset: float, arms: int, target_tets: int = 1200) -> dict:
    """The optimized 2D section ``X`` (n, 2) [m] (mesh ``fem``) as a 3D scene: base revolved, arms
    replicated (:func:`revolve_arms`), meshed with quadratic tets, next to the 2D scene it came from.

    kept : vertices of the base (the keep sites: the region the optimizer left unchanged); the cut
        between base and arms is the base's face toward O (``object_start``, O's position at s = 0)
    scene_xml, scene_toml : the optimized 2D scene (its object, path, fixed region, material and
        simulation table carry over; the fixed box is widened out of the plane to hold the
        revolved base)
    target_tets : tetrahedra wanted (:func:`simfab.fem.meshing.tetrahedralize`: the thin arms take
        more), lifted to 10-node tets
        (``element_order = 2``: linear tets of this size would be tens of percent too stiff)

    Writes STEM_optimized_revolved.{stl (mm, for printing), xml, toml} and
    STEM_optimized_revolved_part.npz (the tet mesh, so re-simulating is reproducible); returns
    their paths {"stl", "scene_xml", "scene_toml", "mesh"} (all or nothing written).
    """
    kept = np.asarray(kept, dtype=np.int64)
    if kept.size == 0:
        raise InputError("replicating arms needs the base marked by a keep site ([design] keep)",
                         where="--revolve-arms")
    X = np.asarray(X, float)
    ax = 0 if axis == "x" else 1
    rad = 1 - ax
    a_kept = X[kept, ax]
    base_side = -1 if float(object_start[ax]) > float(a_kept.mean()) else 1
    cut = float(a_kept.max() if base_side < 0 else a_kept.min())
    loops = [X[lp] for lp in boundary_loops(fem.boundary_facets)]
    mesh = revolve_arms(loops, axis=axis, offset=offset, cut=cut, base_side=base_side, arms=arms,
                        width=float(fem.thickness))
    V, T = tetrahedralize(mesh.vertices, mesh.faces, target_tets=int(target_tets), coarsen=True)
    on_base = (X[:, ax] - cut) * base_side >= 0
    R = float(np.abs(X[on_base, rad] - offset).max())  # the revolved base's radius

    out = Path(out)
    name = f"{stem}_optimized_revolved"
    paths = {"stl": out / f"{name}.stl", "scene_xml": out / f"{name}.xml", "scene_toml": out / f"{name}.toml",
             "mesh": out / f"{name}_part.npz"}
    cfg = tomllib.loads(Path(scene_toml).read_text(encoding="utf-8"))
    cfg.pop("design", None)
    cfg["name"], cfg["dim"] = name, 3
    cfg["compliant"] = stored_part_table(paths["mesh"].name, paths["stl"].name, "mm", len(T))
    cfg["simulation"] = dict(cfg.get("simulation", {}), element_order=2)
    tree = ET.parse(scene_xml)
    root = tree.getroot()
    root.set("model", name)
    for m in root.iter("mesh"):
        if m.get("name") == "part":
            m.set("vertex", " ".join(f"{v:.9g}" for v in mesh.vertices.ravel()))
            m.set("face", " ".join(str(int(i)) for i in mesh.faces.ravel()))
    fixed_site = cfg.get("fixed", {}).get("site", "fixed")
    for s in root.iter("site"):
        if s.get("name") == fixed_site:  # out of the plane as far as the revolved base reaches
            size = [float(v) for v in s.get("size").split()]
            size += [size[-1]] * (3 - len(size))
            size[2] = max(size[2], 1.01 * R)
            s.set("size", " ".join(f"{v:.9g}" for v in size))
    mm = mesh.copy()
    mm.apply_scale(1e3)
    with atomic_paths(paths) as tmp:
        mm.export(str(tmp["stl"]), file_type="stl")
        with open(tmp["mesh"], "wb") as f:
            np.savez(f, points=V, elements=T)
        tmp["scene_toml"].write_text(f"# written by simfab couple optimize: {Path(scene_toml).name}'s section, base "
                                     f"revolved about {axis}, {arms} arms\n" + tomli_w.dumps(cfg), encoding="utf-8")
        tmp["scene_xml"].write_text(ET.tostring(root, encoding="unicode"), encoding="utf-8")
    return paths
