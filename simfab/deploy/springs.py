"""Torsional springs of a pattern: cubic Bezier arcs between consecutive edge midpoints of a quad,
with their bulge sized from the growth the quad must undergo.

Arc (quad with centre c, consecutive edge midpoints M0, M1; handle pull b [-]):

    P1 = M0 + b (c - M0),  P2 = M1 + b (c - M1),
    B(t) = (1-t)^3 M0 + 3 (1-t)^2 t P1 + 3 (1-t) t^2 P2 + t^3 M1,   t in [0, 1],

so the arc leaves each midpoint towards the quad centre and bulges inwards (b = 1: both handles
at the centre; b > 1: the arc passes closer to the centre than its handles' foot points).

Sizing rule (why). Deployment scales the quad by s_q = e^{-u_q} (u_q: flattening log scale
factor at the quad): the two midpoints an arc joins move apart, its chord c grows to s_q c
(the pattern passes each arc's own chord growth, from the growth r - g of the insert at the
corner the arc turns around: :func:`simfab.deploy.pattern.quad_growth`). An arc of length S can
follow only by bending while S > s_q c; as S -> s_q c it straightens and its resistance to
further growth diverges (it ends up carrying the growth in tension, which compresses the beams:
they buckle out of plane locally at every insert instead of the network growing into the target
- measured on the bundled dome: a 16 mm high deployment for a 54 mm target with the earlier
fixed b = 0.7, S/c = 1.16 < s_q = 1.22 at the centre).
Hence each quad's b is the smallest b >= ``spring_bulge`` with

    S_k(b) / c_k >= (1 + spring_slack) max(s_k, 1)           for all four arcs k of the quad,

found by bisection (S/c grows monotonically with b). b is capped where an arc would come within
``spring_width`` of the quad centre (the four arcs of a quad must stay apart for the cut); a
quad that needs more is reported (``tight``) and keeps the capped b. Shrinking quads (u > 0,
saddles) need no growth slack (their arcs bend further); they keep the plain margin.
"""

from __future__ import annotations

import numpy as np

_ARC_SAMPLES = 64  # polyline points for arc lengths and centre clearances
_BISECTION_STEPS = 30
_B_UPPER = 2.0  # bisection bracket of the cap search (the arc reaches the centre well before)


def bezier(M0: np.ndarray, M1: np.ndarray, c: np.ndarray, b: float, n) -> np.ndarray:
    """(n+1,2) points of one arc from M0 to M1 (2,) with handles pulled by b towards c (2,) [m], at
    n+1 uniform parameters (n int) or at the parameters n (array, in [0, 1])."""
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


def _length_ratio(M0, M1, c, b) -> np.ndarray:
    """(q,) smallest arc length / chord over each quad's four arcs."""
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
    """Per quad: handle pull b (q,) [-], its four arcs' length/chord ratios S/c at b (q,4) [-], and
    whether the quad is ``tight`` (q,) (an arc needs more than the centre clearance allows).

    P (n,2) [m] quad vertices; quads (q,4); mids_of_quad (q,4,2) [m] midpoints of the quad's
    edges k = (v_k, v_{k+1}); growth (q,) or (q,4) [-] the quad's s_q or each arc's own chord
    growth (arc k joins the midpoints of edges k and k+1); bulge_min, slack [-]; width [m] spring
    width (the clearance kept from the quad centre)."""
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
