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

import simfab.growth.tolerances as tol
from simfab.growth.skeleton import chains, subset


@dataclasses.dataclass
class SkinReport:
    """Checks of a skin mesh (after an STL round trip unless stated).

    watertight, is_volume : trimesh checks. bodies : connected components. volume [m³].
    nodes_contained : skeleton nodes inside the skin or on its boundary (a ball of radius
        CONTAIN_TOL r_min around the node overlaps the skin by TOUCH_FRACTION of its volume).
    overlap_volume : volume of skin ∩ objects [m³] (before the round trip).
    penetration : largest depth [m] of a skin vertex inside an object that was not carved
        (carved objects are exact: their overlap is ``overlap_volume``).
    objects_subtracted / objects_not_manifold : object names carved out / skipped.
    attempts : skins built until one passed the round trip (see :func:`skin_skeleton`).
    """

    watertight: bool = False
    is_volume: bool = False
    bodies: int = 0
    volume: float = 0.0
    nodes_total: int = 0
    nodes_contained: int = 0
    overlap_volume: float = 0.0
    penetration: float = 0.0
    objects_subtracted: list = dataclasses.field(default_factory=list)
    objects_not_manifold: list = dataclasses.field(default_factory=list)
    attempts: int = 1

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


def skin_solid(nodes: np.ndarray, parent: np.ndarray, radius: np.ndarray, *, segments: int = 12, rotation=None):
    """Union of sphere-pair hulls along every segment (isolated nodes become spheres): a Manifold.

    ``rotation`` (3, 3) turns the sphere tessellation (used to retry a skin whose STL
    round trip failed, see :func:`skin_skeleton`).
    """
    m3 = _m3()
    S = _unit_sphere(segments)
    if rotation is not None:
        S = S @ np.asarray(rotation).T
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


def simplify_chains(nodes: np.ndarray, parent: np.ndarray, radius: np.ndarray, keep: np.ndarray,
                    tolerance: float = 0.25) -> np.ndarray:
    """(n,) bool: nodes to keep for skinning. Along each chain (between the ``keep`` nodes,
    branch points and leaves) interior nodes are dropped by Douglas–Peucker while the
    dropped nodes stay within ``tolerance`` × (smallest radius on the chain) of the chord
    (so they stay well inside the skin). Heavily overlapping hulls of short segments make
    the union slow and produce slivers; this removes them without changing the shape."""
    out = np.ones(len(nodes), bool)
    for c in chains(parent, keep):
        if len(c) < 3:
            continue
        eps = tolerance * float(radius[c].min())
        sel = np.zeros(len(c), bool)
        sel[[0, -1]] = True
        stack = [(0, len(c) - 1)]
        while stack:
            i, j = stack.pop()
            if j - i < 2:
                continue
            a, b = nodes[c[i]], nodes[c[j]]
            P = nodes[c[i + 1:j]]
            ab = b - a
            t = np.clip((P - a) @ ab / max(float(ab @ ab), 1e-300), 0.0, 1.0)
            d = np.linalg.norm(a + t[:, None] * ab - P, axis=1)
            k = int(np.argmax(d))
            if d[k] > eps:
                sel[i + 1 + k] = True
                stack += [(i, i + 1 + k), (i + 1 + k, j)]
        out[c[~sel]] = False
    return out


def object_manifolds(objects: dict, report: SkinReport) -> list:
    """Manifolds of the objects that are valid closed meshes; the others are listed in the report."""
    out = []
    for name, mesh in objects.items():
        man = to_manifold(mesh)
        if man is None:
            report.objects_not_manifold.append(name)
        else:
            out.append(man)
            report.objects_subtracted.append(name)
    return out


def carve(solid, cutters: list):
    """``solid`` minus every cutter Manifold."""
    m3 = _m3()
    if not cutters:
        return solid
    return m3.Manifold.batch_boolean([solid] + list(cutters), m3.OpType.Subtract)


def overlap_volume(solid, cutters: list) -> float:
    """Volume [m³] of ``solid`` ∩ cutters."""
    m3 = _m3()
    return float(sum(m3.Manifold.batch_boolean([solid, c], m3.OpType.Intersect).volume() for c in cutters))


def penetration_depth(mesh, objects: dict) -> float:
    """Largest distance [m] from a skin vertex inside a (watertight) object to that object's surface."""
    depth = 0.0
    V = np.asarray(mesh.vertices)
    for obj in objects.values():
        if not obj.is_watertight or len(V) == 0:
            continue
        lo, hi = obj.bounds
        cand = np.nonzero(np.all((V > lo) & (V < hi), axis=1))[0]
        if cand.size == 0:
            continue
        inside = cand[obj.contains(V[cand])]
        if inside.size:
            _, d, _ = obj.nearest.on_surface(V[inside])
            depth = max(depth, float(d.max()))
    return depth


def clean_for_stl(mesh):
    """The mesh as an STL reader sees it: float32 vertices merged (trimesh's merge precision),
    then the faces that collapsed (repeated vertex) or doubled up (the same triangle twice,
    a zero-volume fin) removed. Edges shorter than the STL precision otherwise break
    watertightness after a write/read round trip."""
    import trimesh

    rt = stl_round_trip(mesh)
    F = np.asarray(rt.faces)
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    _, inv, cnt = np.unique(np.sort(F, axis=1), axis=0, return_inverse=True, return_counts=True)
    F = F[cnt[inv.reshape(-1)] == 1]
    F = split_degenerate(np.asarray(rt.vertices), collapse_short_edges(np.asarray(rt.vertices), F))
    out = trimesh.Trimesh(np.asarray(rt.vertices), F, process=False)
    out.remove_unreferenced_vertices()
    return out


#: A face is degenerate when its area is below this times the squared largest extent (the
#: criterion of :func:`simfab.io.mesh.inspect_mesh`).
DEGENERATE_AREA_REL = 1e-12


def collapse_short_edges(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Collapse edges shorter than the length of a degenerate face's edge (a triangle with all
    edges below sqrt(2 DEGENERATE_AREA_REL) x extent has no area to speak of): their endpoints
    are merged (union-find), faces that lose a vertex and the fins left behind (the same
    triangle twice) are removed. Returns the new faces; vertices are not moved."""
    F = np.asarray(F, np.int64)
    if not len(F):
        return F
    eps = np.sqrt(2.0 * DEGENERATE_AREA_REL) * float(np.max(np.ptp(V, axis=0)))
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    short = E[np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1) < eps]
    if not len(short):
        return F
    root = np.arange(len(V))

    def find(x):
        while root[x] != x:
            root[x] = root[root[x]]
            x = root[x]
        return x

    for a, b in short:
        ra, rb = find(int(a)), find(int(b))
        if ra != rb:
            root[max(ra, rb)] = min(ra, rb)
    rep = np.array([find(i) for i in range(len(V))])
    F = rep[F]
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    _, inv, cnt = np.unique(np.sort(F, axis=1), axis=0, return_inverse=True, return_counts=True)
    return F[cnt[inv.reshape(-1)] == 1]


def split_degenerate(V: np.ndarray, F: np.ndarray, *, passes: int = 10) -> np.ndarray:
    """Remove zero-area (collinear) triangles without opening the surface.

    A degenerate triangle (a, c, b) whose middle vertex b lies on its longest edge a-c is
    dropped, and the neighbour (c, a, d) across that edge is split at b into (c, b, d) and
    (b, a, d): every edge keeps exactly one twin, so a watertight mesh stays watertight and
    the surface is unchanged. Repeated until no degenerate face is left (or ``passes``).
    Returns the new faces (k, 3).
    """
    F = np.asarray(F, np.int64)
    if not len(F):
        return F
    scale = float(np.max(np.ptp(V, axis=0)))
    for _ in range(passes):
        tri = V[F]
        area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        bad = np.nonzero(area <= DEGENERATE_AREA_REL * scale * scale)[0]
        if not bad.size:
            break
        edge_face = {(int(f[k]), int(f[(k + 1) % 3])): i for i, f in enumerate(F) for k in range(3)}
        drop, new = set(), []
        for i in bad:
            if i in drop:
                continue
            f = [int(x) for x in F[i]]
            lengths = [np.linalg.norm(V[f[(k + 1) % 3]] - V[f[k]]) for k in range(3)]
            k = int(np.argmax(lengths))
            a, c, b = f[k], f[(k + 1) % 3], f[(k + 2) % 3]
            j = edge_face.get((c, a))
            if j is None or j in drop or j == i:
                continue
            d = [int(x) for x in F[j] if x not in (a, c)]
            if len(d) != 1 or d[0] == b:
                continue
            drop.update((i, j))
            new += [(c, b, d[0]), (b, a, d[0])]
        if not new:
            break
        keep = np.ones(len(F), bool)
        keep[list(drop)] = False
        F = np.vstack([F[keep], np.asarray(new, np.int64)])
    return F


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
            inside[out] = _touches(rt, x[out], tol.CONTAIN_TOL * r_min)
        rep.nodes_contained = int(inside.sum())
    return rep


def _touches(mesh, x: np.ndarray, radius: float) -> np.ndarray:
    """(k,) bool: a ball of ``radius`` around each point overlaps the solid by at least
    ``TOUCH_FRACTION`` of its volume (points on the boundary, e.g. on a carved contact face,
    overlap by one half). Exact booleans: ray-based point tests are unreliable exactly on
    the surface."""
    m3 = _m3()
    solid = to_manifold(mesh)
    if solid is None or not radius > 0:
        return np.zeros(len(x), bool)
    ball = m3.Manifold.sphere(radius, 8)
    full = ball.volume()
    out = np.zeros(len(x), bool)
    for i, p in enumerate(x):
        b = ball.translate(tuple(float(c) for c in p))
        out[i] = m3.Manifold.batch_boolean([solid, b], m3.OpType.Intersect).volume() >= tol.TOUCH_FRACTION * full
    return out


def skin_skeleton(nodes, parent, radius, objects: dict | None = None, *, segments: int = 12, subtract: bool = True,
         attempts: int = 3, simplify: float | None = 0.25, fixed=None):
    """Skin a skeleton: returns (``trimesh.Trimesh``, :class:`SkinReport`).

    nodes (n, 3) [m], parent (n,), radius (n,) [m]; ``objects`` name -> trimesh are carved
    out when ``subtract`` (objects that are not valid manifolds are listed in the report).
    Chains are simplified first (:func:`simplify_chains` with tolerance ``simplify``, None
    to skip; ``fixed`` (n,) bool marks nodes that must stay, default the roots). The mesh is
    cleaned for STL (:func:`clean_for_stl`); if it still fails the round-trip checks, the
    skin is rebuilt with a turned sphere tessellation (up to ``attempts`` times). The
    containment check always uses every input node.
    """
    nodes = np.asarray(nodes, np.float64)
    radius = np.asarray(radius, np.float64)
    parent = np.asarray(parent, np.int64)
    r_min = float(radius.min()) if len(radius) else 0.0
    rng = np.random.default_rng(0)
    sn, sp, sr = nodes, parent, radius
    if simplify is not None and simplify > 0 and len(nodes) > 2:
        kept = simplify_chains(nodes, parent, radius, fixed if fixed is not None else parent < 0, simplify)
        idx, sp = _collapse(parent, kept)
        sn, sr = nodes[idx], radius[idx]
    # the objects' manifolds do not depend on the attempt: build them once
    found = SkinReport()
    cutters = object_manifolds(objects, found) if objects else []
    carved = found.objects_subtracted if subtract else []
    # carved objects cannot be penetrated (exact booleans; rep.overlap_volume checks it):
    # measure the depth only for objects left whole
    whole = {k: v for k, v in (objects or {}).items() if k not in carved}
    for attempt in range(max(1, attempts)):
        rep = SkinReport(objects_subtracted=list(carved), objects_not_manifold=list(found.objects_not_manifold))
        rotation = None if attempt == 0 else _random_rotation(rng)
        solid = skin_solid(sn, sp, sr, segments=segments, rotation=rotation)
        if subtract:
            solid = carve(solid, cutters)
        rep.overlap_volume = overlap_volume(solid, cutters)
        mesh = clean_for_stl(to_trimesh(solid))
        check_skin(mesh, nodes, r_min, rep)
        rep.penetration = penetration_depth(mesh, whole)
        rep.attempts = attempt + 1
        if rep.watertight and rep.is_volume:
            break
    return mesh, rep


def _random_rotation(rng) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def _collapse(parent: np.ndarray, kept: np.ndarray):
    """Re-index a forest to the kept nodes, joining each kept node to its nearest kept ancestor."""
    anc = parent.copy()
    # nodes come after their parents: resolve dropped parents in index order
    for i in range(len(parent)):
        a = anc[i]
        if a >= 0 and not kept[a]:
            anc[i] = anc[a]
    return subset(anc, kept)
