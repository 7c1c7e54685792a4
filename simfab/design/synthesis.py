"""2D -> 3D synthesis of an optimized section: extrusion (plane strain) or revolution.

- extrusion: the section's triangles are extruded by the scene's thickness along z
  (:func:`simfab.coupling.outputs.extrude_triangles`);
- revolution: the section's outline is revolved a full turn about an axis in its plane, the
  line x = ``offset`` (axis "y") or y = ``offset`` (axis "x"). The section must lie on one side
  of the axis (a part that crosses it would overlap itself); the outline is revolved with
  ``sections`` segments per turn (trimesh ``creation.revolve``), giving a closed, watertight
  surface for a closed outline.
"""

from __future__ import annotations

import numpy as np

from simfab.errors import InputError


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
    import trimesh

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
