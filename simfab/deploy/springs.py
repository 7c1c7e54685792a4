"""Torsional springs of a pattern: cubic Bezier arcs (or zigzags) between consecutive edge midpoints
of a quad, sized from the growth the quad undergoes in deployment.

Arc (quad centre c, consecutive edge midpoints M0, M1; handle pull b [-]):

    P1 = M0 + b (c - M0),  P2 = M1 + b (c - M1),
    B(t) = (1-t)^3 M0 + 3 (1-t)^2 t P1 + 3 (1-t) t^2 P2 + t^3 M1,   t in [0, 1].

Deployment grows an arc's chord c by s (:func:`simfab.deploy.pattern.quad_growth`); an arc of
length S follows by bending only while S > s c (straightened, it carries the growth in tension and
the beams buckle locally). Each quad's b is the smallest b >= ``spring_bulge`` with

    S_k(b) / c_k >= (1 + spring_slack) max(s_k, 1)           for all four arcs k,

by bisection (:func:`size_bulges`), capped where an arc comes within ``spring_width`` of the centre
(the quad is then ``tight``). Longer arcs: zigzags packed into the arc's triangle (:func:`zigzag_layout`,
:func:`size_zigzag`); a skewed quad may take one pull per arc (:func:`size_arcs`). The reasoning and
the figures behind it: docs/methods.md, "simfab.deploy.springs".
"""

from __future__ import annotations

import numpy as np

_ARC_SAMPLES = 64  # polyline points for arc lengths and centre clearances
_BISECTION_STEPS = 30
_B_UPPER = 2.0  # bisection bracket of the cap search (the arc reaches the centre well before)


def bezier(M0: np.ndarray, M1: np.ndarray, c: np.ndarray, b: float, n) -> np.ndarray:
    """Points of one arc from M0 to M1 with handles pulled by b towards c.

    Args:
        M0: (2,) [m] start.
        M1: (2,) [m] end.
        c: (2,) [m] the quad centre.
        b: the pull [-].
        n: segments (n+1 uniform parameters), or the parameters (array, in [0, 1]).

    Returns:
        (k,2) [m].
    """
    t = (np.linspace(0.0, 1.0, n + 1) if np.ndim(n) == 0 else np.asarray(n, dtype=np.float64))[:, None]
    P1, P2 = M0 + b * (c - M0), M1 + b * (c - M1)
    return (1 - t) ** 3 * M0 + 3 * (1 - t) ** 2 * t * P1 + 3 * (1 - t) * t**2 * P2 + t**3 * M1


def _arcs(M0, M1, c, b) -> np.ndarray:
    """(q,4,k,2) sample points of every quad's four arcs: M0, M1 (q,4,2), c (q,1,2), b (q,)."""
    t = np.linspace(0.0, 1.0, _ARC_SAMPLES + 1)[None, None, :, None]
    bb = np.asarray(b, dtype=np.float64)[:, None, None]
    P1, P2 = M0 + bb * (c - M0), M1 + bb * (c - M1)
    P0, P1, P2, P3 = (a[:, :, None, :] for a in (M0, P1, P2, M1))
    return (1 - t) ** 3 * P0 + 3 * (1 - t) ** 2 * t * P1 + 3 * (1 - t) * t**2 * P2 + t**3 * P3


def _arc_ratios(M0, M1, c, b) -> np.ndarray:
    """(q,4) arc length / chord of each quad's four arcs."""
    p = _arcs(M0, M1, c, b)
    S = np.sum(np.linalg.norm(np.diff(p, axis=2), axis=3), axis=2)
    return S / np.linalg.norm(M1 - M0, axis=2)


def length_ratio(M0, M1, c, b) -> np.ndarray:
    """Smallest arc length / chord over each quad's four arcs.

    Args:
        M0: (q,4,2) [m] each arc's start.
        M1: (q,4,2) [m] each arc's end.
        c: (q,1,2) [m] the quad centres.
        b: (q,) or (q,4) [-] the pulls.

    Returns:
        (q,) [-].
    """
    return np.min(_arc_ratios(M0, M1, c, b), axis=1)


def _clearance(M0, M1, c, b) -> np.ndarray:
    """(q,) smallest distance of each quad's arcs from its centre [m]."""
    return np.min(np.linalg.norm(_arcs(M0, M1, c, b) - c[:, :, None, :], axis=3), axis=(1, 2))


def _bisect(ok, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Per quad, the smallest b in [lo, hi] with ok(b) True (ok monotone in b: False then True;
    vectorized over quads); hi where none, lo where already."""
    lo, hi = lo.copy(), hi.copy()
    at_lo = ok(lo)
    for _ in range(_BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        good = ok(mid)
        hi = np.where(good, mid, hi)
        lo = np.where(good, lo, mid)
    return np.where(at_lo, lo, hi)  # hi stays where no b in the range is ok


def size_bulges(P: np.ndarray, quads: np.ndarray, mids_of_quad: np.ndarray, growth: np.ndarray, *, bulge_min: float,
                slack: float, width: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per quad, the smallest pull that gives every arc its slack (see the module doc).

    Args:
        P: (n,2) [m] quad vertices.
        quads: (q,4) the quads.
        mids_of_quad: (q,4,2) [m] midpoints of the quad's edges k = (v_k, v_{k+1}).
        growth: (q,) or (q,4) [-] the quad's s_q or each arc's own chord growth (arc k joins the
            midpoints of edges k and k+1).
        bulge_min: the smallest pull [-].
        slack: the length margin [-].
        width: spring width [m] (the clearance kept from the quad centre).

    Returns:
        (pull b (q,) [-], the four arcs' S/c at b (q,4) [-], tight (q,) bool: an arc needs more than
        the centre clearance allows).
    """
    nq = len(quads)
    if nq == 0:
        return np.zeros(0), np.zeros(0), np.zeros(0, dtype=bool)
    M0 = np.asarray(mids_of_quad, dtype=np.float64)
    M1 = np.roll(M0, -1, axis=1)
    c = P[quads].mean(axis=1)[:, None, :]
    bmin = np.full(nq, float(bulge_min))
    # cap: the largest b whose arcs keep ``width`` from the centre (the first b that does not, by bisection)
    cap = np.maximum(_bisect(lambda b: _clearance(M0, M1, c, b) < width, bmin, np.full(nq, _B_UPPER)), bmin)
    g = np.asarray(growth, dtype=np.float64)
    need = (1.0 + slack) * np.maximum(g if g.ndim == 2 else g[:, None], 1.0)  # (q,4)
    b = _bisect(lambda x: np.all(_arc_ratios(M0, M1, c, x) >= need, axis=1), bmin, cap)
    ratio = _arc_ratios(M0, M1, c, b)
    return b, ratio, np.any(ratio < need - 1e-9, axis=1)


def size_arcs(M0: np.ndarray, M1: np.ndarray, c: np.ndarray, need: np.ndarray, b: np.ndarray, *,
              bulge_min: float, width: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-arc pulls for quads short of the slack at their common pull.

    Each arc gets the smallest pull that reaches its own need; the per-arc pulls are kept where the
    arcs' centre clearances c_k keep them as far apart as four arcs at the cap would (opposite arcs
    c_k + c_{k+2} >= 2 w, adjacent ones about sqrt(c_k^2 + c_{k+1}^2) >= sqrt(2) w).

    Args:
        M0: (q,4,2) [m] each arc's start midpoint.
        M1: (q,4,2) [m] each arc's end midpoint.
        c: (q,1,2) [m] the quad centres.
        need: (q,4) [-] the S/c each arc needs.
        b: (q,) [-] the common pulls.
        bulge_min: the smallest pull [-].
        width: spring width [m].

    Returns:
        (pulls (q,4) [-] (the common b repeated where the per-arc ones would bring two arcs nearer
        than the cap allows, or an arc does not reach its need), their S/c (q,4) [-]).
    """
    q = len(b)
    lo, hi = np.full(q, float(bulge_min)), np.full(q, _B_UPPER)
    bk = np.empty((q, 4))
    for k in range(4):
        sl = (slice(None), slice(k, k + 1))
        bk[:, k] = _bisect(lambda x: _arc_ratios(M0[sl], M1[sl], c, x)[:, 0] >= need[:, k], lo, hi)
    ratio = np.stack([_arc_ratios(M0[:, k:k + 1], M1[:, k:k + 1], c, bk[:, k])[:, 0] for k in range(4)], axis=1)
    clear = np.stack([np.min(np.linalg.norm(_arcs(M0[:, k:k + 1], M1[:, k:k + 1], c, bk[:, k])[:, 0]
                                            - c, axis=2), axis=1) for k in range(4)], axis=1)
    nxt, opp = np.roll(clear, -1, axis=1), np.roll(clear, -2, axis=1)
    ok = (np.all(clear + opp >= 2.0 * width - 1e-12, axis=1)
          & np.all(clear**2 + nxt**2 >= 2.0 * width**2 - 1e-18, axis=1) & np.all(ratio >= need - 1e-9, axis=1))
    common = np.repeat(np.asarray(b, dtype=np.float64)[:, None], 4, axis=1)
    common_ratio = _arc_ratios(M0, M1, c, b)
    return np.where(ok[:, None], bk, common), np.where(ok[:, None], ratio, common_ratio)


# --- zigzag springs -------------------------------------------------------------------------------------------------

ZIGZAG_MAX_LEGS = 12  # legs of the longest zigzag tried (even counts 2, 4, ..., this)
_TURN_SAMPLES = 16  # polyline points per half turn of a drawn zigzag
# rod segments per piece of a zigzag (lead-in/out line, quarter turn, leg, half turn): a leg bends like a cantilever
# (two segments resolve its curvature's linear profile), a half turn of 180 deg turns by 60 deg per node
ZIGZAG_SEGMENTS = {"lead": 1, "quarter": 1, "leg": 2, "half": 3}


def zigzag_segments(legs: int) -> int:
    """Rod segments of a zigzag.

    Args:
        legs: its legs.

    Returns:
        The segment count (:data:`ZIGZAG_SEGMENTS` per piece).
    """
    s = ZIGZAG_SEGMENTS
    return 2 * (s["lead"] + s["quarter"]) + legs * s["leg"] + (legs - 1) * s["half"]


def _zigzag_frame(M0, M1, c):
    """Local frame of the arc's triangle (M0, M1, c): origin M0, x along the chord, y towards c;
    returns (chord length, unit x (2,), unit y (2,), inward unit normals of the sides M0-c and M1-c
    in local coordinates (2,), (2,))."""
    M0, M1, c = (np.asarray(a, dtype=np.float64) for a in (M0, M1, c))
    L = float(np.linalg.norm(M1 - M0))
    ex = (M1 - M0) / L
    ey = np.array([-ex[1], ex[0]])
    if (c - M0) @ ey < 0:
        ey = -ey
    C = np.array([(c - M0) @ ex, (c - M0) @ ey])
    d0 = C / np.linalg.norm(C)  # side M0 -> c
    d1 = (C - [L, 0.0]) / np.linalg.norm(C - [L, 0.0])  # side M1 -> c
    n0 = np.array([d0[1], -d0[0]])  # inward: towards +x of the side through the origin
    n1 = np.array([-d1[1], d1[0]])
    if n0 @ [L, 0.0] < 0:
        n0 = -n0
    if n1 @ ([0.0, 0.0] - np.array([L, 0.0])) < 0:
        n1 = -n1
    return L, ex, ey, n0, n1


def zigzag_layout(M0, M1, c, legs: int, amplitude: float, clearance: float):
    """Pieces of a zigzag spring from M0 to M1 inside the triangle (M0, M1, c).

    Local frame: x along the chord M0 -> M1 (length L), y towards c. The path runs along the chord
    from M0, turns up by a quarter circle into leg 0, and alternates ``legs`` (even) vertical legs at
    pitch p = 2 rho joined by half circles of radius rho (at the top between legs 2i and 2i+1, at the
    bottom - touching the chord - between legs 2i+1 and 2i+2), then turns down by a quarter circle
    into the chord to M1. Every turn's circle keeps ``clearance`` + rho from both sides M0-c, M1-c
    (inward normals n0, n1): the spring's centre line stays ``clearance`` inside the triangle (apart
    from its ends on the chord), so the four springs of a quad stay 2 clearance apart. With
    X_min + rho = x_0 the first leg (n0 . (X_min, rho) = rho + clearance, linear in rho) and likewise
    the last, the legs fill [X_min + rho, X_max - rho]:

        rho = (gamma - alpha) / (2 legs + beta + epsilon),
        X_min = alpha + beta rho,  X_max = gamma - epsilon rho.

    The top of the pair (2i, 2i+1) is t_i = t_lo + amplitude (t_max,i - t_lo), with t_max,i the height
    at which the top half circle (centre X_i) touches the clearance line of a side and
    t_lo = rho + clearance (every leg at least one clearance long). ``legs`` legs fit when
    rho >= clearance and every t_max,i >= t_lo.

    Args:
        M0: (2,) [m] start.
        M1: (2,) [m] end.
        c: (2,) [m] the quad centre.
        legs: the legs (even).
        amplitude: the leg height fraction [-].
        clearance: [m].

    Returns:
        (pieces, rho [m]), or None where ``legs`` legs do not fit: pieces in world coordinates,
        ("line", P, Q) and ("arc", centre, radius, angle from, angle to, R) - the angles in the chord's
        frame, R (2,2) its axes as columns.
    """
    L, ex, ey, n0, n1 = _zigzag_frame(M0, M1, c)
    M0 = np.asarray(M0, dtype=np.float64)
    # n0 . (X, rho) >= rho + clearance  ->  X >= (rho (1 - n0y) + clearance) / n0x
    alpha, beta = clearance / n0[0], (1.0 - n0[1]) / n0[0]
    # n1 . (X - L, rho) >= rho + clearance  ->  X <= L - (rho (1 - n1y) + clearance) / (-n1x)
    gamma, eps = L - clearance / -n1[0], (1.0 - n1[1]) / -n1[0]
    rho = (gamma - alpha) / (2 * legs + beta + eps)
    if not (rho >= clearance and legs >= 2 and legs % 2 == 0) or n0[1] >= 0 or n1[1] >= 0:
        return None  # (a side leaning outward over the chord: the centre projects beyond it - no zigzag)
    x = (alpha + beta * rho) + rho + 2 * rho * np.arange(legs)
    tops = []
    for i in range(legs // 2):
        X = 0.5 * (x[2 * i] + x[2 * i + 1])
        # n . (X - o, t) >= rho + clearance for both sides (n_y < 0 for the sides above the chord)
        tmax = min((rho + clearance - n0[0] * X) / n0[1], (rho + clearance - n1[0] * (X - L)) / n1[1])
        if tmax < rho + clearance:
            return None
        tops.append(rho + clearance + amplitude * (tmax - rho - clearance))
    loc = []  # pieces in local coordinates
    loc.append(("line", np.array([0.0, 0.0]), np.array([x[0] - rho, 0.0])))
    loc.append(("arc", np.array([x[0] - rho, rho]), rho, -0.5 * np.pi, 0.0))
    for j in range(legs):
        t = tops[j // 2]
        up = j % 2 == 0
        loc.append(("line", np.array([x[j], rho if up else t]), np.array([x[j], t if up else rho])))
        if j == legs - 1:
            break
        if up:  # top half turn, clockwise over the top
            loc.append(("arc", np.array([x[j] + rho, t]), rho, np.pi, 0.0))
        else:  # bottom half turn, counter-clockwise under the bottom
            loc.append(("arc", np.array([x[j] + rho, rho]), rho, -np.pi, 0.0))
    loc.append(("arc", np.array([x[-1] + rho, rho]), rho, np.pi, 1.5 * np.pi))
    loc.append(("line", np.array([x[-1] + rho, 0.0]), np.array([L, 0.0])))
    R = np.column_stack([ex, ey])
    out = []
    for p in loc:
        if p[0] == "line":
            out.append(("line", M0 + R @ p[1], M0 + R @ p[2]))
        else:
            out.append(("arc", M0 + R @ p[1], p[2], p[3], p[4], R))
    return out, rho


def piece_points(p, m: int) -> np.ndarray:
    """Points of one zigzag piece (a line or an arc) at uniform steps of its arc length.

    Args:
        p: one of :func:`zigzag_layout`'s pieces.
        m: number of steps.

    Returns:
        (m+1,2) points [m].
    """
    s = np.linspace(0.0, 1.0, m + 1)[:, None]
    if p[0] == "line":
        return p[1] + s * (p[2] - p[1])
    _, C, r, a0, a1, R = p
    a = a0 + s[:, 0] * (a1 - a0)
    return C + (r * np.column_stack([np.cos(a), np.sin(a)])) @ R.T


def _piece_kind(p, k: int, n: int) -> str:
    if p[0] == "line":
        return "lead" if k in (0, n - 1) else "leg"
    return "quarter" if abs(p[4] - p[3]) < 0.75 * np.pi else "half"


def zigzag_points(pieces, *, rod: bool = False) -> np.ndarray:
    """Polyline of a zigzag's pieces.

    Args:
        pieces: :func:`zigzag_layout`'s pieces.
        rod: the rod's nodes (:data:`ZIGZAG_SEGMENTS` per piece) instead of the drawn polyline
            (``_TURN_SAMPLES`` points per half turn, straight pieces as they are).

    Returns:
        (k,2) [m].
    """
    out = []
    for k, p in enumerate(pieces):
        kind = _piece_kind(p, k, len(pieces))
        if rod:
            m = ZIGZAG_SEGMENTS[kind]
        else:
            m = 1 if p[0] == "line" else _TURN_SAMPLES // 2 if kind == "quarter" else _TURN_SAMPLES
        pts = piece_points(p, m)
        out.append(pts if k == 0 else pts[1:])
    return np.vstack(out)


def _polyline_ratio(pts: np.ndarray) -> float:
    return float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)) / np.linalg.norm(pts[-1] - pts[0]))


def size_zigzag(M0, M1, c, need: float, clearance: float) -> tuple[int, float, float]:
    """The shortest zigzag (fewest legs, then the smallest leg height by bisection - its length grows
    monotonically with the amplitude) whose drawn length is at least ``need`` x its chord; the
    longest that fits where none reaches.

    Args:
        M0: (2,) [m] start.
        M1: (2,) [m] end.
        c: (2,) [m] the quad centre.
        need: the S/c needed [-].
        clearance: [m].

    Returns:
        (legs (0: none fits), amplitude [-], S/c [-]).
    """
    best = (0, 0.0, 0.0)
    for legs in range(2, ZIGZAG_MAX_LEGS + 1, 2):
        lay = zigzag_layout(M0, M1, c, legs, 1.0, clearance)
        if lay is None:  # (more legs: a smaller rho and lower legs may fit where fewer do not)
            continue
        r1 = _polyline_ratio(zigzag_points(lay[0]))
        if r1 > best[2]:
            best = (legs, 1.0, r1)
        if r1 < need:
            continue
        ratio = lambda a: _polyline_ratio(zigzag_points(zigzag_layout(M0, M1, c, legs, a, clearance)[0]))  # noqa
        lo, hi = 0.0, 1.0
        if ratio(lo) >= need:
            return legs, lo, ratio(lo)
        for _ in range(_BISECTION_STEPS):
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if ratio(mid) >= need else (mid, hi)
        return legs, hi, ratio(hi)
    return best
