"""Quad meshes of a flat domain: the layouts the deployment pattern is built on.

The flat domain is a flattened target's outline (a shapely Polygon, metres); each layout returns
(P (n,2) [m], quads (q,4) CCW) for :func:`simfab.deploy.pattern.layout`, which builds the beams,
inserts and springs on it. :func:`quad_meshes` picks by the ``[pattern] layout`` key:

- ``"grid"`` (:func:`clipped_grid`): the square grid of spacing h through the origin, nodes
  outside the outline projected onto it; cells with an edge < h/4 or not convex dropped;
- ``"conforming"`` (:func:`conforming_quads`): a grid core with one pillow layer of quads on the
  outline (as in hexahedral meshing), the outline vertices placed to balance each chord's segment;
- ``"mesh"`` (:func:`mesh_quads`): an unstructured quad mesh that follows any outline (the notches
  of a cut flattening): Triangle's quality triangulation paired into quads by a maximum-weight
  matching, then smoothed; a few meshings are tried (:data:`MESH_RECIPES`).

Each keeps the largest edge-connected set of quads (:func:`largest_component`). The method notes
(pillow layer, area balance, matching weights): docs/methods.md, "simfab.deploy.quadmesh".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import shapely
from scipy.sparse.csgraph import connected_components

from simfab.errors import InputError

#: the ``[pattern] layout`` values
LAYOUTS = ("conforming", "grid", "mesh")


def quad_meshes(poly, uv: np.ndarray, h: float, *, layout: str = "grid",
                core: str = "smoothed") -> list[tuple[np.ndarray, np.ndarray]]:
    """The candidate quad meshes of a layout of the flat domain (one, or one per meshing that succeeds).

    Args:
        poly: the flat domain (a shapely Polygon) [m].
        uv: (n,2) [m] the flattening's vertices (the grid's extent).
        h: the spacing [m].
        layout: "grid", "conforming" or "mesh" (:data:`LAYOUTS`).
        core: the conforming layout's core, "smoothed" (:data:`SMOOTHING_ITERATIONS` sweeps) or "regular".

    Returns:
        [(P (n,2) [m], quads (q,4) CCW), ...]; InputError naming ``pattern.spacing`` when none fits.
    """
    if layout == "grid":
        return [clipped_grid(poly, uv, h)]
    if layout == "mesh":
        meshes = [m for m in (mesh_quads(poly, h, r) for r in MESH_RECIPES) if m is not None]
        if not meshes:
            raise InputError(f"no quad mesh fits the flat domain at spacing {h} m (make pattern.spacing smaller)",
                             where="pattern.spacing")
        return meshes
    return [conforming_quads(poly, h, uv, sweeps=SMOOTHING_ITERATIONS if core == "smoothed" else 0)]


def _good_quad(Q: np.ndarray, h: float) -> bool:
    d = np.roll(Q, -1, axis=0) - Q
    if np.min(np.linalg.norm(d, axis=1)) < 0.25 * h:
        return False
    cross = d[:, 0] * np.roll(d, -1, axis=0)[:, 1] - d[:, 1] * np.roll(d, -1, axis=0)[:, 0]
    area = 0.5 * np.sum(Q[:, 0] * np.roll(Q[:, 1], -1) - np.roll(Q[:, 0], -1) * Q[:, 1])
    return bool(np.all(cross > -1e-12 * h * h) and area > 0.2 * h * h)


def largest_component(quads: np.ndarray) -> np.ndarray:
    """The largest edge-connected set of quads.

    Args:
        quads: (q,4) vertex ids.

    Returns:
        (q',4) the quads of the largest component.
    """
    e = np.sort(np.concatenate([quads[:, [k, (k + 1) % 4]] for k in range(4)]), axis=1)
    q = np.tile(np.arange(len(quads)), 4)
    _, inv = np.unique(e, axis=0, return_inverse=True)
    inv = inv.ravel()
    M = sp.coo_matrix((np.ones(len(q)), (q, inv)), shape=(len(quads), inv.max() + 1)).tocsr()
    n, lab = connected_components(M @ M.T, directed=False)
    return quads[lab == np.argmax(np.bincount(lab))]


def clipped_grid(poly, uv, h):
    """The clipped square grid (``layout = "grid"``).

    Grid nodes inside the domain are kept; a cell with three or two (adjacent) corners inside gets its
    outside corners projected to the nearest boundary point; cells that become too small (an edge
    < h/4) or non-convex are dropped.

    Args:
        poly: the flat domain (a shapely Polygon) [m].
        uv: (n,2) [m] the flattening's vertices (the grid's extent).
        h: the spacing [m].

    Returns:
        (P (n,2) [m], quads (q,4) CCW); InputError naming ``pattern.spacing`` when no cell fits.
    """

    lo, hi = uv.min(axis=0), uv.max(axis=0)
    ni = np.arange(np.floor(lo[0] / h) - 1, np.ceil(hi[0] / h) + 2)
    nj = np.arange(np.floor(lo[1] / h) - 1, np.ceil(hi[1] / h) + 2)
    I, J = np.meshgrid(ni, nj, indexing="ij")
    G = np.stack([I * h, J * h], axis=-1)  # (a, b, 2)
    inside = shapely.contains_xy(poly, G[..., 0], G[..., 1])
    ring = poly.exterior
    proj = G.copy()
    out_idx = np.argwhere(~inside)
    if len(out_idx):
        pts = shapely.points(G[~inside])
        near = shapely.line_interpolate_point(ring, shapely.line_locate_point(ring, pts))
        proj[~inside] = shapely.get_coordinates(near)
    quads = []
    A, B = inside.shape
    for i in range(A - 1):
        for j in range(B - 1):
            c = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)]
            ins = [inside[k] for k in c]
            nin = sum(ins)
            if nin == 4 or nin == 3 or (nin == 2 and (ins[0] == ins[1] or ins[1] == ins[2])):
                Q = np.array([proj[k] for k in c])
                if _good_quad(Q, h):
                    quads.append([k[0] * B + k[1] for k in c])
    if not quads:
        raise InputError(f"no quad fits the flat domain at spacing {h} m (make pattern.spacing smaller)",
                         where="pattern.spacing")
    quads = np.array(quads)
    quads = largest_component(quads)
    used, inv = np.unique(quads, return_inverse=True)
    quads = inv.reshape(-1, 4)
    P = proj.reshape(-1, 2)[used]
    return P, quads


MESH_CORNER_DEG = 25.0  # outline vertices turning by more than this are corners of the mesh's boundary curves


@dataclass(frozen=True, kw_only=True)
class MeshRecipe:
    """One quad meshing of the flat domain (:func:`mesh_quads`).

    Args:
        full_quad: True: a triangulation of edge 2 ``size`` h, its triangles paired into quads (a
            maximum-weight matching, the quads' squareness the weight), then every quad split into 4
            and every unpaired triangle into 3 (edge ~h, inserts with 3-6 beams); False: a
            triangulation of edge ``size`` h whose triangles are all paired into quads (a perfect
            matching; none when it does not exist).
        size: the triangulation's edge [spacings].
        uniform_outline: each outline curve (between corners) divided into round(L / h) equal edges
            (the two sides of a seam, of equal flat length, then get facing vertices).
        lattice: the interior seeded with a square lattice of the triangulation's edge centred on the
            domain (its triangles pair back into squares: a regular core); False: Triangle's own
            quality refinement places the points.
        margin: the lattice points' distance from the outline [edges].
    """

    full_quad: bool
    size: float
    uniform_outline: bool
    lattice: bool = False
    margin: float = 0.5


#: the meshings :func:`layout` tries with ``layout = "mesh"``, keeping the pattern with the fewest
#: defects (unreachable gaps, quads short of spring slack or without a spring), then the largest
#: covered area. The full-quad ones always yield quads only; the uniform outline keeps short outline
#: curves (a rim piece between two seams) from seeding strips of thin quads whose short edges leave
#: no room for a gap.
MESH_RECIPES = (MeshRecipe(full_quad=True, size=1.0, uniform_outline=True, lattice=True, margin=0.5),
                MeshRecipe(full_quad=True, size=1.0, uniform_outline=True, lattice=True, margin=0.35),
                MeshRecipe(full_quad=True, size=1.0, uniform_outline=True, lattice=True, margin=0.7),
                MeshRecipe(full_quad=True, size=1.2, uniform_outline=False),
                MeshRecipe(full_quad=False, size=1.0, uniform_outline=True, lattice=True, margin=0.6),
                MeshRecipe(full_quad=False, size=1.1, uniform_outline=True))


MESH_MIN_ANGLE_DEG = 28.0  # smallest triangle angle asked of Triangle (its quality bound)


MESH_SHORT_EDGE = 0.6  # [spacings] the smoothing lengthens edges shorter than this


MESH_SMOOTHING = 10  # Laplacian sweeps of the quad mesh's interior vertices (undone where a quad folds)


def mesh_quads(poly, h: float, recipe: MeshRecipe = MESH_RECIPES[0]) -> tuple[np.ndarray, np.ndarray] | None:
    """Boundary-following unstructured quad mesh of the flat domain ``poly`` (``layout = "mesh"``).

    For outlines a grid cannot follow (the notches a cut flattening's wedges leave,
    :mod:`simfab.deploy.cuts`). The outline is split at its corners (turning angle >
    ``MESH_CORNER_DEG``: cone tips, where a seam meets the rim) into curves, each divided into equal
    arc-length edges (points on the outline); Triangle (Shewchuk's quality Delaunay mesher, the
    ``triangle`` package: no system libraries) meshes the domain without adding outline points, the
    triangles are paired into quads (:class:`MeshRecipe`), and the interior vertices are smoothed.
    What a boundary edge leaves out is its chord's segment (2/3 s L, sagitta s ~ h^2 / (8 R) on a
    rim of radius R). Deterministic.

    Args:
        poly: the flat domain (a shapely Polygon) [m].
        h: the spacing [m].
        recipe: how to mesh it.

    Returns:
        (P (n,2) [m], quads (q,4) CCW), or None when the recipe leaves triangles (no perfect matching).
    """
    import triangle

    ring = np.asarray(poly.exterior.coords)[:-1]
    if not poly.exterior.is_ccw:
        ring = ring[::-1]
    d1, d2 = ring - np.roll(ring, 1, axis=0), np.roll(ring, -1, axis=0) - ring
    turn = np.abs(np.arctan2(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0], np.sum(d1 * d2, axis=1)))
    corners = np.flatnonzero(turn > np.radians(MESH_CORNER_DEG))
    corners = corners if len(corners) else np.array([0])
    n = len(ring)
    edge = recipe.size * h * (2.0 if recipe.full_quad else 1.0)
    curves = []
    for a, b in zip(corners, np.r_[corners[1:], corners[0]]):
        pts = ring[np.arange(a, b + (n if b <= a else 0) + 1) % n]
        curves.append(pts)
    lengths = [float(np.sum(np.linalg.norm(np.diff(c, axis=0), axis=1))) for c in curves]
    count = [max(1, int(round(L / edge))) for L in lengths]
    if not recipe.full_quad and sum(count) % 2:
        count[int(np.argmax(np.asarray(lengths) / count))] += 1
    outline = []
    for c, L, m in zip(curves, lengths, count):
        s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))]
        if recipe.uniform_outline or recipe.full_quad:
            t = np.linspace(0.0, L, m + 1)[:-1]
        else:  # the outline's own points, thinned to about the edge length
            keep = np.r_[0, np.flatnonzero(np.diff(np.floor(s / edge)) > 0) + 1]
            t = s[keep[keep < len(s) - 1]]
        outline.append(np.column_stack([np.interp(t, s, c[:, 0]), np.interp(t, s, c[:, 1])]))
    B = np.concatenate(outline)
    if len(B) < 3:
        return None
    seg = np.column_stack([np.arange(len(B)), np.roll(np.arange(len(B)), -1)])
    area = np.sqrt(3) / 4 * edge**2
    opts = f"pq{MESH_MIN_ANGLE_DEG:g}a{area:.6g}YQ"
    if recipe.lattice:
        x0, y0, x1, y1 = poly.bounds
        c = np.asarray(poly.centroid.coords[0])
        gx = c[0] + edge * np.arange(np.floor((x0 - c[0]) / edge), np.ceil((x1 - c[0]) / edge) + 1)
        gy = c[1] + edge * np.arange(np.floor((y0 - c[1]) / edge), np.ceil((y1 - c[1]) / edge) + 1)
        G = np.stack(np.meshgrid(gx, gy, indexing="ij"), axis=-1).reshape(-1, 2)
        inner = poly.buffer(-recipe.margin * edge)
        G = G[shapely.contains_xy(inner, G[:, 0], G[:, 1])] if not inner.is_empty else G[:0]
        B = np.concatenate([B, G])
        opts = f"pq{MESH_MIN_ANGLE_DEG:g}YQ"
    try:
        tri = triangle.triangulate(dict(vertices=B, segments=seg), opts)
    except Exception:  # Triangle rejects a self-touching outline
        return None
    X, T = np.asarray(tri["vertices"], dtype=np.float64), np.asarray(tri["triangles"], dtype=np.int64)
    if len(T) == 0:
        return None
    quads, single = _pair_triangles(X, T, n_fixed=len(B) - (len(G) if recipe.lattice else 0))
    if recipe.full_quad:
        X, quads = _split_into_quads(X, quads, T[single], poly)
    elif len(single):
        return None
    fixed = np.zeros(len(X), dtype=bool)
    fixed[_outline(quads)] = True
    quads = _ccw(X, quads)
    X = _smart_smooth(X, quads, fixed, MESH_SMOOTHING, short_edge=MESH_SHORT_EDGE * h)
    if not np.all(_convex(X, quads)):
        return None
    used, inv = np.unique(quads, return_inverse=True)
    P = X[used]
    return P, _ccw(P, inv.reshape(-1, 4))


def _corner_sines(Q: np.ndarray) -> np.ndarray:
    """(..., 4) the sine of each corner of CCW quads Q (..., 4, 2) (< 0: a reflex corner)."""
    a, b = np.roll(Q, 1, axis=-2) - Q, np.roll(Q, -1, axis=-2) - Q
    cross = b[..., 0] * a[..., 1] - b[..., 1] * a[..., 0]
    return cross / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1) + 1e-300)


def _smart_smooth(P: np.ndarray, quads: np.ndarray, fixed: np.ndarray, sweeps: int,
                  short_edge: float = 0.0) -> np.ndarray:
    """Gauss-Seidel Laplacian smoothing of the free vertices over the quad edges, a move kept only
    where it does not lower the vertex's quality: the smallest corner sine of its quads (so a reflex
    corner can only open up, a convex mesh stays convex) and, with ``short_edge`` [m], its shortest
    edge over ``short_edge`` (short edges lengthen: an insert needs room for its gap)."""
    X = P.copy()
    e = np.unique(np.sort(np.concatenate([quads[:, [k, (k + 1) % 4]] for k in range(4)]), axis=1), axis=0)
    nbr = [[] for _ in range(len(X))]
    for a, b in e:
        nbr[a].append(b)
        nbr[b].append(a)
    inq = [[] for _ in range(len(X))]
    for q, vs in enumerate(quads):
        for v in vs:
            inq[v].append(q)
    free = [v for v in range(len(X)) if not fixed[v] and nbr[v]]
    def quality(v, qs):
        q = _corner_sines(X[qs]).min()
        if short_edge:
            q = min(q, np.linalg.norm(X[nbr[v]] - X[v], axis=1).min() / short_edge)
        return q

    for _ in range(sweeps):
        for v in free:
            qs = quads[inq[v]]
            old = X[v].copy()
            before = quality(v, qs)
            lap, ring = X[nbr[v]].mean(axis=0), X[np.unique(qs)].mean(axis=0)
            near = X[nbr[v]][np.argmin(np.linalg.norm(X[nbr[v]] - old, axis=1))]
            best, best_q = old, before
            for cand in (lap, 0.5 * (old + lap), ring, 0.5 * (old + ring), old + 0.2 * (old - near)):
                X[v] = cand
                q = quality(v, qs)
                if q > best_q or (q == best_q and cand is lap):
                    best, best_q = cand, q
                    if cand is lap:
                        break
            X[v] = best
    return X


def _convex(P: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """(q,) bool: every corner of each (CCW) quad turns left."""
    Q = P[quads]
    a, b = np.roll(Q, 1, axis=1) - Q, np.roll(Q, -1, axis=1) - Q
    return np.all(b[..., 0] * a[..., 1] - b[..., 1] * a[..., 0] > 0, axis=1)


def _pair_triangles(X: np.ndarray, T: np.ndarray, n_fixed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Pair adjacent triangles into convex quads: a maximum-cardinality matching of the triangles'
    adjacency (pairs forming a convex quad only) of largest total squareness (1 - the largest
    deviation of a corner from 90 deg over 90 deg, plus 1); a non-convex pair only at a tiny weight, and
    only when its reflex corner is a free vertex (ids >= ``n_fixed``: the smoothing may open it).
    Returns (quads (p,4), unpaired triangle ids)."""
    import networkx as nx

    e = np.concatenate([T[:, [1, 2]], T[:, [2, 0]], T[:, [0, 1]]])
    opp = np.concatenate([T[:, 0], T[:, 1], T[:, 2]])
    tid = np.tile(np.arange(len(T)), 3)
    key = np.sort(e, axis=1)
    order = np.lexsort((key[:, 1], key[:, 0]))
    k = key[order]
    same = np.flatnonzero(np.all(k[1:] == k[:-1], axis=1))
    i, j = order[same], order[same + 1]
    # the quad (opp_i, e_i[0], opp_j, e_i[1]) - CCW when T is CCW
    cand = np.column_stack([opp[i], e[i, 0], opp[j], e[i, 1]])
    cand = _ccw(X, cand)
    Q = X[cand]
    a, b = np.roll(Q, 1, axis=1) - Q, np.roll(Q, -1, axis=1) - Q
    cross = b[..., 0] * a[..., 1] - b[..., 1] * a[..., 0]
    cos = np.einsum("qki,qki->qk", a, b) / (np.linalg.norm(a, axis=2) * np.linalg.norm(b, axis=2))
    dev = np.max(np.abs(np.degrees(np.arccos(np.clip(cos, -1, 1))) - 90.0), axis=1)
    convex = np.all(cross > 0, axis=1)
    fixable = ~np.any((cross <= 0) & (cand < n_fixed), axis=1)
    G = nx.Graph()
    G.add_nodes_from(range(len(T)))
    rim = np.sum(T < n_fixed, axis=1) >= 2  # a triangle on the outline: paired first (its split would
    bonus = rim.astype(float)  # leave a short edge at an outline insert, whose gap then has no room)
    for q in np.flatnonzero(convex | fixable):  # a non-convex pair only where the matching needs it
        a_, b_ = int(tid[i[q]]), int(tid[j[q]])
        G.add_edge(a_, b_, weight=(2.0 - dev[q] / 90.0 if convex[q] else 0.01) + bonus[a_] + bonus[b_], quad=q)
    match = nx.max_weight_matching(G, maxcardinality=True)
    pairs = sorted(tuple(sorted(m)) for m in match)
    quads = np.array([cand[G.edges[a_, b_]["quad"]] for a_, b_ in pairs], dtype=np.int64).reshape(-1, 4)
    paired = np.zeros(len(T), dtype=bool)
    paired[np.asarray(pairs, dtype=np.int64).ravel()] = True
    return quads, np.flatnonzero(~paired)


def _split_into_quads(X: np.ndarray, quads: np.ndarray, tris: np.ndarray, poly):
    """Every quad into 4 and every triangle into 3 quads (edge midpoints, face centroid); the midpoints
    of outline edges moved onto the outline ``poly``. Returns (X', quads')."""
    faces = [list(q) for q in quads] + [list(t) for t in tris]
    mid: dict = {}
    pts = [p for p in X]

    def midpoint(a, b):
        k = (min(a, b), max(a, b))
        if k not in mid:
            mid[k] = len(pts)
            pts.append(0.5 * (X[a] + X[b]))
        return mid[k]

    out = []
    for f in faces:
        c = len(pts)
        pts.append(X[f].mean(axis=0))
        m = [midpoint(f[k], f[(k + 1) % len(f)]) for k in range(len(f))]
        for k in range(len(f)):
            out.append([f[k], m[k], c, m[k - 1]])
    quads = np.asarray(out, dtype=np.int64)
    P = np.asarray(pts)
    ring = poly.exterior
    for v in _outline(quads):
        if v >= len(X):  # a new outline midpoint: onto the outline
            P[v] = np.asarray(ring.interpolate(ring.project(shapely.Point(P[v]))).coords[0])
    return P, quads


CORE_MARGIN = 0.5  # core grid nodes keep >= CORE_MARGIN x spacing from the boundary


SMOOTHING_ITERATIONS = 20  # sweeps of conforming_core = "smoothed"


def conforming_quads(poly, h: float, uv: np.ndarray, *,
                     sweeps: int = SMOOTHING_ITERATIONS) -> tuple[np.ndarray, np.ndarray]:
    """Boundary-conforming quad mesh of the flat domain (``layout = "conforming"``).

    A square grid core with one *pillow* layer (as in hexahedral meshing): the core is the grid cells
    whose corners lie at least :data:`CORE_MARGIN` h inside the domain; every vertex v_k of its outline
    loop gets a boundary vertex p_k, and every loop edge one quad (v_k, p_k, p_k+1, v_k+1), so no quad
    has three boundary vertices on a line. ``sweeps`` Laplacian sweeps then smooth the core's outline
    (``sweeps = 0``: the core stays on the grid and each p_k lies on its loop vertex's outward
    bisector). The p_k are moved off the boundary so that each chord's segment area is balanced
    (:func:`_area_preserving`). Method notes: docs/methods.md, "simfab.deploy.quadmesh".

    Args:
        poly: the flat domain (a shapely Polygon) [m].
        h: the spacing [m].
        uv: (n,2) [m] the flattening's vertices (the grid's extent).
        sweeps: Jacobi sweeps of the core's outline (0: left on the grid).

    Returns:
        (P (n,2) [m], quads (q,4) CCW); InputError naming ``pattern.spacing`` when no core cell fits.
    """

    ring = poly.exterior
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    ni = np.arange(np.floor(lo[0] / h) - 1, np.ceil(hi[0] / h) + 2)
    nj = np.arange(np.floor(lo[1] / h) - 1, np.ceil(hi[1] / h) + 2)
    I, J = np.meshgrid(ni, nj, indexing="ij")
    G = np.stack([I * h, J * h], axis=-1)
    A, B = I.shape
    flatG = G.reshape(-1, 2)
    pts = shapely.points(flatG)
    core = (shapely.contains_xy(poly, flatG[:, 0], flatG[:, 1])
            & (shapely.distance(ring, pts) >= CORE_MARGIN * h)).reshape(A, B)
    cells = [[i * B + j, (i + 1) * B + j, (i + 1) * B + j + 1, i * B + j + 1]
             for i in range(A - 1) for j in range(B - 1)
             if core[i, j] and core[i + 1, j] and core[i + 1, j + 1] and core[i, j + 1]]
    if not cells:
        raise InputError(f"no quad fits the flat domain at spacing {h} m (make pattern.spacing smaller)",
                         where="pattern.spacing")
    quads = largest_component(np.array(cells))
    quads = _remove_pinches(quads)
    loop = _outline(quads)  # CCW loop of core vertex ids
    # boundary vertices: nearest points, then arc-length positions made to follow the loop's order
    L = ring.length
    s = np.asarray(shapely.line_locate_point(ring, shapely.points(flatG[loop])), dtype=np.float64)
    if sweeps == 0:  # along the outward bisectors: no straight angle at a staircase corner
        s = _bisector_positions(ring, flatG[loop], s)
    ccw = shapely.Polygon(flatG[loop]).exterior.is_ccw == ring.is_ccw  # both loops the same way round
    if not ccw:
        s = -s
    s = np.unwrap(s / L * 2 * np.pi) * L / (2 * np.pi)  # continuous around the loop
    s = _monotone(s, L, relax=2 if sweeps else 0)
    if not ccw:
        s = -s
    p = shapely.get_coordinates(shapely.line_interpolate_point(ring, np.mod(s, L)))
    p = _area_preserving(ring, s, p)
    n0 = len(flatG)
    P = np.vstack([flatG, p])
    m = len(loop)
    k = np.arange(m)
    pillow = np.stack([loop, n0 + k, n0 + (k + 1) % m, loop[(k + 1) % m]], axis=1)
    quads = np.vstack([quads, pillow])
    quads = _ccw(P, quads)
    used, inv = np.unique(quads, return_inverse=True)
    quads = inv.reshape(-1, 4)
    P = P[used]
    movable = np.isin(used, loop)  # only the core's outline moves (the grid inside it stays regular)
    P = _smooth(P, quads, ~movable, sweeps)
    return P, quads


def _bisector_positions(ring, V: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Arc-length positions (m,) on ``ring`` where the outward bisector of each vertex of the
    closed loop V (m,2) [m] (the normalised sum of its two edges' outward normals) first meets it
    (``s`` (m,): the nearest points', kept where a ray misses). At a convex staircase corner of an
    unsmoothed core the nearest point lies on the line of one of its loop edges, and the pillow
    quad there would have a straight angle (no spring); on the bisector both pillow quads get
    ~135 deg."""

    d = np.roll(V, -1, axis=0) - V
    orient = np.sign(np.sum(V[:, 0] * np.roll(V[:, 1], -1) - np.roll(V[:, 0], -1) * V[:, 1]))
    nrm = orient * np.column_stack([d[:, 1], -d[:, 0]]) / np.linalg.norm(d, axis=1)[:, None]
    b = nrm + np.roll(nrm, 1, axis=0)
    b /= np.linalg.norm(b, axis=1)[:, None]
    reach = 2.0 * float(np.ptp(V, axis=0).max() + ring.length)
    out = s.copy()
    for k in range(len(V)):
        hit = shapely.intersection(shapely.LineString([V[k], V[k] + reach * b[k]]), ring)
        pts = shapely.get_coordinates(hit)
        if len(pts):
            first = pts[np.argmin(np.linalg.norm(pts - V[k], axis=1))]
            out[k] = shapely.line_locate_point(ring, shapely.Point(first))
    return out


AREA_SAMPLES = 24  # boundary points per chord for its segment area


def _area_preserving(ring, s: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Boundary vertices p (m,2) [m] (at arc-length positions s (m,) on ``ring``, in the loop's
    order) moved along the outline's vertex normals so that each chord's segment area is balanced:
    chord j (p_j, p_j+1, length L_j) bounds the segment of signed area A_j between it and the
    boundary (positive where the boundary bulges out of the outline), whose mean height is
    delta_j = A_j / L_j; moving the chord outward by delta_j leaves as much of the segment outside
    as it adds beyond the boundary (a parabolic arc: the chord at 2/3 of the sagitta). A vertex
    moves by the mean of its two chords' delta along the mean of their outward normals."""

    m = len(p)
    t = np.linspace(0.0, 1.0, AREA_SAMPLES + 1)
    s1 = np.r_[s[1:], s[0] + (ring.length if s[-1] > s[0] else -ring.length)]
    arc = shapely.get_coordinates(shapely.line_interpolate_point(
        ring, np.mod(s[:, None] + t[None, :] * (s1 - s)[:, None], ring.length).ravel())).reshape(m, -1, 2)
    arc[:, 0], arc[:, -1] = p, np.roll(p, -1, axis=0)
    x, y = arc[..., 0], arc[..., 1]
    shoelace = 0.5 * np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1)  # arc + chord back
    q = np.roll(p, -1, axis=0)
    orient = np.sign(np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]))  # +1: the outline runs CCW
    d = q - p
    Lc = np.linalg.norm(d, axis=1)
    nrm = orient * np.column_stack([d[:, 1], -d[:, 0]]) / Lc[:, None]  # outward normal of each chord
    delta = orient * shoelace / Lc  # a boundary bulging outward closes the way the outline runs
    vn = nrm + np.roll(nrm, 1, axis=0)
    vn /= np.linalg.norm(vn, axis=1)[:, None]
    return p + (0.5 * (delta + np.roll(delta, 1)))[:, None] * vn


def _remove_pinches(quads: np.ndarray) -> np.ndarray:
    """Drop cells until every vertex on the outline has exactly two outline edges (no two parts
    touching at one corner): the cell at such a vertex with the fewest edge neighbours goes."""
    while True:
        e = np.sort(np.concatenate([quads[:, [k, (k + 1) % 4]] for k in range(4)]), axis=1)
        uniq, inv, cnt = np.unique(e, axis=0, return_inverse=True, return_counts=True)
        bnd = uniq[cnt == 1]
        deg = np.bincount(bnd.ravel(), minlength=int(quads.max()) + 1)
        bad = np.flatnonzero(deg > 2)
        if not len(bad):
            return largest_component(quads)
        qi = np.flatnonzero(np.any(quads == bad[0], axis=1))
        nb = [int(np.sum(cnt[inv.ravel()[np.arange(4) * len(quads) + q]] == 2)) for q in qi]
        quads = np.delete(quads, qi[int(np.argmin(nb))], axis=0)


def _outline(quads: np.ndarray) -> np.ndarray:
    """Vertex ids of the outline of a quad mesh with one simple boundary loop, in the quads' order
    (CCW for CCW quads)."""
    nxt = {}
    directed = np.concatenate([quads[:, [k, (k + 1) % 4]] for k in range(4)])
    key = np.sort(directed, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    for a, b in directed[cnt[inv.ravel()] == 1]:
        nxt[int(a)] = int(b)
    start = next(iter(nxt))
    loop = [start]
    while nxt[loop[-1]] != start:
        loop.append(nxt[loop[-1]])
    return np.array(loop)


def _monotone(s: np.ndarray, L: float, relax: int = 2) -> np.ndarray:
    """Arc-length positions (m,) made strictly increasing within one turn (each at least L / (4 m)
    after the previous: nearest points of neighbouring loop vertices can come in the wrong order at
    a convex staircase corner), then relaxed ``relax`` times towards their neighbours' mean (even
    spacing; 0 keeps the bisector positions of an unsmoothed core)."""
    m = len(s)
    out = s.copy()
    gap = L / (4.0 * m)
    for k in range(1, m):
        out[k] = max(out[k], out[k - 1] + gap)
    if out[-1] - out[0] > L - gap:  # compress into one turn
        out = out[0] + (out - out[0]) * (L - gap) / (out[-1] - out[0])
    for _ in range(relax):
        prev = np.r_[out[-1] - L, out[:-1]]
        nxt = np.r_[out[1:], out[0] + L]
        out = 0.5 * out + 0.25 * (prev + nxt)
    return out


def _ccw(P: np.ndarray, quads: np.ndarray) -> np.ndarray:
    Q = P[quads]
    area = np.sum(Q[:, :, 0] * np.roll(Q[:, :, 1], -1, axis=1) - np.roll(Q[:, :, 0], -1, axis=1) * Q[:, :, 1], axis=1)
    out = quads.copy()
    out[area < 0] = out[area < 0][:, ::-1]
    return out


def _smooth(P: np.ndarray, quads: np.ndarray, fixed: np.ndarray, iterations: int) -> np.ndarray:
    """Jacobi Laplacian smoothing over the quad edges (fixed vertices stay)."""

    e = np.unique(np.sort(np.concatenate([quads[:, [k, (k + 1) % 4]] for k in range(4)]), axis=1), axis=0)
    n = len(P)
    W = sp.coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(n, n)).tocsr()
    deg = np.asarray(W.sum(axis=1)).ravel()
    X = P.copy()
    for _ in range(iterations):
        X = np.where(fixed[:, None], P, (W @ X) / deg[:, None])
    return X
