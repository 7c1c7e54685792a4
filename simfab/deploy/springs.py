"""Torsional springs of a pattern: cubic Bezier arcs between consecutive edge midpoints of a quad,
with their bulge sized from the growth the quad must undergo.

Arc (quad with centre c, consecutive edge midpoints M0, M1; handle pull b [-]):

    P1 = M0 + b (c - M0),  P2 = M1 + b (c - M1),
    B(t) = (1-t)^3 M0 + 3 (1-t)^2 t P1 + 3 (1-t) t^2 P2 + t^3 M1,   t in [0, 1],

so the arc leaves each midpoint towards the quad centre and bulges inwards (b = 1: both handles
at the centre; b > 1: the arc passes closer to the centre than its handles' foot points).

Sizing rule (why). Deployment scales the quad by s_q = e^{-u_q} (u_q: flattening log scale
factor at the quad, mean of its corners): the two midpoints an arc joins move apart, its chord
c grows to s_q c. An arc of length S can follow only by bending while S > s_q c; as S -> s_q c
it straightens and its resistance to further growth diverges (it ends up carrying the growth in
tension, which compresses the beams: they buckle out of plane locally at every insert instead of
the network growing into the target - measured on the bundled dome: a 16 mm high deployment
for a 54 mm target with the earlier fixed b = 0.7, S/c = 1.16 < s_q = 1.22 at the centre).
Hence each quad's b is the smallest b >= ``spring_bulge`` with

    S(b) / c >= (1 + spring_slack) max(s_q, 1)               for all four arcs of the quad,

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
    """(n+1,2) points of the arc from M0 to M1 (2,) with handles pulled by b towards c (2,) [m], at
    n+1 uniform parameters (n int) or at the parameters n (array, in [0, 1])."""
    t = (np.linspace(0.0, 1.0, n + 1) if np.ndim(n) == 0 else np.asarray(n, dtype=np.float64))[:, None]
    P1, P2 = M0 + b * (c - M0), M1 + b * (c - M1)
    return (1 - t) ** 3 * M0 + 3 * (1 - t) ** 2 * t * P1 + 3 * (1 - t) * t**2 * P2 + t**3 * M1


def _length_ratio(M0, M1, c, b) -> float:
    p = bezier(M0, M1, c, b, _ARC_SAMPLES)
    return float(np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1)) / np.linalg.norm(M1 - M0))


def _clearance(M0, M1, c, b) -> float:
    return float(np.min(np.linalg.norm(bezier(M0, M1, c, b, _ARC_SAMPLES) - c, axis=1)))


def _bisect(f, lo: float, hi: float) -> float:
    """Smallest b in [lo, hi] with f(b) True (f monotone: False then True); hi if none."""
    if f(lo):
        return lo
    if not f(hi):
        return hi
    for _ in range(_BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if f(mid) else (mid, hi)
    return hi


def size_bulges(P: np.ndarray, quads: np.ndarray, mids_of_quad: np.ndarray, growth: np.ndarray, *, bulge_min: float,
                slack: float, width: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per quad (q,): handle pull b [-], the arcs' smallest length/chord ratio S/c at b [-], and
    whether the quad is ``tight`` (needs more than the centre clearance allows).

    P (n,2) [m] quad vertices; quads (q,4); mids_of_quad (q,4,2) [m] midpoints of the quad's
    edges k = (v_k, v_{k+1}); growth (q,) [-] s_q; bulge_min, slack [-]; width [m] spring width
    (the clearance kept from the quad centre)."""
    nq = len(quads)
    b = np.empty(nq)
    ratio = np.empty(nq)
    tight = np.zeros(nq, dtype=bool)
    for q in range(nq):
        M = mids_of_quad[q]
        c = P[quads[q]].mean(axis=0)
        arcs = [(M[k], M[(k + 1) % 4]) for k in range(4)]
        cap = _bisect(lambda x: min(_clearance(m0, m1, c, x) for m0, m1 in arcs) < width, bulge_min, _B_UPPER)
        cap = max(cap, bulge_min)
        need = (1.0 + slack) * max(float(growth[q]), 1.0)
        bq = _bisect(lambda x: min(_length_ratio(m0, m1, c, x) for m0, m1 in arcs) >= need, bulge_min, cap)
        b[q] = bq
        ratio[q] = min(_length_ratio(m0, m1, c, bq) for m0, m1 in arcs)
        tight[q] = ratio[q] < need - 1e-9
    return b, ratio, tight
