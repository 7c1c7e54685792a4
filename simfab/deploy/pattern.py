"""The flat pattern on a flattened target: beams, inserts, torsional springs, the gap rule.

On a quad mesh of the flat domain (:mod:`simfab.deploy.quadmesh`, ``[pattern] layout``; metres):

- every quad edge is a **beam** (width ``w``, sheet thickness ``t``) split at its midpoint by a
  rigid junction;
- each quad gets a **torsional spring**: four cubic Bezier arcs joining consecutive edge midpoints,
  bulging towards the quad centre, long enough for the quad's growth in deployment
  (:mod:`simfab.deploy.springs`); a zigzag where no Bezier arc is (:func:`zigzag_springs`); none in
  a boundary quad with an interior angle above ``degenerate_angle_deg``;
- at every interior vertex the beams stop short of a gap of half-size g_i that receives a rigid
  insert of half-size r_i from the catalogue (``insert_half_sizes``); boundary vertices join their
  beams rigidly, except along the seams of a cut flattening (:mod:`simfab.deploy.cuts`) and at cone
  tips (:func:`cone_tip_growth`).

Gap rule: the flattening scales lengths by e^u, so each half edge (h_i/2) at vertex i must grow by
r - g_i in deployment:

    g_i = r - (h_i / 2) (e^{-u_i} - 1)      (:func:`gap_rule`; or fitted to the edges, :func:`edge_fitted_growth`)

u < 0 (positive curvature): g < r, the insert pushes (a dome); u > 0: g > r, it pulls (a saddle).
Achievable gaps: ``min_gap <= g <= h_i/2 - min_beam``; others are clamped and reported unreachable.
Each insert takes the catalogue size whose gap is nearest the middle of that range (:func:`assign_sizes`;
unused sizes leave the catalogue, :func:`used_sizes_only`). Derivation: docs/methods.md, "simfab.deploy.pattern".
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
import shapely

from simfab.deploy._config import require_positive
from simfab.deploy.quadmesh import LAYOUTS, largest_component, quad_meshes
from simfab.deploy.springs import bezier, size_arcs, size_bulges, size_zigzag, zigzag_layout, zigzag_points
from simfab.errors import InputError


@dataclass(frozen=True, kw_only=True)
class PatternConfig:
    """Pattern parameters (scene ``[pattern]`` table). Lengths [m].

    Args:
        spacing: grid spacing h [m] (``layout = "mesh"``: the target edge length).
        beam_width: in-plane beam width [m].
        beam_thickness: sheet thickness [m].
        insert_half_size: r, the distance from an insert's centre to where it clamps the beams [m]
            (one size for all inserts).
        insert_half_sizes: the insert catalogue, a list of such sizes [m] (when given it replaces
            ``insert_half_size``; each insert gets one, :func:`assign_sizes`).
        spring_bulge: smallest Bezier handle pull towards the quad centre [-].
        spring_slack: arc length margin over the deployed chord [-] (:mod:`simfab.deploy.springs`).
        spring_width: in-plane width of the spring arcs [m] (narrower than the beams: the springs let
            the cells grow in plane).
        min_gap: smallest gap that can be cut [m].
        min_beam: shortest half beam that carries its spring junction [m].
        degenerate_angle_deg: interior angle above which a boundary quad gets no spring [deg].
        layout: "grid", "conforming" or "mesh" (:func:`simfab.deploy.quadmesh.quad_meshes`).
        springs: "zigzag" (an arc the Bezier family cannot make long enough becomes a zigzag,
            :func:`zigzag_springs`; a quad where no zigzag fits takes one pull per arc) or "bezier"
            (Bezier arcs at one pull per quad only, those short of the slack reported).
        growth_fit: "vertex" (each insert's growth from its own u and mean edge length, :func:`gap_rule`)
            or "edges" (fitted to every edge's length and u, :func:`edge_fitted_growth`).
        conforming_core: "smoothed" (the conforming layout's core outline Laplacian-smoothed) or
            "regular" (left on the grid: every core edge h long, as the vertex gap rule assumes).
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
        if self.layout not in LAYOUTS:
            raise InputError(f"must be 'conforming', 'grid' or 'mesh' (got {self.layout!r})", where="pattern.layout")
        if self.springs not in ("bezier", "zigzag"):
            raise InputError(f"must be 'bezier' or 'zigzag' (got {self.springs!r})", where="pattern.springs")
        if not isinstance(self.insert_half_sizes, (tuple, list)):
            raise InputError(f"must be a list of sizes [m] (got {self.insert_half_sizes!r})",
                             where="pattern.insert_half_sizes")
        object.__setattr__(self, "insert_half_sizes", tuple(self.insert_half_sizes))
        require_positive(self, "pattern.")
        if len(set(self.sizes)) != len(self.sizes):
            raise InputError(f"sizes must differ (got {list(self.insert_half_sizes)})", where=self._sizes_key)

    @property
    def _sizes_key(self) -> str:
        """The scene key the insert sizes come from."""
        return "pattern.insert_half_sizes" if self.insert_half_sizes else "pattern.insert_half_size"

    def plates_fit(self) -> bool:
        """Whether the largest plates stay clear of their neighbours' at the spacing: half-side r +
        beam_width < spacing / 2."""
        return max(self.sizes) + self.beam_width < self.spacing / 2

    def check_plates(self) -> None:
        """Refuse a catalogue whose largest plates would overlap their neighbours' at the spacing (half-side
        r + beam_width >= spacing / 2). Checked where the catalogue is final (:func:`layout`, the scene's
        loader after its defaults are decided), not at construction: a scene that sets only the spacing gets
        its catalogue decided from the target, and the fixed default size need not fit that spacing.

        Raises:
            InputError: naming ``pattern.insert_half_size`` or ``pattern.insert_half_sizes``.
        """
        if not self.plates_fit():
            raise InputError(f"insert size {max(self.sizes)} m: two neighbouring insert plates (half-side r + "
                             f"beam_width) would overlap at spacing {self.spacing} m (needs r < spacing/2 - "
                             f"beam_width)", where=self._sizes_key)

    @property
    def sizes(self) -> tuple:
        """The insert catalogue [m], increasing (``insert_half_sizes``, or the one ``insert_half_size``)."""
        return tuple(sorted(self.insert_half_sizes)) if self.insert_half_sizes else (self.insert_half_size,)


@dataclass(frozen=True)
class Pattern:
    """A flat pattern (arrays index the quad-mesh vertices, edges and quads); built by :func:`layout`.

    Args:
        P: (n,2) [m] quad vertices.
        quads: (q,4) vertex ids, CCW.
        edges: (e,2) vertex ids.
        edge_quads: (e,2) the quads on either side of each edge (-1: none).
        interior: (n,) bool, the vertices with an insert.
        u: (n,) [-] the flattening's log scale factor at the vertices.
        gap: (n,) [m] gap half-size (0 on boundary vertices).
        gap_required: (n,) [m] the gap before clamping to the achievable range.
        unreachable: (k,) vertex ids whose required gap is outside the achievable range.
        spring: (q,) bool, the quads with a torsional spring.
        insert_ids: (n,) insert label numbers (-1 on the boundary).
        insert_size: (n,) [m] each insert's half-size r_i (0 on the boundary).
        insert_class: (n,) its index in ``config.sizes`` (-1 on the boundary).
        bulge: (q,4) [-] spring handle pull per arc (one per quad, or per arc where a quad needs it:
            :func:`simfab.deploy.springs.size_arcs`).
        growth: (q,4) [-] the growth of the four spring arcs' chords in deployment (:func:`quad_growth`;
            about e^{-u} in a regular cell).
        spring_ratio: (q,4) [-] the arcs' length / chord ratios.
        spring_legs: (q,4) legs of each arc's zigzag (0: a Bezier arc).
        spring_amplitude: (q,4) [-] the zigzag's leg height fraction.
        tight_springs: (k,) quads whose arcs cannot get the slack.
        config: the :class:`PatternConfig`.
        gap_max: (n,) [m] the largest gap the tuning may cut (:func:`tuning_gap_limit`).
        cone_tip: (n,) bool, the vertex sits on a cone tip of a cut flattening.
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
        """The number of inserts."""
        return int(np.sum(self.interior))

    def class_label(self, v: int) -> str:
        """Size-class letter of an insert.

        Args:
            v: the vertex id.

        Returns:
            "A" for the smallest catalogue size, "B", ...; "" with a one-size catalogue.
        """
        return CLASS_LETTERS[int(self.insert_class[v])] if len(self.config.sizes) > 1 else ""

    def bill_of_materials(self) -> list[dict]:
        """The inserts to make, per catalogue size.

        Returns:
            One dict per size: size_class (letter), half_size_mm, plate_side_mm (2 (r + beam_width), the
            insert part as cut), count and the insert numbers.
        """
        out = []
        for k, r in enumerate(self.config.sizes):
            vs = np.flatnonzero(self.interior & (self.insert_class == k))
            out.append(dict(size_class=CLASS_LETTERS[k], half_size_mm=r * 1e3,
                            plate_side_mm=2e3 * (r + self.config.beam_width), count=int(len(vs)),
                            inserts=sorted(int(self.insert_ids[v]) for v in vs)))
        return out

    def midpoints(self) -> np.ndarray:
        """Edge midpoints (the junction positions).

        Returns:
            (e,2) [m].
        """
        return 0.5 * (self.P[self.edges[:, 0]] + self.P[self.edges[:, 1]])

    def beam_halves(self) -> list[tuple[int, int, np.ndarray, np.ndarray]]:
        """Every half beam, from its edge's midpoint to its end at the vertex's gap.

        Returns:
            Per edge and end: (edge, vertex, start = midpoint (2,) [m], end = beam end at the vertex (2,) [m]).
        """
        out = []
        mids = self.midpoints()
        for e, (a, b) in enumerate(self.edges):
            for v, o in ((a, b), (b, a)):
                d = self.P[o] - self.P[v]
                d /= np.linalg.norm(d)
                out.append((e, int(v), mids[e], self.P[v] + self.gap[v] * d))
        return out

    def spring_curves(self, n=12) -> list[tuple[int, int, int, np.ndarray]]:
        """The spring arcs as cut.

        Args:
            n: segments of a Bezier arc (n + 1 uniform parameters).

        Returns:
            Per spring arc: (quad, edge from, edge to, points (k,2) [m]); a zigzag as its drawn polyline
            (:func:`simfab.deploy.springs.zigzag_points`).
        """
        return [(q, e0, e1, self._zigzag(q, k, e0, e1, rod=False) if self.spring_legs[q, k] else
                 bezier(*self._arc_ends(q, e0, e1), float(self.bulge[q, k]), n))
                for q, k, e0, e1 in self._arcs()]

    def spring_rods(self, params: np.ndarray) -> list[tuple[int, int, int, np.ndarray]]:
        """The spring arcs as rods.

        Args:
            params: the Bezier parameters (in [0, 1]) of a Bezier arc's rod nodes.

        Returns:
            Per spring arc: (quad, edge from, edge to, rod nodes (k,2) [m]); a zigzag at its own nodes
            (``ZIGZAG_SEGMENTS`` per piece).
        """
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


#: the shortest beam end an insert on short edges keeps, relative to ``min_beam`` (:func:`_pattern_on`: the
#: beam ends of an insert whose gap does not fit otherwise scale with its edges, as the features scale with
#: the cell below 20 mm, simfab.deploy.auto.FEATURE_SCALE_MIN)
SHORT_BEAM_MIN = 0.5
#: the shortest half beam at an insert, relative to the sheet's thickness: shorter, it is no beam (a stub
#: whose rod segments fall to micrometres, :func:`_pattern_on`); the layout's own short-beam rule
#: (SHORT_BEAM_MIN) sizes gaps by a vertex's mean edge, and this floor holds on each of its edges
HALF_BEAM_FLOOR = 0.5


def assign_sizes(d: np.ndarray, gmax: np.ndarray, sizes, min_gap: float) -> np.ndarray:
    """Catalogue size per insert: of the sizes whose gap ``g = r - d`` is achievable, the one nearest
    the middle of [min_gap, gmax] (most margin for cut tolerances); where none is, the one with the
    smallest shortfall.

    Args:
        d: (k,) [m] the growth r - g each insert needs.
        gmax: (k,) [m] its largest achievable gap.
        sizes: (s,) [m] the catalogue.
        min_gap: the smallest gap [m].

    Returns:
        (k,) catalogue index per insert.
    """
    r = np.asarray(sizes, dtype=np.float64)[None, :]
    g = r - np.asarray(d)[:, None]  # (k, s) gap each size would need
    hi = np.asarray(gmax)[:, None]
    short = np.maximum(min_gap - g, 0.0) + np.maximum(g - hi, 0.0)
    off_middle = np.abs(g - 0.5 * (min_gap + hi))
    least = short <= short.min(axis=1, keepdims=True) + 1e-12  # all achievable ones (shortfall 0), if any
    return np.argmin(np.where(least, off_middle, np.inf), axis=1)


def gap_rule(u: np.ndarray, h: np.ndarray, r: float) -> np.ndarray:
    """Gap half-size g = r - (h/2)(e^{-u} - 1) (see the module doc).

    Args:
        u: (n,) [-] log scale factors.
        h: (n,) [m] mean flat edge lengths.
        r: the insert half-size [m].

    Returns:
        (n,) [m].
    """
    return r - 0.5 * h * np.expm1(-np.asarray(u, dtype=np.float64))


#: weight of the edges' growth differences against their sums in :func:`edge_fitted_growth`
GROWTH_FIT_DIFFERENCE = 0.3


def edge_fitted_growth(P: np.ndarray, edges: np.ndarray, u: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Insert growths fitted to the edges (``growth_fit = "edges"``).

    Deployment lengthens edge (a, b) of flat length L_e by d_a + d_b; the target asks for
    G_e = (L_e/2)(e^{-u_a} + e^{-u_b} - 2) (the trapezoid rule of e^{-u} along it), each end's share
    differing by D_e = (L_e/2)(e^{-u_a} - e^{-u_b}). Least squares in relative terms,

        min_d  sum_e ((d_a + d_b - G_e) / L_e)^2 + mu^2 sum_{e: a, b free} ((d_a - d_b - D_e) / L_e)^2,

    mu = :data:`GROWTH_FIT_DIFFERENCE` (the differences remove the sums' null direction on a
    bipartite quad mesh). On a uniform grid d = (h/2)(e^{-u} - 1), the vertex rule, zeroes every
    residual; where edges differ in length the edges' sums are matched instead.

    Args:
        P: (n,2) [m] the vertices.
        edges: (e,2) vertex ids.
        u: (n,) [-] the log scale factor at the vertices.
        free: (n,) bool, the vertices with an insert (the others join their beams rigidly: d = 0).

    Returns:
        d (n,) [m].
    """

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
    """Lay the pattern out on a flattening.

    With ``layout = "mesh"`` the pattern of the best of the candidate meshings (fewest
    :func:`defects`, then the largest covered area).

    Args:
        uv: (n,2) [m] the flat vertices.
        boundary: the ordered boundary loop (vertex ids).
        faces: (m,3) the triangles.
        u: (n,) [-] the log scale factor.
        cfg: the :class:`PatternConfig`.
        seams: flat polylines [(k,2) m] of the cut sides of a cut flattening (their boundary vertices
            get inserts).
        cone_tips: (c,2) [m] the cones' flat positions (a pattern vertex there takes its growth from
            :func:`cone_tip_growth`).

    Returns:
        The :class:`Pattern` (``gap_max``: the largest gap the tuning may cut). InputError when the
        boundary self-intersects or no quad fits.
    """

    cfg.check_plates()
    poly = shapely.Polygon(uv[boundary])
    if not poly.is_valid:
        raise InputError("the flattened boundary self-intersects; the target needs cuts or cones")
    h = cfg.spacing
    check_cell_count(poly.area, h, what="the flat domain")
    meshes = quad_meshes(poly, uv, h, layout=cfg.layout, core=cfg.conforming_core)
    best, best_key = None, None
    for P, quads in meshes:
        pat = _pattern_on(poly, P, quads, uv, faces, u, cfg, seams, cone_tips)
        key = (defects(pat), -covered_fraction(pat, poly))
        if best_key is None or key < best_key:
            best, best_key = pat, key
    return used_sizes_only(best)


def used_sizes_only(pat: Pattern) -> Pattern:
    """The pattern with its catalogue cut to the sizes some insert takes: a size no insert takes (the
    catalogue is sized before the layout) would be listed in the bill of materials with count 0.
    Every insert keeps its size, gap and number; ``insert_class`` is renumbered in the same order.

    Args:
        pat: the :class:`Pattern`.

    Returns:
        The :class:`Pattern` (``pat`` itself when every size is used or there is no insert).
    """
    sizes = pat.config.sizes
    used = np.unique(pat.insert_class[pat.interior])
    if len(used) in (0, len(sizes)):
        return pat
    new = np.full(len(sizes), -1)
    new[used] = np.arange(len(used))
    cls = np.where(pat.interior, new[np.maximum(pat.insert_class, 0)], -1)
    cfg = dataclasses.replace(pat.config, insert_half_sizes=tuple(sizes[k] for k in used))
    return dataclasses.replace(pat, insert_class=cls, config=cfg)


def covered_fraction(pat: Pattern, poly) -> float:
    """The fraction of the flat domain the pattern's quads cover (their parts outside it not counted).

    Args:
        pat: the :class:`Pattern`.
        poly: the flat domain (a shapely Polygon).

    Returns:
        The fraction [-].
    """

    return float(np.sum(shapely.area(shapely.intersection(shapely.polygons(pat.P[pat.quads]), poly))) / poly.area)


def defects(pat: Pattern) -> int:
    """Count what a layout leaves wanting.

    Args:
        pat: the :class:`Pattern`.

    Returns:
        Inserts whose gap is unreachable + quads short of spring slack + quads without a spring.
    """
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
    # an insert whose gap does not fit its beam ends (short edges: a mesh layout's valence-3 vertices, seams)
    # keeps beam ends scaled with its edges, min_beam x e / h (e: its mean edge, on a seam its shortest; at
    # least SHORT_BEAM_MIN of min_beam), the size re-chosen for that limit; every other insert is unchanged
    over = interior & (req > gmax + 1e-12)
    if over.any():
        e = np.where(seam, emin, hv)
        g_short = 0.5 * e - cfg.min_beam * np.clip(e / h, SHORT_BEAM_MIN, 1.0)
        gmax = np.where(over, np.maximum(gmax, g_short), gmax)
        cls[over] = assign_sizes(-need[over], gmax[over], cfg.sizes, cfg.min_gap)
        r_v = np.where(interior, np.asarray(cfg.sizes)[np.maximum(cls, 0)], 0.0)
        req = np.where(interior, r_v + need, 0.0)
    # every half beam of an insert keeps HALF_BEAM_FLOOR x the sheet's thickness: the limits above follow the
    # vertex's mean edge, and on a much shorter edge of the same vertex (a mesh layout's cells clipped by the
    # outline) the half beam shrank to nothing (64 um on a shallow 180 mm cap: rod segments of 9 um, whose
    # bending the deployment's Newton could not factor); there the gap is limited by that edge and the
    # size re-chosen for it
    g_edge = 0.5 * emin - HALF_BEAM_FLOOR * cfg.beam_thickness
    short = interior & (np.clip(req, cfg.min_gap, gmax) > g_edge + 1e-12)
    if short.any():
        gmax = np.where(short, np.maximum(g_edge, cfg.min_gap), gmax)
        cls[short] = assign_sizes(-need[short], gmax[short], cfg.sizes, cfg.min_gap)
        r_v = np.where(interior, np.asarray(cfg.sizes)[np.maximum(cls, 0)], 0.0)
        req = np.where(interior, r_v + need, 0.0)
    unreachable = np.flatnonzero(interior & ((req < cfg.min_gap) | (req > gmax)))
    gap = np.where(interior, np.clip(req, cfg.min_gap, gmax), 0.0)
    # springs: none in quads with nearly collinear neighbouring edges
    spring = np.array([max_angle(P[q]) < np.radians(cfg.degenerate_angle_deg) for q in quads])
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
    """Growth of the insert at a cone tip: the mean over its edges of the half edge's growth,

        d = mean_e  int_0^{L_e/2} (e^{-u(s)} - 1) ds      (s from the tip along edge e),

    u interpolated on the flat triangulation, Gauss-Legendre with :data:`TIP_QUADRATURE` points. The
    gap rule's endpoint value is 0 there (u = 0 at a cone, :mod:`simfab.deploy.cuts`) while the first
    ring around the cone shrank: the cone metric's u is singular at the cone, so the endpoint rule
    misses the whole half edge.

    Args:
        P: (n,2) [m] the pattern's vertices.
        edges: (e,2) its edges.
        v: the tip vertex.
        uv: (m,2) [m] the flat triangulation's vertices.
        faces: its triangles.
        u: (m,) [-] the log scale factor on it.

    Returns:
        d [m].
    """
    es = edges[np.any(edges == v, axis=1)]
    other = es.sum(axis=1) - v
    x, w = np.polynomial.legendre.leggauss(TIP_QUADRATURE)
    s = 0.25 * (x + 1.0)  # [0, 1/2] of each edge
    pts = P[v] + s[None, :, None] * (P[other] - P[v])[:, None, :]  # (k, q, 2)
    uq = interpolate(uv, faces, u, pts.reshape(-1, 2)).reshape(len(other), -1)
    L = np.linalg.norm(P[other] - P[v], axis=1)
    return float(np.mean(0.25 * L * (np.expm1(-uq) @ w)))


def zigzag_springs(P, quads, qmids, growth, ratio, tight, cfg: PatternConfig):
    """Zigzag springs where a Bezier arc cannot get the slack.

    Each arc of a ``tight`` quad short of S/c >= (1 + spring_slack) max(growth, 1) becomes the
    shortest zigzag that reaches it (:func:`simfab.deploy.springs.size_zigzag`), or the longest one
    that fits where that is longer than the Bezier arc; the zigzag stays ``spring_width`` inside its
    triangle (edge midpoints and quad centre).

    Args:
        P: (n,2) [m] the vertices.
        quads: (q,4) the quads.
        qmids: (q,4,2) [m] the midpoint of each quad's edge (v_k, v_k+1).
        growth: (q,4) [-] the arcs' chord growths (:func:`quad_growth`).
        ratio: (q,4) [-] the Bezier arcs' S/c.
        tight: (q,) bool, the quads short of the slack.
        cfg: the :class:`PatternConfig`.

    Returns:
        (legs (q,4) int (0: Bezier), amplitude (q,4) [-], S/c (q,4), the quads still short (q,) bool).
    """
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
    """The largest gap the tuning may cut (``Pattern.gap_max``).

    Args:
        gmax: (n,) [m] the achievable limit.
        emin: (n,) [m] each vertex's shortest edge.
        gap: (n,) [m] the gap the layout cut.
        min_beam: the shortest half beam [m].
        cut: a cut pattern (its wedges leave short clipped edges next to inserts): then also at most
            emin/2 - min_beam, or the layout's gap (a half beam would otherwise shrink to nothing).

    Returns:
        (n,) [m].
    """
    if not cut:
        return gmax
    return np.minimum(gmax, np.maximum(0.5 * emin - min_beam, gap))


SEAM_TOL = 1e-6  # [spacings] where the seams are cut out of the domain's outline to leave the rim


def near_seams(P: np.ndarray, poly, seams, h: float) -> np.ndarray:
    """The points nearer a seam than the rim (the pattern's outline along a cut, on the seam or inside
    the domain where the grid dropped the cells a wedge crosses).

    Args:
        P: (n,2) [m] points.
        poly: the flat domain (a shapely Polygon); its outline without the seams is the rim (u = 0).
        seams: the seam polylines [(k,2) m].
        h: the spacing [m].

    Returns:
        (n,) bool.
    """

    if not len(seams):
        return np.zeros(len(P), dtype=bool)
    lines = shapely.MultiLineString([np.asarray(s, dtype=np.float64) for s in seams])
    rim = shapely.difference(poly.exterior, shapely.buffer(lines, SEAM_TOL * h))
    pts = shapely.points(P)
    return shapely.distance(lines, pts) < shapely.distance(rim, pts)


OUTSIDE_AREA = 0.1  # a quad with more than this fraction of its area outside the flat domain is dropped


def drop_outside_quads(poly, P: np.ndarray, quads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop quads with more than :data:`OUTSIDE_AREA` of their area outside the flat domain (a cell whose
    corners lie on both sides of a cut's wedge would bridge the seam) and keep the largest
    edge-connected set; a no-op on a domain without notches.

    Args:
        poly: the flat domain (a shapely Polygon).
        P: (n,2) [m] vertices.
        quads: (q,4) quads.

    Returns:
        (P, quads) re-indexed.
    """

    cells = shapely.polygons(P[quads])
    out = shapely.area(shapely.difference(cells, poly)) > OUTSIDE_AREA * shapely.area(cells)
    if not out.any():
        return P, quads
    quads = largest_component(quads[~out])
    used, inv = np.unique(quads, return_inverse=True)
    return P[used], inv.reshape(-1, 4)


def quad_growth(P: np.ndarray, quads: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Growth of the chords of each quad's four spring arcs in deployment.

    Arc k lies around corner k+1 (the order of :meth:`Pattern.spring_curves`) and joins the midpoints
    of that corner's two edges, at distances a, b from it; deployment lengthens both half edges by
    d_v, so with the corner angle alpha kept the chord grows from sqrt(a^2 + b^2 - 2ab cos alpha) to
    the same with a + d_v, b + d_v.

    Args:
        P: (n,2) [m] vertices.
        quads: (q,4) quads.
        d: (n,) [m] each vertex's growth r - g (0 on the boundary).

    Returns:
        (q,4) [-] chord growth factors.
    """
    v = quads
    prev, nxt = np.roll(quads, 1, axis=1), np.roll(quads, -1, axis=1)
    A = 0.5 * (P[prev] - P[v])  # (q,4,2) corner -> midpoint of the edge to the previous corner
    B = 0.5 * (P[nxt] - P[v])
    a, b = np.linalg.norm(A, axis=2), np.linalg.norm(B, axis=2)
    cos = np.einsum("qki,qki->qk", A, B) / (a * b)
    chord = lambda x, y: np.sqrt(np.maximum(x * x + y * y - 2 * x * y * cos, 0.0))  # noqa: E731
    return np.roll(chord(a + d[v], b + d[v]) / chord(a, b), -1, axis=1)


def max_angle(Q: np.ndarray) -> float:
    """Largest interior angle of a convex quad; a quad with one above ``degenerate_angle_deg`` gets no spring.

    Args:
        Q: (4,2) corners in order [m].

    Returns:
        The largest interior angle [rad].
    """
    out = 0.0
    for k in range(4):
        a, b = Q[k - 1] - Q[k], Q[(k + 1) % 4] - Q[k]
        out = max(out, float(np.arccos(np.clip(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)), -1, 1))))
    return out


def interpolate(uv, faces, values, P) -> np.ndarray:
    """Piecewise-linear interpolation of per-vertex values on the flat triangulation.

    Points outside it (a conforming layout's boundary vertices, up to about a sagitta off the
    boundary) take the value at their nearest point of the boundary edges (the field extended
    constant along the boundary's normal).

    Args:
        uv: (n,2) [m] the triangulation's vertices.
        faces: (m,3) its triangles.
        values: (n,) or (n,k) per-vertex values.
        P: (p,2) [m] the points.

    Returns:
        (p,) or (p,k).
    """
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
    """The target points of flat points (barycentric on the flat triangulation).

    Args:
        uv: (n,2) [m] the flattening.
        faces: (m,3) its triangles.
        V: (n,3) [m] the target's vertices.
        P: (k,2) [m] flat points.

    Returns:
        (k,3) [m].
    """
    return interpolate(uv, faces, V, P)
