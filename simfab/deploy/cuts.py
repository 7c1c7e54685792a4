"""Cuts: BFF with cone singularities chosen automatically, cut paths from the cones to the boundary.

A steep cap shrinks its centre beyond the growth the inserts reach; a cone concentrates curvature
at one vertex so that the flat metric e^{2u} g needs less scaling around it. Cone metric (the
notation of :mod:`simfab.deploy.flatten`; u = 0 on the boundary and at the cones C):

    A_{I'I'} u_{I'} = -Omega_{I'}            (I' = interior vertices that are not cones),

flat at every vertex of I', with the angle defect Omega~_c = Omega_c + (A u)_c at each cone c
(Ben-Chen, Gotsman and Bunin 2008; :func:`cone_metric`).

- :func:`place_cones`: greedy; while some interior vertex's growth is unreachable by the
  catalogue (:func:`reachable`) or beyond ``max_growth``, a cone at the most negative u at least
  ``boundary_distance`` / ``cone_distance`` spacings from the boundary and the other cones;
- :func:`cut_paths`: shortest mesh-edge paths from each cone to the boundary (a forest: the cut
  mesh stays a disk); :func:`cut_mesh` duplicates the cut vertices;
- :func:`flatten_with_cuts`: BFF of the cut mesh with the cone metric's u prescribed on its
  boundary; both sides of a cut are congruent (the seams), free in deployment or tied
  (:func:`seam_ties`, ``join_seams``).

The reasoning in full: docs/methods.md, "simfab.deploy.cuts".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import shapely
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from simfab.deploy import flatten as bff
from simfab.deploy.pattern import near_seams
from simfab.errors import InputError


@dataclass(frozen=True, kw_only=True)
class CutsConfig:
    """Scene ``[cuts]`` table.

    Args:
        max_cones: cone singularities the greedy placement may add (0: no cuts).
        boundary_distance: smallest graph distance of a cone from the boundary, in pattern spacings
            [-] (a cone nearer the boundary would only cut off a sliver).
        cone_distance: smallest graph distance between two cones, in pattern spacings [-] (two cones
            closer than a cell would share one).
        max_growth: largest cell growth e^{-u} the torsional springs follow [-]
            (:mod:`simfab.deploy.springs`): cones are added until every interior vertex has a
            reachable gap and e^{-u} <= max_growth.
        join_seams: close the seams in deployment by ties between facing seam vertices
            (:func:`seam_ties`; false: the seams stay free).
    """

    max_cones: int = 0
    boundary_distance: float = 1.5
    cone_distance: float = 2.0
    max_growth: float = 1.25
    join_seams: bool = False

    def __post_init__(self):
        if not isinstance(self.join_seams, bool):
            raise InputError(f"must be true or false (got {self.join_seams!r})", where="cuts.join_seams")
        if isinstance(self.max_cones, bool) or not isinstance(self.max_cones, int) or self.max_cones < 0:
            raise InputError(f"must be a non-negative integer (got {self.max_cones!r})", where="cuts.max_cones")
        for f in ("boundary_distance", "cone_distance", "max_growth"):
            v = getattr(self, f)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (np.isfinite(v) and v > 0):
                raise InputError(f"must be a positive number (got {v!r})", where=f"cuts.{f}")


@dataclass(frozen=True)
class Seam:
    """One cut path.

    Args:
        cone: the cone's vertex id.
        path: (k,) original vertex ids from the cone (or branch point) to where it meets the
            boundary or an earlier cut.
        sides: (2,k) the cut-mesh vertex ids of its two sides (the copies on either side, in the
            order of ``path``).
    """

    cone: int
    path: np.ndarray
    sides: np.ndarray


@dataclass(frozen=True)
class CutFlattening:
    """Result of :func:`flatten_with_cuts`.

    Args:
        V: (n',3) [m] the cut mesh's vertices (copies along the cuts).
        F: (m,3) its faces.
        orig: (n',) the original vertex of each.
        flat: the :class:`simfab.deploy.flatten.Flattening` of the cut mesh.
        cones: (c,) original vertex ids.
        cone_defect: (c,) [rad] the cone metric's angle defect at each.
        u_uncut: (n,) [-] the cone metric's u on the original mesh.
        seams: one :class:`Seam` per cone.
        unreachable_vertices: interior vertices whose growth no catalogue size reaches, without cones
            and with them (counts).
    """

    V: np.ndarray
    F: np.ndarray
    orig: np.ndarray
    flat: object
    cones: np.ndarray
    cone_defect: np.ndarray
    u_uncut: np.ndarray
    seams: list
    unreachable_vertices: dict


def reachable(u: np.ndarray, spacing: float, sizes, min_gap: float, min_beam: float) -> np.ndarray:
    """Where some catalogue size r has an achievable gap for the growth d = (h/2)(e^{-u} - 1), i.e.
    ``min_gap <= r - d <= h/2 - min_beam`` (the gap rule of :mod:`simfab.deploy.pattern` at a regular cell).

    Args:
        u: (n,) [-] log scale factors.
        spacing: h [m].
        sizes: the catalogue [m].
        min_gap: [m].
        min_beam: [m].

    Returns:
        (n,) bool.
    """
    d = 0.5 * spacing * np.expm1(-np.asarray(u, dtype=np.float64))[:, None]
    g = np.asarray(sizes, dtype=np.float64)[None, :] - d
    return np.any((g >= min_gap) & (g <= 0.5 * spacing - min_beam), axis=1)


def _edges(F: np.ndarray) -> np.ndarray:
    return np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1), axis=0)


def _graph(V: np.ndarray, F: np.ndarray) -> sp.csr_matrix:
    e = _edges(F)
    w = np.linalg.norm(V[e[:, 0]] - V[e[:, 1]], axis=1)
    n = len(V)
    return sp.coo_matrix((np.r_[w, w], (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(n, n)).tocsr()


def cone_metric(V: np.ndarray, F: np.ndarray, cones) -> tuple[np.ndarray, np.ndarray]:
    """The cone metric with u = 0 on the boundary and at the cones (see the module doc).

    Args:
        V: (n,3) [m] vertices.
        F: (m,3) faces.
        cones: (c,) vertex ids.

    Returns:
        (u (n,) [-], the cones' angle defects Omega~ (c,) [rad]).
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    n = len(V)
    cones = np.asarray(cones, dtype=np.int64)
    loop = bff.boundary_loop(F, n)
    ang = bff.corner_angles(V, F)
    A = bff.cotan_laplacian(V, F, ang)
    omega = 2.0 * np.pi - np.bincount(F.ravel(), weights=ang.ravel(), minlength=n)
    fixed = np.zeros(n, dtype=bool)
    fixed[loop] = True
    fixed[cones] = True
    free = np.flatnonzero(~fixed)
    u = np.zeros(n)
    if len(free):
        u[free] = bff.CholeskyFactor(A[free][:, free]).solve(-omega[free])
    return u, omega[cones] + (A @ u)[cones]


def place_cones(V: np.ndarray, F: np.ndarray, cfg: CutsConfig, pattern_cfg) -> tuple[np.ndarray, np.ndarray]:
    """Greedy cone placement (see the module doc).

    Args:
        V: (n,3) [m] vertices.
        F: (m,3) faces.
        cfg: the :class:`CutsConfig`.
        pattern_cfg: the :class:`simfab.deploy.pattern.PatternConfig` (spacing, catalogue, gap limits).

    Returns:
        (cones (c,) vertex ids, u (n,) [-] of the cone metric).
    """
    n = len(V)
    loop = bff.boundary_loop(F, n)
    G = _graph(V, F)
    h = pattern_cfg.spacing
    d_bnd = dijkstra(G, indices=loop, min_only=True)
    interior = np.ones(n, dtype=bool)
    interior[loop] = False
    cones: list[int] = []
    d_cone = np.full(n, np.inf)
    while True:
        u, _ = cone_metric(V, F, cones)
        ok = reachable(u, h, pattern_cfg.sizes, pattern_cfg.min_gap, pattern_cfg.min_beam) & (-u <= np.log(
            cfg.max_growth))
        if np.all(ok[interior]) or len(cones) >= cfg.max_cones:
            return np.asarray(cones, dtype=np.int64), u
        cand = interior & (u < 0) & (d_bnd >= cfg.boundary_distance * h) & (d_cone >= cfg.cone_distance * h)
        if not cand.any():
            return np.asarray(cones, dtype=np.int64), u
        c = int(np.argmin(np.where(cand, u, np.inf)))
        cones.append(c)
        d_cone = np.minimum(d_cone, dijkstra(G, indices=c))


def cut_paths(V: np.ndarray, F: np.ndarray, cones) -> list[np.ndarray]:
    """Per cone (in order), the shortest mesh-edge path from it to the boundary that avoids the earlier
    cuts (their vertices removed from the graph); where the earlier cuts wall a cone off, the path
    may end on an earlier cut instead.

    Args:
        V: (n,3) [m] vertices.
        F: (m,3) faces.
        cones: (c,) vertex ids.

    Returns:
        One path (k,) of vertex ids per cone, its last vertex on the boundary or an earlier cut.
    """
    n = len(V)
    G = _graph(V, F).tolil()
    bnd = set(bff.boundary_loop(F, n).tolist())
    used: set[int] = set()
    paths = []
    for c in cones:
        H = G.copy()
        for v in used:  # block the earlier cuts' interior vertices
            H[v, :] = 0
            H[:, v] = 0
        for roots, graph in ((bnd, H), (bnd | used, G)):
            src = np.fromiter(roots, dtype=np.int64)
            _, pred, source = dijkstra(graph.tocsr(), indices=src, min_only=True, return_predecessors=True)
            if source[c] >= 0:
                break
        else:
            raise InputError(f"cone at vertex {c} is not connected to the boundary", where="target")
        path = [int(c)]
        while path[-1] not in roots:
            path.append(int(pred[path[-1]]))
        paths.append(np.asarray(path, dtype=np.int64))
        used.update(p for p in path if p not in bnd)
    return paths


def cut_mesh(F: np.ndarray, n: int, cut_edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cut a triangle mesh along edges. Each vertex on a cut gets one copy per wedge of its faces (faces
    joined across its uncut edges); the first wedge keeps the vertex's id, the others get new ids
    n, n+1, ...

    Args:
        F: (m,3) faces.
        n: the vertex count.
        cut_edges: (k,2) the edges to cut.

    Returns:
        (F' (m,3), orig (n',): the original vertex of each vertex of the cut mesh).
    """
    F = np.asarray(F, dtype=np.int64)
    cut = {(int(min(a, b)), int(max(a, b))) for a, b in cut_edges}
    Fn = F.copy()
    orig = list(range(n))
    touched = sorted({v for e in cut for v in e})
    for v in touched:
        faces = np.flatnonzero(np.any(F == v, axis=1))
        parent = {int(f): int(f) for f in faces}

        def find(f):
            while parent[f] != f:
                parent[f] = parent[parent[f]]
                f = parent[f]
            return f

        by_w: dict[int, list[int]] = {}
        for f in faces:
            for w in F[f]:
                if w != v:
                    by_w.setdefault(int(w), []).append(int(f))
        for w, fs in by_w.items():
            if len(fs) == 2 and (min(v, w), max(v, w)) not in cut:
                parent[find(fs[0])] = find(fs[1])
        groups: dict[int, list[int]] = {}
        for f in faces:
            groups.setdefault(find(int(f)), []).append(int(f))
        for k, fs in enumerate(sorted(groups.values(), key=min)):
            if k == 0:
                continue
            nid = len(orig)
            orig.append(v)
            for f in fs:
                Fn[f][F[f] == v] = nid
    return Fn, np.asarray(orig, dtype=np.int64)


def _seam_sides(F_cut: np.ndarray, orig: np.ndarray, path: np.ndarray) -> np.ndarray:
    """(2, k) cut-mesh copies of the path's vertices on either side: side s of cut edge (p_i, p_i+1)
    is the face containing it on that side; walking the path keeps the side (the two faces at each
    cut edge are ordered by their winding: side 0 traverses p_i -> p_i+1)."""
    sides = np.full((2, len(path)), -1, dtype=np.int64)
    fo = orig[F_cut]  # (m,3) original ids of each corner
    for i in range(len(path) - 1):
        a, b = path[i], path[i + 1]
        for f in np.flatnonzero(np.any(fo == a, axis=1) & np.any(fo == b, axis=1)):
            ka, kb = int(np.flatnonzero(fo[f] == a)[0]), int(np.flatnonzero(fo[f] == b)[0])
            s = 0 if (kb - ka) % 3 == 1 else 1
            sides[s, i], sides[s, i + 1] = F_cut[f, ka], F_cut[f, kb]
    return sides


def flatten_with_cuts(V, F, cfg: CutsConfig, pattern_cfg, *, cones=None) -> CutFlattening:
    """Cones, cut paths, and the BFF flattening of the cut mesh with the cone metric's u on its
    boundary (see the module doc).

    Args:
        V: (n,3) [m] vertices.
        F: (m,3) faces.
        cfg: the :class:`CutsConfig`.
        pattern_cfg: the :class:`simfab.deploy.pattern.PatternConfig`.
        cones: (c,) vertex ids (None: placed greedily, :func:`place_cones`).

    Returns:
        The :class:`CutFlattening`.
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    n = len(V)
    interior = np.ones(n, dtype=bool)
    interior[bff.boundary_loop(F, n)] = False
    u0, _ = cone_metric(V, F, [])
    args = (pattern_cfg.spacing, pattern_cfg.sizes, pattern_cfg.min_gap, pattern_cfg.min_beam)
    before = int(np.sum(~reachable(u0, *args)[interior]))
    if cones is None:
        cones, u = place_cones(V, F, cfg, pattern_cfg)
    else:
        cones = np.asarray(cones, dtype=np.int64)
        u, _ = cone_metric(V, F, cones)
    u, defect = cone_metric(V, F, cones)
    after = int(np.sum(~reachable(u, *args)[interior]))
    paths = cut_paths(V, F, cones)
    edges = np.concatenate([np.stack([p[:-1], p[1:]], axis=1) for p in paths]) if paths else np.zeros((0, 2), int)
    F_cut, orig = cut_mesh(F, n, edges)
    V_cut = V[orig]
    flat = bff.flatten(V_cut, F_cut, u_boundary=u[orig])
    seams = [Seam(cone=int(c), path=p, sides=_seam_sides(F_cut, orig, p)) for c, p in zip(cones, paths)]
    return CutFlattening(V=V_cut, F=F_cut, orig=orig, flat=flat, cones=np.asarray(cones, dtype=np.int64),
                         cone_defect=np.asarray(defect), u_uncut=u, seams=seams,
                         unreachable_vertices=dict(without_cones=before, with_cones=after))


@dataclass(frozen=True)
class SeamTies:
    """Ties across the seams (:func:`seam_ties`).

    Args:
        pairs: (k,2) pattern vertex ids facing each other across a cut.
        length: (k,) [m] their distance on the target.
    """

    pairs: np.ndarray
    length: np.ndarray


TIE_ACROSS = 1.5  # a pair is across a wedge when its flat distance exceeds this x its target distance
TIE_REACH = 1.5  # [spacings] largest target distance of a tied pair


def cone_points(cf: CutFlattening) -> np.ndarray:
    """The cones' flat positions (a cut path's cone end is one vertex of the cut mesh).

    Args:
        cf: the :class:`CutFlattening`.

    Returns:
        (c,2) [m].
    """
    return np.array([cf.flat.uv[np.flatnonzero(cf.orig == c)[0]] for c in cf.cones]).reshape(-1, 2)


def seam_lines(cf: CutFlattening) -> list:
    """Both sides of every cut path (the seams) in the flat domain; a cone placed on an earlier cut's path
    (its path is the one vertex) adds none.

    Args:
        cf: the :class:`CutFlattening`.

    Returns:
        [(label "S<k>", (j,2) [m] flat polyline)].
    """
    return [(f"S{k + 1}", cf.flat.uv[side]) for k, s in enumerate(cf.seams) if len(s.path) > 1 for side in s.sides]


def seam_ties(pat, Y: np.ndarray, cf: CutFlattening) -> SeamTies:
    """Pairs of seam vertices (pattern boundary vertices along a seam,
    :func:`simfab.deploy.pattern.near_seams`) that face each other across a cut: mutual nearest
    neighbours by their target points, within ``TIE_REACH`` spacings on the target and at least
    ``TIE_ACROSS`` times that apart in the flat pattern (two vertices along the same side of a seam are
    about as far apart flat as on the target).

    Args:
        pat: the :class:`simfab.deploy.pattern.Pattern`.
        Y: (n,3) [m] the pattern vertices' target points.
        cf: the :class:`CutFlattening`.

    Returns:
        The :class:`SeamTies`.
    """
    h = pat.config.spacing
    bnd = np.zeros(len(pat.P), dtype=bool)
    bnd[pat.edges[pat.edge_quads[:, 1] < 0].ravel()] = True
    poly = shapely.Polygon(cf.flat.uv[cf.flat.boundary])
    S = np.flatnonzero(bnd & near_seams(pat.P, poly, [p for _, p in seam_lines(cf)], h))
    if len(S) < 2:
        return SeamTies(pairs=np.zeros((0, 2), dtype=np.int64), length=np.zeros(0))
    # candidate pairs within reach on the target from a k-d tree (memory linear in the seam vertices)
    ij = cKDTree(Y[S]).query_pairs(TIE_REACH * h, output_type="ndarray").reshape(-1, 2)
    d3 = np.linalg.norm(Y[S[ij[:, 0]]] - Y[S[ij[:, 1]]], axis=1)
    d2 = np.linalg.norm(pat.P[S[ij[:, 0]]] - pat.P[S[ij[:, 1]]], axis=1)
    ok = (d2 > TIE_ACROSS * d3) & (d3 < TIE_REACH * h)
    ij, d3 = ij[ok], d3[ok]
    nn = np.full(len(S), -1)
    best = np.full(len(S), np.inf)
    for (a, b), d in zip(np.concatenate([ij, ij[:, ::-1]]), np.r_[d3, d3]):  # each one's nearest (first on ties)
        if d < best[a] or (d == best[a] and b < nn[a]):
            best[a], nn[a] = d, b
    pairs = [(S[i], S[j]) for i, j in enumerate(nn) if j >= 0 and nn[j] == i and i < j]
    P = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    return SeamTies(pairs=P, length=np.linalg.norm(Y[P[:, 0]] - Y[P[:, 1]], axis=1))
