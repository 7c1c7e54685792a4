"""Skinning a skeleton into one printable solid with manifold3d.

Each segment becomes the convex hull of the spheres at its two nodes (radius r_i, r_j): a
truncated cone with spherical joints, so that branches meet smoothly at every node. The
hulls are unioned by manifold3d's batch boolean (exact, always manifold), then the
supported objects are subtracted so that the skin cannot penetrate them (a carved contact
face where it touches them). The result is checked after an STL write/read round trip
with merged vertices, the form a slicer sees.
"""

from __future__ import annotations

import dataclasses
import io

import numpy as np

from simfab.growth import tolerances as tol


@dataclasses.dataclass
class SkinReport:
    """Checks of a skin mesh (after an STL round trip unless stated).

    watertight, is_volume : trimesh checks. bodies : connected components. volume [m³].
    nodes_contained : skeleton nodes inside the skin (within CONTAIN_TOL r_min of it).
    overlap_volume : volume of skin ∩ objects [m³] (before the round trip).
    objects_subtracted / objects_not_manifold : object names carved out / skipped.
    """

    watertight: bool = False
    is_volume: bool = False
    bodies: int = 0
    volume: float = 0.0
    nodes_total: int = 0
    nodes_contained: int = 0
    overlap_volume: float = 0.0
    objects_subtracted: list = dataclasses.field(default_factory=list)
    objects_not_manifold: list = dataclasses.field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.watertight and self.is_volume and self.bodies == 1 and self.volume > 0 and \
            self.nodes_contained == self.nodes_total


def _m3():
    import manifold3d

    return manifold3d


def _unit_sphere(segments: int) -> np.ndarray:
    m3 = _m3()
    return np.asarray(m3.Manifold.sphere(1.0, int(segments)).to_mesh64().vert_properties)[:, :3]


def to_manifold(mesh):
    """``manifold3d.Manifold`` of a ``trimesh.Trimesh`` (vertices merged); None if not a valid manifold."""
    m3 = _m3()
    m = mesh.copy()
    m.merge_vertices()
    try:
        man = m3.Manifold(m3.Mesh64(vert_properties=np.ascontiguousarray(m.vertices, np.float64),
                                    tri_verts=np.ascontiguousarray(m.faces, np.uint64)))
    except Exception:  # manifold3d rejects malformed input with various exception types
        return None
    if man.status() != m3.Error.NoError or man.is_empty():
        return None
    return man


def to_trimesh(man):
    """``trimesh.Trimesh`` of a Manifold (float64 vertices)."""
    import trimesh

    mesh = man.to_mesh64()
    return trimesh.Trimesh(np.asarray(mesh.vert_properties)[:, :3].astype(np.float64),
                           np.asarray(mesh.tri_verts, np.int64), process=False)


def skin_solid(nodes: np.ndarray, parent: np.ndarray, radius: np.ndarray, *, segments: int = 16):
    """Union of sphere-pair hulls along every segment (isolated nodes become spheres): a Manifold."""
    m3 = _m3()
    S = _unit_sphere(segments)
    parts = []
    for c in range(len(nodes)):
        p = parent[c]
        if p >= 0:
            pts = np.concatenate([nodes[p] + radius[p] * S, nodes[c] + radius[c] * S])
            parts.append(m3.Manifold.hull_points(pts))
    has_edge = np.zeros(len(nodes), bool)
    has_edge[parent[parent >= 0]] = True
    has_edge[parent >= 0] = True
    for i in np.nonzero(~has_edge)[0]:
        parts.append(m3.Manifold.hull_points(nodes[i] + radius[i] * S))
    return m3.Manifold.batch_boolean(parts, m3.OpType.Add)


def carve(solid, objects: dict, report: SkinReport):
    """Subtract every object that is a valid manifold from ``solid``; record which ones."""
    m3 = _m3()
    cutters = []
    for name, mesh in objects.items():
        man = to_manifold(mesh)
        if man is None:
            report.objects_not_manifold.append(name)
        else:
            cutters.append(man)
            report.objects_subtracted.append(name)
    if not cutters:
        return solid
    return m3.Manifold.batch_boolean([solid] + cutters, m3.OpType.Subtract)


def overlap_volume(solid, objects: dict) -> float:
    """Volume [m³] of ``solid`` ∩ (objects that are valid manifolds)."""
    m3 = _m3()
    vol = 0.0
    for mesh in objects.values():
        man = to_manifold(mesh)
        if man is not None:
            vol += float(m3.Manifold.batch_boolean([solid, man], m3.OpType.Intersect).volume())
    return vol


def stl_round_trip(mesh):
    """Write ``mesh`` as binary STL and read it back with vertices merged (what a slicer sees)."""
    import trimesh

    buf = io.BytesIO(mesh.export(file_type="stl"))
    return trimesh.load(buf, file_type="stl", process=True)


def check_skin(mesh, nodes: np.ndarray, r_min: float, report: SkinReport | None = None) -> SkinReport:
    """Fill a :class:`SkinReport` for ``mesh`` (trimesh) and the skeleton ``nodes`` (n, 3)."""
    rep = report or SkinReport()
    rt = stl_round_trip(mesh)
    rep.watertight = bool(rt.is_watertight)
    rep.is_volume = bool(rt.is_volume)
    rep.bodies = len(rt.split(only_watertight=False)) if len(rt.faces) else 0
    rep.volume = float(rt.volume) if rep.watertight else 0.0
    x = np.asarray(nodes, np.float64).reshape(-1, 3)
    rep.nodes_total = len(x)
    if len(rt.faces) and len(x):
        inside = rt.contains(x)
        out = np.nonzero(~inside)[0]
        if out.size:
            _, d, _ = rt.nearest.on_surface(x[out])
            inside[out[d <= tol.CONTAIN_TOL * r_min]] = True
        rep.nodes_contained = int(inside.sum())
    return rep


def skin(nodes, parent, radius, objects: dict | None = None, *, segments: int = 16, subtract: bool = True):
    """Skin a skeleton: returns (``trimesh.Trimesh``, :class:`SkinReport`).

    nodes (n, 3) [m], parent (n,), radius (n,) [m]; ``objects`` name -> trimesh are carved
    out when ``subtract`` (objects that are not valid manifolds are listed in the report).
    """
    rep = SkinReport()
    nodes = np.asarray(nodes, np.float64)
    radius = np.asarray(radius, np.float64)
    solid = skin_solid(nodes, np.asarray(parent, np.int64), radius, segments=segments)
    if objects and subtract:
        solid = carve(solid, objects, rep)
    if objects:
        rep.overlap_volume = overlap_volume(solid, objects)
    mesh = to_trimesh(solid)
    check_skin(mesh, nodes, float(radius.min()) if len(radius) else 0.0, rep)
    return mesh, rep
