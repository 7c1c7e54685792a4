"""Flat pattern layout on a flattened target: quad grid, beams, torsional springs, insert gaps.

Layout (all in the flat domain, metres):

- a square grid of spacing ``h`` centred on the flat domain; nodes inside the boundary are kept,
  a cell with three or two (adjacent) corners inside gets its outside corners projected to
  the nearest boundary point; cells that become too small (an edge < h/4) or non-convex are
  dropped, and the largest edge-connected set of cells is the quad mesh (``layout = "grid"``;
  ``"conforming"``: a grid core with a pillow layer on the outline, :func:`conforming_quads`;
  ``"mesh"``: an unstructured quad mesh of the domain (Triangle's triangulation paired into quads),
  :func:`mesh_quads`, the best of a few meshings, :data:`MESH_RECIPES`);
- every quad edge is a **beam** (width ``w``, sheet thickness ``t``), split at its midpoint
  by a rigid junction; each quad gets a **torsional spring**: four cubic Bezier arcs joining
  consecutive edge midpoints, bulging towards the quad centre, each quad's bulge sized so that
  the arcs are long enough for the growth the quad undergoes in deployment
  (:mod:`simfab.deploy.springs`); an arc the Bezier family cannot make long enough is a zigzag
  instead (:func:`zigzag_springs`), and a quad where no zigzag fits takes one pull per arc
  (:func:`simfab.deploy.springs.size_arcs`); a quad whose neighbouring edges are nearly collinear
  (an interior angle > ``degenerate_angle_deg``, boundary quads only) gets no spring;
- at every **interior** quad vertex (four quads around it) the four beams stop short of a
  gap of half-size ``g_i`` that receives a rigid insert of half-size ``r_i`` from the insert
  catalogue (``insert_half_sizes``; one size: ``insert_half_size``); the insert clamps the beam
  ends at distance ``r_i`` from the vertex. Boundary vertices join their beams rigidly (no insert),
  except along the seams of a cut flattening (``seams``, :mod:`simfab.deploy.cuts`; the outline
  nearer a seam than the rim), where u != 0: there the cells grow as inside, so those vertices
  get inserts too (2 or 3 beams) where their shortest edge leaves room for a gap and an insert
  comes nearer their growth than a rigid joint (not at a seam's rim end, u = 0). A pattern vertex
  on a cone tip (``cone_tips``) is a seam vertex whose growth is the half-edge integral
  (:func:`cone_tip_growth`): u = 0 at the cone itself, but its first ring shrank.

Gap rule (derivation). The flattening scales lengths by ``e^u``: a curve of length ``L`` on the
target has length ``e^u L`` in the flat domain (u varies slowly over a cell). Deployment must
give back the target lengths, so around vertex i each half-edge of flat length h/2 must
become ``(h/2) e^{-u_i}`` long. The beams are (nearly) inextensible; the only length that
changes at vertex i is the gap: the beam end moves from distance g_i (cut) to r (insert),
which lengthens each half-edge by ``r - g_i``. Hence

    r - g_i = (h_i / 2) (e^{-u_i} - 1)      =>      g_i = r - (h_i / 2) (e^{-u_i} - 1),

with h_i the mean flat length of the edges at i. u < 0 (the flattening shrank a positively
curved region): g < r, the insert pushes the beams apart and the grown metric buckles into a
dome; u > 0 (negative curvature): g > r, the insert pulls them together, a saddle. Since the
metric error is removed edge by edge, the deployed metric approximates the target's to first
order in the cell size; the shape follows where the network is stiff enough in bending to pick
the target among its isometric embeddings (hence the out-of-plane branch selection in
:mod:`simfab.deploy.network`).

Achievable gaps: ``min_gap <= g <= h_i/2 - min_beam`` (a gap must exist to be cut, and each
half beam needs ``min_beam`` of length to carry its spring junction). Vertices outside are
clamped to the range and reported as unreachable (with the gap they would need).

Insert catalogue. The growth a vertex needs, ``d_i = r_i - g_i = (h_i/2)(e^{-u_i} - 1)``, does
not depend on the insert; the insert size only shifts the gap. So with a short list of sizes
(what a maker can produce) each insert takes a size whose gap ``g = r - d_i`` is achievable -
of those, the one whose gap is nearest the middle of the achievable range (most margin for cut
tolerances either way); where no size reaches, the one with the smallest shortfall, and the
vertex is reported unreachable. The sizes are classes A, B, ... in increasing size (engraved
next to the insert numbers; bill of materials: :meth:`Pattern.bill_of_materials`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
import shapely
from scipy.sparse.csgraph import connected_components

from simfab.deploy._config import require_positive
from simfab.deploy.springs import bezier, size_arcs, size_bulges, size_zigzag, zigzag_layout, zigzag_points
from simfab.errors import InputError


@dataclass(frozen=True, kw_only=True)
class PatternConfig:
    """Pattern parameters (scene ``[pattern]`` table). Lengths [m].

    spacing: grid spacing h; beam_width (in plane) and beam_thickness (sheet); insert_half_size
    r: distance from an insert's centre to where it clamps the beams (one size for all
    inserts); insert_half_sizes: the insert catalogue, a list of such sizes (when given it
    replaces insert_half_size; each insert gets one, see module doc); layout: "grid" (the
    clipped square grid), "conforming" (:func:`conforming_quads`) or "mesh" (:func:`mesh_quads`:
    quads that follow any outline, the seams of a cut flattening included); spring_bulge [-]: smallest
    Bezier handle pull towards the quad centre; spring_slack [-]: arc length margin over the
    deployed chord (see :mod:`simfab.deploy.springs`); spring_width: in-plane width of the spring
    arcs (narrower than the beams: the springs let the cells grow in plane); min_gap, min_beam:
    achievable-gap limits (see module doc); degenerate_angle_deg [deg]: interior angle above
    which a boundary quad gets no spring; springs: "zigzag" (an arc the Bezier family cannot make
    long enough becomes a zigzag, :func:`zigzag_springs`; a quad where no zigzag fits either takes
    one pull per arc, :func:`simfab.deploy.springs.size_arcs`) or "bezier" (Bezier arcs at one pull
    per quad only, those short of the slack reported); growth_fit: "vertex" (each insert's growth
    from its own u and mean edge length, the gap rule of the module doc) or "edges" (the growths fitted to every
    edge's own length and u, :func:`edge_fitted_growth`: for meshes whose edges differ in length);
    conforming_core: "smoothed" (the conforming layout's core outline Laplacian-smoothed) or
    "regular" (left on the grid: every core edge h long, as the vertex gap rule assumes; the
    pillow's boundary vertices on the core outline's bisectors; :func:`conforming_quads`).
    """

    spacing: float = 0.025
    beam_width: float = 0.003
    beam_thickness: float = 0.001
    insert_half_size: float = 0.005
    insert_half_sizes: tuple = ()
    spring_bulge: float = 0.5
    spring_slack: float = 0.1
    spring_width: float = 0.0015
    min_gap: float = 0.0015
    min_beam: float = 0.004
    degenerate_angle_deg: float = 160.0
    layout: str = "grid"
    springs: str = "zigzag"
    growth_fit: str = "vertex"
    conforming_core: str = "smoothed"

    def __post_init__(self):
        if self.conforming_core not in ("regular", "smoothed"):
            raise InputError(f"must be 'regular' or 'smoothed' (got {self.conforming_core!r})",
                             where="pattern.conforming_core")
        if self.growth_fit not in ("edges", "vertex"):
            raise InputError(f"must be 'edges' or 'vertex' (got {self.growth_fit!r})", where="pattern.growth_fit")
        if self.layout not in ("conforming", "grid", "mesh"):
            raise InputError(f"must be 'conforming', 'grid' or 'mesh' (got {self.layout!r})", where="pattern.layout")
        if self.springs not in ("bezier", "zigzag"):
            raise InputError(f"must be 'bezier' or 'zigzag' (got {self.springs!r})", where="pattern.springs")
        if not isinstance(self.insert_half_sizes, (tuple, list)):
            raise InputError(f"must be a list of sizes [m] (got {self.insert_half_sizes!r})",
                             where="pattern.insert_half_sizes")
        object.__setattr__(self, "insert_half_sizes", tuple(self.insert_half_sizes))
        require_positive(self, "pattern.")
        field = "insert_half_sizes" if self.insert_half_sizes else "insert_half_size"
        if len(set(self.sizes)) != len(self.sizes):
            raise InputError(f"sizes must differ (got {list(self.insert_half_sizes)})", where=f"pattern.{field}")
        if not max(self.sizes) + self.beam_width < self.spacing / 2:
            raise InputError(f"insert size {max(self.sizes)} m: two neighbouring insert plates (half-side r + "
                             f"beam_width) would overlap at spacing {self.spacing} m (needs r < spacing/2 - "
                             f"beam_width)", where=f"pattern.{field}")

    @property
    def sizes(self) -> tuple:
        """The insert catalogue [m], increasing (``insert_half_sizes``, or the one ``insert_half_size``)."""
        return tuple(sorted(self.insert_half_sizes)) if self.insert_half_sizes else (self.insert_half_size,)


@dataclass(frozen=True)
class Pattern:
    """A flat pattern (arrays index the quad-mesh vertices, edges and quads).

    P (n,2) [m]: quad vertices; quads (q,4) CCW; edges (e,2); edge_quads (e,2) (-1: none);
    interior (n,) bool (insert vertices); u (n,) [-]: flattening log scale factor at the
    vertices; gap (n,) [m]: gap half-size (0 on boundary vertices); gap_required (n,) [m]
    (before clamping); unreachable (k,) vertex indices; spring (q,) bool; insert_ids (n,) int
    (label number, -1 on the boundary); insert_size (n,) [m]: each insert's half-size r_i (0 on
    the boundary); insert_class (n,) int: its index in ``config.sizes`` (-1 on the boundary);
    bulge (q,4) [-]: spring handle pull per arc (one per quad, or per arc where a quad needs it:
    :func:`simfab.deploy.springs.size_arcs`); growth (q,4) [-]: the growth of its four spring
    arcs' chords in deployment (:func:`quad_growth`; about e^{-u} in a regular cell);
    spring_ratio (q,4) [-]: the arcs' length/chord ratios; spring_legs (q,4) int: legs of each arc's zigzag (0: a
    Bezier arc), spring_amplitude (q,4) [-]: the zigzag's leg height fraction; tight_springs (k,) quads whose arcs
    cannot get the slack (see :mod:`simfab.deploy.springs`); config.
    """

    P: np.ndarray
    quads: np.ndarray
    edges: np.ndarray
    edge_quads: np.ndarray
    interior: np.ndarray
    u: np.ndarray
    gap: np.ndarray
    gap_required: np.ndarray
    unreachable: np.ndarray
    spring: np.ndarray
    insert_ids: np.ndarray
    insert_size: np.ndarray
    insert_class: np.ndarray
    bulge: np.ndarray
    growth: np.ndarray
    spring_ratio: np.ndarray
    spring_legs: np.ndarray
    spring_amplitude: np.ndarray
    tight_springs: np.ndarray
    config: PatternConfig
    gap_max: np.ndarray | None = None  # (n,) [m] largest gap the tuning may cut (see layout)
    cone_tip: np.ndarray | None = None  # (n,) bool: the vertex sits on a cone tip of a cut flattening

    @property
    def n_inserts(self) -> int:
        return int(np.sum(self.interior))

    def class_label(self, v: int) -> str:
        """Size-class letter (A = smallest) of the insert at vertex v ('' with a one-size catalogue)."""
        return CLASS_LETTERS[int(self.insert_class[v])] if len(self.config.sizes) > 1 else ""

    def bill_of_materials(self) -> list[dict]:
        """Per catalogue size: class letter, half-size r [mm], plate side 2 (r + beam_width) [mm]
        (the insert part as cut), count and the insert numbers."""
        out = []
        for k, r in enumerate(self.config.sizes):
            vs = np.flatnonzero(self.interior & (self.insert_class == k))
            out.append(dict(size_class=CLASS_LETTERS[k], half_size_mm=r * 1e3,
                            plate_side_mm=2e3 * (r + self.config.beam_width), count=int(len(vs)),
                            inserts=sorted(int(self.insert_ids[v]) for v in vs)))
        return out

    def midpoints(self) -> np.ndarray:
        """(e,2) edge midpoints [m] (junction positions)."""
        return 0.5 * (self.P[self.edges[:, 0]] + self.P[self.edges[:, 1]])

    def beam_halves(self) -> list[tuple[int, int, np.ndarray, np.ndarray]]:
        """Per edge and end: (edge, vertex, start = midpoint (2,), end = beam end at the vertex (2,))."""
        out = []
        mids = self.midpoints()
        for e, (a, b) in enumerate(self.edges):
            for v, o in ((a, b), (b, a)):
                d = self.P[o] - self.P[v]
                d /= np.linalg.norm(d)
                out.append((e, int(v), mids[e], self.P[v] + self.gap[v] * d))
        return out

    def spring_curves(self, n=12) -> list[tuple[int, int, int, np.ndarray]]:
        """Per spring arc: (quad, edge from, edge to, points (k,2) [m]) as cut: a Bezier arc at n+1
        uniform parameters, a zigzag as its drawn polyline (:func:`simfab.deploy.springs.zigzag_points`)."""
        return [(q, e0, e1, self._zigzag(q, k, e0, e1, rod=False) if self.spring_legs[q, k] else
                 bezier(*self._arc_ends(q, e0, e1), float(self.bulge[q, k]), n))
                for q, k, e0, e1 in self._arcs()]

    def spring_rods(self, params: np.ndarray) -> list[tuple[int, int, int, np.ndarray]]:
        """Per spring arc: (quad, edge from, edge to, rod nodes (k,2) [m]): a Bezier arc at the
        parameters ``params`` (in [0, 1]), a zigzag at its own nodes (``ZIGZAG_SEGMENTS`` per piece)."""
        return [(q, e0, e1, self._zigzag(q, k, e0, e1, rod=True) if self.spring_legs[q, k] else
                 bezier(*self._arc_ends(q, e0, e1), float(self.bulge[q, k]), params))
                for q, k, e0, e1 in self._arcs()]

    def _arcs(self):
        """(quad, arc k, edge from, edge to) of every spring arc, arc k joining edges k and k+1."""
        ekey = {tuple(sorted(e)): i for i, e in enumerate(self.edges.tolist())}
        out = []
        for q, quad in enumerate(self.quads):
            if not self.spring[q]:
                continue
            es = [ekey[tuple(sorted((int(quad[k]), int(quad[(k + 1) % 4]))))] for k in range(4)]
            out += [(q, k, es[k], es[(k + 1) % 4]) for k in range(4)]
        return out

    def _arc_ends(self, q, e0, e1):
        mids = 0.5 * (self.P[self.edges[[e0, e1], 0]] + self.P[self.edges[[e0, e1], 1]])
        return mids[0], mids[1], self.P[self.quads[q]].mean(axis=0)

    def _zigzag(self, q, k, e0, e1, *, rod: bool) -> np.ndarray:
        lay = zigzag_layout(*self._arc_ends(q, e0, e1), int(self.spring_legs[q, k]),
                            float(self.spring_amplitude[q, k]), self.config.spring_width)
        return zigzag_points(lay[0], rod=rod)


CLASS_LETTERS = "ABCDEFGHIJKLMNOPQRSTUVWXYZ"


def assign_sizes(d: np.ndarray, gmax: np.ndarray, sizes, min_gap: float) -> np.ndarray:
    """Catalogue index (k,) per insert (see module doc): d (k,) [m] the growth r - g each needs,
    gmax (k,) [m] its largest achievable gap, sizes (s,) [m] the catalogue; the achievable gap
    nearest the middle of [min_gap, gmax], else the smallest shortfall."""
    r = np.asarray(sizes, dtype=np.float64)[None, :]
    g = r - np.asarray(d)[:, None]  # (k, s) gap each size would need
    hi = np.asarray(gmax)[:, None]
    short = np.maximum(min_gap - g, 0.0) + np.maximum(g - hi, 0.0)
    off_middle = np.abs(g - 0.5 * (min_gap + hi))
    least = short <= short.min(axis=1, keepdims=True) + 1e-12  # all achievable ones (shortfall 0), if any
    return np.argmin(np.where(least, off_middle, np.inf), axis=1)


def gap_rule(u: np.ndarray, h: np.ndarray, r: float) -> np.ndarray:
    """Gap half-size g = r - (h/2)(e^{-u} - 1) [m] for log scale factors u (n,) [-] and mean flat
    edge lengths h (n,) [m] (see module doc)."""
    return r - 0.5 * h * np.expm1(-np.asarray(u, dtype=np.float64))


#: weight of the edges' growth differences against their sums in :func:`edge_fitted_growth`
GROWTH_FIT_DIFFERENCE = 0.3


def edge_fitted_growth(P: np.ndarray, edges: np.ndarray, u: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Insert growths d (n,) [m] fitted to the edges (``growth_fit = "edges"``): P (n,2) [m] the
    vertices, edges (e,2), u (n,) [-] the log scale factor at the vertices, free (n,) bool the
    vertices with an insert (the others join their beams rigidly: d = 0).

    Deployment lengthens edge (a, b) of flat length L_e by d_a + d_b (its two beam ends move by
    the inserts' growths); the target asks for G_e = (L_e/2)(e^{-u_a} + e^{-u_b} - 2) (the
    trapezoid rule of e^{-u} along it), and each end's share differs by
    D_e = (L_e/2)(e^{-u_a} - e^{-u_b}). Least squares in relative terms,

        min_d  sum_e ((d_a + d_b - G_e) / L_e)^2 + mu^2 sum_{e: a, b free} ((d_a - d_b - D_e) / L_e)^2,

    mu = :data:`GROWTH_FIT_DIFFERENCE`: the sums carry the metric; the differences, weaker, remove
    the null direction of the sums on a bipartite quad mesh (alternating +t / -t on its two vertex
    classes). On a uniform grid d = (h/2)(e^{-u} - 1), the vertex rule, zeroes every residual;
    where edges differ in length (a smoothed pillow layer, an unstructured mesh) the edges' sums
    are matched instead of each vertex's mean edge length's growth."""

    n = len(P)
    a, b = edges[:, 0], edges[:, 1]
    L = np.linalg.norm(P[a] - P[b], axis=1)
    ea, eb = np.exp(-u[a]), np.exp(-u[b])
    G, D = 0.5 * L * (ea + eb - 2.0), 0.5 * L * (ea - eb)
    idx = np.flatnonzero(free)
    col = np.full(n, -1)
    col[idx] = np.arange(len(idx))
    both = np.flatnonzero(free[a] & free[b])
    rows, cols, vals = [], [], []
    for end in (a, b):  # the sums: d_a + d_b
        m = np.flatnonzero(free[end])
        rows.append(m)
        cols.append(col[end[m]])
        vals.append(1.0 / L[m])
    for end, sign in ((a, 1.0), (b, -1.0)):  # the differences: d_a - d_b
        rows.append(len(edges) + np.arange(len(both)))
        cols.append(col[end[both]])
        vals.append(sign * GROWTH_FIT_DIFFERENCE / L[both])
    A = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(len(edges) + len(both), len(idx)))
    rhs = np.concatenate([G / L, GROWTH_FIT_DIFFERENCE * D[both] / L[both]])
    d = np.zeros(n)
    d[idx] = spla.spsolve((A.T @ A).tocsc(), A.T @ rhs)
    return d


#: most pattern cells (domain area / spacing^2) a layout accepts: the deployment's and the tuning's cost
#: (dense normal equations over the inserts) grow with them
MAX_CELLS = 4000


def check_cell_count(area: float, h: float, *, what: str = "the target") -> None:
    """Refuse a spacing that would lay more than :data:`MAX_CELLS` cells on ``area``.

    Args:
        area: the surface's (or flat domain's) area [m^2].
        h: the pattern spacing [m].
        what: what the area is, for the message.

    Raises:
        InputError: naming ``pattern.spacing``.
    """
    cells = area / h**2
    if not cells <= MAX_CELLS:
        raise InputError(f"{cells:.3g} cells of {h:.4g} m on {what} ({area:.4g} m^2): more than {MAX_CELLS}; "
                         f"make the spacing at least {np.sqrt(area / MAX_CELLS):.3g} m (or check the target's units)",
                         where="pattern.spacing")


def layout(uv: np.ndarray, boundary: np.ndarray, faces: np.ndarray, u: np.ndarray, cfg: PatternConfig, *,
           seams=(), cone_tips=()) -> Pattern:
    """Lay the pattern out on a flattening (uv (n,2) [m], ordered boundary loop, faces, u (n,)).
    ``seams``: flat polylines [(k,2) m] of the cut sides of a cut flattening (their boundary
    vertices get inserts); ``cone_tips`` (c,2) [m]: the cones' flat positions (a pattern vertex
    there takes its growth from :func:`cone_tip_growth`). ``Pattern.gap_max``: the largest gap the
    tuning may cut (:func:`tuning_gap_limit`). ``layout = "mesh"``: the pattern of the best of the
    :data:`MESH_RECIPES` meshings (fewest :func:`defects`, then the largest covered area)."""

    poly = shapely.Polygon(uv[boundary])
    if not poly.is_valid:
        raise InputError("the flattened boundary self-intersects; the target needs cuts or cones")
    h = cfg.spacing
    check_cell_count(poly.area, h, what="the flat domain")
    if cfg.layout == "grid":
        meshes = [_clipped_grid(poly, uv, h)]
    elif cfg.layout == "mesh":
        meshes = [m for m in (mesh_quads(poly, h, r) for r in MESH_RECIPES) if m is not None]
        if not meshes:
            raise InputError(f"no quad mesh fits the flat domain at spacing {h} m (make pattern.spacing smaller)",
                             where="pattern.spacing")
    else:
        sweeps = SMOOTHING_ITERATIONS if cfg.conforming_core == "smoothed" else 0
        meshes = [conforming_quads(poly, h, uv, sweeps=sweeps)]
    best, best_key = None, None
    for P, quads in meshes:
        pat = _pattern_on(poly, P, quads, uv, faces, u, cfg, seams, cone_tips)
        key = (defects(pat), -covered_fraction(pat, poly))
        if best_key is None or key < best_key:
            best, best_key = pat, key
    return best


def covered_fraction(pat: Pattern, poly) -> float:
    """The fraction [-] of the flat domain ``poly`` (a shapely Polygon) that the pattern's quads cover
    (their parts outside it not counted)."""

    return float(np.sum(shapely.area(shapely.intersection(shapely.polygons(pat.P[pat.quads]), poly))) / poly.area)


def defects(pat: Pattern) -> int:
    """Inserts whose gap is unreachable, quads short of spring slack and quads without a spring."""
    return int(len(pat.unreachable) + len(pat.tight_springs) + np.sum(~pat.spring))


def _pattern_on(poly, P, quads, uv, faces, u, cfg: PatternConfig, seams, cone_tips=()) -> Pattern:
    """The pattern (inserts, gaps, springs) on the quad mesh (P, quads) of the flat domain ``poly``."""
    h = cfg.spacing
    P, quads = drop_outside_quads(poly, P, quads)
    # edges and their quads
    e_all = np.concatenate([quads[:, [k, (k + 1) % 4]] for k in range(4)])
    q_all = np.tile(np.arange(len(quads)), 4)
    key = np.sort(e_all, axis=1)
    edges, inv_e = np.unique(key, axis=0, return_inverse=True)
    inv_e = inv_e.ravel()
    edge_quads = np.full((len(edges), 2), -1)
    for k, (e, q) in enumerate(zip(inv_e, q_all)):
        edge_quads[e, 0 if edge_quads[e, 0] < 0 else 1] = q
    bnd_v = np.zeros(len(P), dtype=bool)
    bnd_v[edges[edge_quads[:, 1] < 0].ravel()] = True
    valence = np.bincount(edges.ravel(), minlength=len(P))
    # u at the pattern vertices: linear interpolation on the flat triangulation
    uP = interpolate(uv, faces, u, P)
    elen = np.linalg.norm(P[edges[:, 0]] - P[edges[:, 1]], axis=1)
    hv = np.bincount(edges.ravel(), weights=np.repeat(elen, 2), minlength=len(P)) / np.maximum(valence, 1)
    gmax = 0.5 * hv - cfg.min_beam
    # every vertex inside the outline holds an insert (4 beams; 3 or 5 at staircase corners), and so
    # does a boundary vertex along a seam (u != 0 there: its cell must grow too, simfab.deploy.cuts) whose
    # shortest edge leaves room for a gap (its gap limit is set by that edge: clipped cells are short)
    emin = np.full(len(P), np.inf)
    np.minimum.at(emin, edges.ravel(), np.repeat(elen, 2))
    seam = bnd_v & near_seams(P, poly, seams, h) & (0.5 * emin - cfg.min_beam >= cfg.min_gap)
    gmax = np.where(seam, 0.5 * emin - cfg.min_beam, gmax)
    need = gap_rule(uP, hv, 0.0)  # -d: the gap with r = 0
    if cfg.growth_fit == "edges":
        need = -edge_fitted_growth(P, edges, uP, ~bnd_v | seam)
    tip = np.zeros(len(P), dtype=bool)
    if len(cone_tips):
        near = np.min(np.linalg.norm(P[:, None] - np.asarray(cone_tips)[None], axis=2), axis=1)
        tip = bnd_v & (near < SEAM_TOL * h)
        for v in np.flatnonzero(tip & seam):
            need[v] = -cone_tip_growth(P, edges, v, uv, faces, u)
    # a seam vertex that needs less growth |d| than its best insert falls short by is joined rigidly
    # (growth 0: the nearer one; a seam's rim end, where u = 0)
    if seam.any():
        k = assign_sizes(-need[seam], gmax[seam], cfg.sizes, cfg.min_gap)
        g = np.asarray(cfg.sizes)[k] + need[seam]
        short = np.maximum(cfg.min_gap - g, 0.0) + np.maximum(g - gmax[seam], 0.0)
        seam[np.flatnonzero(seam)[np.abs(need[seam]) <= short]] = False
    interior = ~bnd_v | seam
    cls = np.full(len(P), -1)
    cls[interior] = assign_sizes(-need[interior], gmax[interior], cfg.sizes, cfg.min_gap)
    r_v = np.where(interior, np.asarray(cfg.sizes)[np.maximum(cls, 0)], 0.0)
    req = np.where(interior, r_v + need, 0.0)
    unreachable = np.flatnonzero(interior & ((req < cfg.min_gap) | (req > gmax)))
    gap = np.where(interior, np.clip(req, cfg.min_gap, gmax), 0.0)
    # springs: none in quads with nearly collinear neighbouring edges
    spring = np.array([_max_angle(P[q]) < np.radians(cfg.degenerate_angle_deg) for q in quads])
    growth = quad_growth(P, quads, r_v - gap)
    qmids = 0.5 * (P[quads] + P[np.roll(quads, -1, axis=1)])  # (q,4,2) midpoint of edge (v_k, v_k+1)
    bulge, ratio, tight = size_bulges(P, quads, qmids, growth, bulge_min=cfg.spring_bulge, slack=cfg.spring_slack,
                                      width=cfg.spring_width)
    legs, amp = np.zeros((len(quads), 4), dtype=np.int64), np.zeros((len(quads), 4))
    if cfg.springs == "zigzag":
        legs, amp, ratio, tight = zigzag_springs(P, quads, qmids, growth, ratio, tight & spring, cfg)
    bulge = np.repeat(bulge[:, None], 4, axis=1)
    # all Bezier and still short (no zigzag fits): per-arc pulls; ``springs = "bezier"`` keeps one pull per quad
    short = np.flatnonzero(tight & spring & ~np.any(legs > 0, axis=1)) if cfg.springs == "zigzag" else []
    if len(short):
        need_s = (1.0 + cfg.spring_slack) * np.maximum(growth[short], 1.0)
        bulge[short], ratio[short] = size_arcs(qmids[short], np.roll(qmids[short], -1, axis=1),
                                               P[quads[short]].mean(axis=1)[:, None, :], need_s, bulge[short, 0],
                                               bulge_min=cfg.spring_bulge, width=cfg.spring_width)
        tight[short] = np.any(ratio[short] < need_s - 1e-9, axis=1)
    ids = np.full(len(P), -1)
    order = np.flatnonzero(interior)
    order = order[np.lexsort((P[order, 0], -P[order, 1]))]  # row by row from the top, left to right
    ids[order] = np.arange(1, len(order) + 1)
    return Pattern(P=P, quads=quads, edges=edges, edge_quads=edge_quads, interior=interior, u=uP, gap=gap,
                   gap_required=req, unreachable=unreachable, spring=spring, insert_ids=ids, insert_size=r_v,
                   insert_class=cls, bulge=bulge, growth=growth, spring_ratio=ratio, spring_legs=legs,
                   spring_amplitude=amp, tight_springs=np.flatnonzero(tight & spring), config=cfg,
                   gap_max=np.where(interior, tuning_gap_limit(gmax, emin, gap, cfg.min_beam, bool(len(seams))), 0.0),
                   cone_tip=tip)


#: Gauss-Legendre points per half edge of :func:`cone_tip_growth`
TIP_QUADRATURE = 8


def cone_tip_growth(P: np.ndarray, edges: np.ndarray, v: int, uv, faces, u) -> float:
    """Growth d [m] of the insert at a cone tip v: the mean over its edges of the half edge's
    growth in deployment,

        d = mean_e  int_0^{L_e/2} (e^{-u(s)} - 1) ds      (s from the tip along edge e),

    u interpolated on the flat triangulation (uv, faces, u), Gauss-Legendre with
    :data:`TIP_QUADRATURE` points. The gap rule's endpoint value (h/2)(e^{-u_v} - 1) is 0 there (u = 0
    at a cone, :mod:`simfab.deploy.cuts`) while the first ring around the cone shrank: the cone
    metric's u is singular at a cone (its vertex value 0 is the discrete convention), so the
    endpoint rule misses the whole half edge."""
    es = edges[np.any(edges == v, axis=1)]
    other = es.sum(axis=1) - v
    x, w = np.polynomial.legendre.leggauss(TIP_QUADRATURE)
    s = 0.25 * (x + 1.0)  # [0, 1/2] of each edge
    pts = P[v] + s[None, :, None] * (P[other] - P[v])[:, None, :]  # (k, q, 2)
    uq = interpolate(uv, faces, u, pts.reshape(-1, 2)).reshape(len(other), -1)
    L = np.linalg.norm(P[other] - P[v], axis=1)
    return float(np.mean(0.25 * L * (np.expm1(-uq) @ w)))


def zigzag_springs(P, quads, qmids, growth, ratio, tight, cfg: PatternConfig):
    """Zigzag springs where a Bezier arc cannot get the slack: each arc of a ``tight`` quad (q,)
    bool short of S/c >= (1 + spring_slack) max(growth, 1) becomes the shortest zigzag that reaches
    it (:func:`simfab.deploy.springs.size_zigzag`), or the longest one that fits where that is
    longer than the Bezier arc. The zigzag stays ``spring_width`` inside its triangle (edge
    midpoints and quad centre); the quad's Bezier arcs keep ``spring_width`` from the centre (their
    sizing), which they approach only near the triangles' shared apex. Returns legs (q,4)
    int (0: Bezier), amplitude (q,4), S/c (q,4) and the quads still short of the slack (q,) bool."""
    legs, amp = np.zeros((len(quads), 4), dtype=np.int64), np.zeros((len(quads), 4))
    ratio, tight = ratio.copy(), tight.copy()
    need = (1.0 + cfg.spring_slack) * np.maximum(growth, 1.0)
    c = P[quads].mean(axis=1)
    for q in np.flatnonzero(tight):
        for k in np.flatnonzero(ratio[q] < need[q] - 1e-9):
            n, a, r = size_zigzag(qmids[q, k], qmids[q, (k + 1) % 4], c[q], need[q, k], cfg.spring_width)
            if n and r > ratio[q, k]:
                legs[q, k], amp[q, k], ratio[q, k] = n, a, r
        tight[q] = bool(np.any(ratio[q] < need[q] - 1e-9))
    return legs, amp, ratio, tight


def tuning_gap_limit(gmax, emin, gap, min_beam: float, cut: bool) -> np.ndarray:
    """(n,) [m] the largest gap the tuning may cut (``Pattern.gap_max``): the achievable limit
    ``gmax``; on a cut pattern (``cut``: the wedges leave short clipped edges next to inserts) also
    at most half the vertex's shortest edge ``emin`` less ``min_beam``, or the gap the layout cut
    (a beam half would otherwise shrink to zero length, measured on the petal)."""
    if not cut:
        return gmax
    return np.minimum(gmax, np.maximum(0.5 * emin - min_beam, gap))


SEAM_TOL = 1e-6  # [spacings] where the seams are cut out of the domain's outline to leave the rim


def near_seams(P: np.ndarray, poly, seams, h: float) -> np.ndarray:
    """(n,) bool: points P (n,2) [m] nearer to one of the seam polylines [(k,2)] than to the rim (the
    flat domain ``poly``'s outline without the seams; u = 0 there): the pattern's outline along a
    cut, on the seam or inside the domain where the grid dropped the cells a wedge crosses."""

    if not len(seams):
        return np.zeros(len(P), dtype=bool)
    lines = shapely.MultiLineString([np.asarray(s, dtype=np.float64) for s in seams])
    rim = shapely.difference(poly.exterior, shapely.buffer(lines, SEAM_TOL * h))
    pts = shapely.points(P)
    return shapely.distance(lines, pts) < shapely.distance(rim, pts)


OUTSIDE_AREA = 0.1  # a quad with more than this fraction of its area outside the flat domain is dropped


def drop_outside_quads(poly, P: np.ndarray, quads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop quads with more than ``OUTSIDE_AREA`` of their area outside the flat domain ``poly``
    (a grid cell whose corners lie on both sides of a cut's wedge, :mod:`simfab.deploy.cuts`, would
    bridge the seam), keep the largest edge-connected set: (P, quads) re-indexed. A no-op on a
    domain without notches (the cells' corners lie in it or on its boundary)."""

    cells = shapely.polygons(P[quads])
    out = shapely.area(shapely.difference(cells, poly)) > OUTSIDE_AREA * shapely.area(cells)
    if not out.any():
        return P, quads
    quads = _largest_component(quads[~out])
    used, inv = np.unique(quads, return_inverse=True)
    return P[used], inv.reshape(-1, 4)


def quad_growth(P: np.ndarray, quads: np.ndarray, d: np.ndarray) -> np.ndarray:
    """(q,4) [-] growth of the chords of each quad's four spring arcs, arc k around corner k+1 (the
    order of :meth:`Pattern.spring_curves`). The arc around corner
    v joins the midpoints of v's two edges, at distances a, b from v; deployment lengthens both
    half-edges by d_v (d (n,) [m] = r - g, 0 on the boundary), so with the corner angle alpha kept
    the chord grows from sqrt(a^2 + b^2 - 2ab cos alpha) to the same with a + d_v, b + d_v."""
    v = quads
    prev, nxt = np.roll(quads, 1, axis=1), np.roll(quads, -1, axis=1)
    A = 0.5 * (P[prev] - P[v])  # (q,4,2) corner -> midpoint of the edge to the previous corner
    B = 0.5 * (P[nxt] - P[v])
    a, b = np.linalg.norm(A, axis=2), np.linalg.norm(B, axis=2)
    cos = np.einsum("qki,qki->qk", A, B) / (a * b)
    chord = lambda x, y: np.sqrt(np.maximum(x * x + y * y - 2 * x * y * cos, 0.0))  # noqa: E731
    return np.roll(chord(a + d[v], b + d[v]) / chord(a, b), -1, axis=1)


def _good_quad(Q: np.ndarray, h: float) -> bool:
    d = np.roll(Q, -1, axis=0) - Q
    if np.min(np.linalg.norm(d, axis=1)) < 0.25 * h:
        return False
    cross = d[:, 0] * np.roll(d, -1, axis=0)[:, 1] - d[:, 1] * np.roll(d, -1, axis=0)[:, 0]
    area = 0.5 * np.sum(Q[:, 0] * np.roll(Q[:, 1], -1) - np.roll(Q[:, 0], -1) * Q[:, 1])
    return bool(np.all(cross > -1e-12 * h * h) and area > 0.2 * h * h)


def _max_angle(Q: np.ndarray) -> float:
    """Largest interior angle [rad] of a convex quad (4,2)."""
    out = 0.0
    for k in range(4):
        a, b = Q[k - 1] - Q[k], Q[(k + 1) % 4] - Q[k]
        out = max(out, float(np.arccos(np.clip(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)), -1, 1))))
    return out


def _largest_component(quads: np.ndarray) -> np.ndarray:

    e = np.sort(np.concatenate([quads[:, [k, (k + 1) % 4]] for k in range(4)]), axis=1)
    q = np.tile(np.arange(len(quads)), 4)
    _, inv = np.unique(e, axis=0, return_inverse=True)
    inv = inv.ravel()
    M = sp.coo_matrix((np.ones(len(q)), (q, inv)), shape=(len(quads), inv.max() + 1)).tocsr()
    n, lab = connected_components(M @ M.T, directed=False)
    return quads[lab == np.argmax(np.bincount(lab))]


def interpolate(uv, faces, values, P) -> np.ndarray:
    """Piecewise-linear interpolation of per-vertex ``values`` (n,) or (n,k) on the flat triangulation
    at P (m,2); points outside (a conforming layout's boundary vertices, up to ~ a sagitta off the
    boundary) take the value at their nearest point of the triangulation's boundary edges (linear
    along the edge): the field extended constant along the boundary's normal."""
    import matplotlib.tri as mtri

    vals = np.asarray(values, dtype=np.float64)
    V = vals.reshape(len(uv), -1)
    tri = mtri.Triangulation(uv[:, 0], uv[:, 1], faces)
    f = tri.get_trifinder()(P[:, 0], P[:, 1])
    out = np.empty((len(P), V.shape[1]))
    ins = f >= 0
    if ins.any():  # barycentric coordinates in the containing triangle
        T = uv[faces[f[ins]]]  # (k,3,2)
        A = np.stack([T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]], axis=2)  # (k,2,2)
        lam = np.linalg.solve(A, (P[ins] - T[:, 0])[:, :, None])[:, :, 0]
        w = np.column_stack([1.0 - lam.sum(axis=1), lam])
        out[ins] = np.einsum("kj,kjc->kc", w, V[faces[f[ins]]])
    if (~ins).any():
        e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
        ue, cnt = np.unique(e, axis=0, return_counts=True)
        be = ue[cnt == 1]  # boundary edges
        a, d = uv[be[:, 0]], uv[be[:, 1]] - uv[be[:, 0]]
        X = P[~ins][:, None, :]
        t = np.clip(np.einsum("mbi,bi->mb", X - a, d) / np.einsum("bi,bi->b", d, d), 0.0, 1.0)
        dist = np.linalg.norm(a + t[:, :, None] * d - X, axis=2)
        j = np.argmin(dist, axis=1)
        tj = t[np.arange(len(j)), j][:, None]
        out[~ins] = (1.0 - tj) * V[be[j, 0]] + tj * V[be[j, 1]]
    return out.reshape((len(P),) + vals.shape[1:])


def map_to_surface(uv, faces, V, P) -> np.ndarray:
    """3D target points (k,3) [m] of flat points P (k,2): barycentric on the flat triangulation."""
    return interpolate(uv, faces, V, P)


def _clipped_grid(poly, uv, h):
    """The clipped square grid (``layout = "grid"``): (P (n,2), quads (q,4) CCW)."""

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
    quads = _largest_component(quads)
    used, inv = np.unique(quads, return_inverse=True)
    quads = inv.reshape(-1, 4)
    P = proj.reshape(-1, 2)[used]
    return P, quads


MESH_CORNER_DEG = 25.0  # outline vertices turning by more than this are corners of the mesh's boundary curves


@dataclass(frozen=True, kw_only=True)
class MeshRecipe:
    """One quad meshing of the flat domain (:func:`mesh_quads`). full_quad: True - a triangulation
    of edge 2 ``size`` h, its triangles paired into quads (a maximum-weight matching, the quads'
    squareness the weight), then every quad split into 4 and every unpaired triangle into 3 (edge ~h,
    no triangle left, inserts with 3-6 beams); False - a triangulation of edge ``size`` h whose
    triangles are all paired into quads (a perfect matching; None when none exists: an odd number
    of outline edges, or the triangles' adjacency has none); size [spacings]; uniform_outline: each
    outline curve (between corners) divided into round(L / h) equal edges (at least one; one curve
    gets one more when a perfect matching needs an even total) - the two sides of a seam, of equal
    flat length, then get facing vertices. lattice: the interior seeded with a square lattice of the
    triangulation's edge centred on the domain (its triangles pair back into squares: a regular core,
    split into h squares when full_quad), its points at least ``margin`` edges from the outline;
    False: Triangle's own quality refinement places them."""

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
    """Boundary-conforming quad mesh of the flat domain ``poly`` (``layout = "conforming"``):
    (P (n,2) [m], quads (q,4) CCW).

    Method (a square grid with one *pillow* layer, as in hexahedral meshing): the core is the
    grid cells (spacing h, on the grid through the origin) whose four corners lie inside the
    domain at least ``CORE_MARGIN`` h from its boundary (the largest edge-connected set, cells that
    touch the rest at one corner only removed, so its outline is one simple loop v_0 .. v_m).
    Every loop vertex gets a boundary vertex p_k (its nearest boundary point, then spread along
    the boundary by arc length so that their order follows the loop's), and every loop edge
    (v_k, v_k+1) one quad (v_k, p_k, p_k+1, v_k+1): each pillow quad has exactly two vertices on
    the boundary, so no quad degenerates into a triangle with three boundary vertices on a line
    (what clipping a grid cell does where the boundary runs across it). Then Laplacian smoothing of
    the core's outline vertices (``sweeps`` Jacobi sweeps, boundary vertices fixed; the uniform
    grid is its fixed point, so only the cells near the boundary move). Smoothing lifts the pillow
    quads' angles at the staircase corners below ``degenerate_angle_deg``, but moves the outline
    vertices off the grid: the vertex gap rule, which gives all of an insert's beams one growth
    from their mean edge length, then over- and under-grows its unequal edges (docs/decisions.md:
    the dome). ``sweeps = 0`` keeps the core on the grid and puts each p_k where the outward
    bisector of its loop vertex meets the boundary instead (:func:`_bisector_positions`, not
    relaxed along it): at a convex staircase corner the nearest point would continue one of the
    core's edges, a straight angle in its pillow quad. The chord
    polygon of the p_k on the boundary would leave out the segments between the chords and the
    boundary (sagitta s ~ h^2 / (8 R) for a boundary of curvature radius R, ~1.2 % of the bundled
    targets' area); the p_k are moved off the boundary so that every chord's segment is balanced
    (:func:`_area_preserving`): the outline crosses the boundary, and what it leaves out is
    (4/9) s a per chord (a: the half length over which the boundary lies outside it; 0.128 s L for a
    circular arc instead of 2/3 s L), matched by as much outside. Staircase corners of
    the core give loop vertices of valence 3 (convex) or 5 (concave) - inserts with 3 or 5 beams.
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
    quads = _largest_component(np.array(cells))
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
            return _largest_component(quads)
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
