"""Facet check and refinement: boundary facets whose interior crosses into O get interpolated
constraint points (their density doubled when refined facets still penetrate); see
:mod:`simfab.coupling.simulate`, steps 3-4."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from simfab.contact.imls import unrotated
from simfab.coupling import config as C
from simfab.coupling.layout import EDGE_PAIRS, point_dhat
from simfab.coupling.model import CouplingModel
from simfab.coupling.points import check_weights, facet_points, facet_weights, vertex_points
from simfab.coupling.state import Evaluation, StepState
from simfab.errors import ConvergenceError


@dataclass(frozen=True, eq=False)
class FacetCheck:
    """The facet check at positions x (n, dim) [m], path length s [m] and refinement density
    ``order``: ids (f,) of the boundary facets that could reach into O, psi_max (f,) [m] the largest
    psi (or a certified upper bound of it) over each one's check points, refined (f,) bool; points:
    the constraint points it was made with; margin [m]: the smallest slack min_v d(v) - L cover of
    the facets not listed (inf: none), by which they are certified outside O."""

    x: np.ndarray
    s: float
    order: int
    ids: np.ndarray
    psi_max: np.ndarray
    refined: np.ndarray
    points: object = None
    margin: float = np.inf


def crossing_facets(cm: CouplingModel, x: np.ndarray, s: float, state: StepState,
                    final: Evaluation | None = None) -> list:
    """Facets to (re)refine at (x, s): unrefined boundary facets near O whose interior crosses into
    O, and, when a refined facet still penetrates O by more than the tolerance between its points,
    every refined facet again at twice the density (returned as the full list)."""
    if not cm.options.refine:
        return []
    fc = facet_check(cm, x, s, state, final)
    ids, psi_max, refined = fc.ids, fc.psi_max, fc.refined
    if len(ids) == 0:
        return []
    if np.any(psi_max[refined] > cm.tol):
        limit = C.MAX_EDGE_SAMPLES if cm.dim == 2 else C.MAX_FACE_LATTICE
        if 2 * state.order > limit:
            raise ConvergenceError(f"refinement at density {state.order} still leaves a penetration of "
                                   f"{psi_max[refined].max():.3e} m > {cm.tol:.3e} m at s={s:.6g} m")
        state.order = 2 * state.order + (1 if cm.dim == 2 else 0)  # new points = the old check points
        rebuild_points(cm, state)
        return sorted(state.refined | {int(f) for f in ids[psi_max > 0]})
    return [int(f) for f in ids[(psi_max > 0) & ~refined]]


def warm_crossings(cm: CouplingModel, x: np.ndarray, s: float, state: StepState, distances=None) -> list:
    """Unrefined boundary facets whose interior crosses into O at a step's warm start (x, s): refined
    before the step is solved (:func:`simfab.coupling.stepper.advance`, frictionless runs), where Newton
    would otherwise converge with them crossing and the step be solved again. Refined facets are left to the check
    after the solve (:func:`crossing_facets`, which may double the density).

    Args:
        cm: the coupling model.
        x: the warm start (n, dim) [m].
        s: the step's path length [m].
        state: the state the step starts from (its refined facets, density and check caches).
        distances: (d (k,) [m], grad d (k, dim)) of the state's constraint points at x when the step's
            objective knows them (:meth:`simfab.coupling.objective.StepObjective.known_distances`), or
            None (the boundary vertices' distances are evaluated).

    Returns:
        Facet ids (rows of ``cm.contact_facets``), empty when none crosses or refinement is off.
    """
    if not cm.options.refine:
        return []
    fc = facet_check(cm, x, s, state, distances=distances)
    return [int(f) for f in fc.ids[(fc.psi_max > 0) & ~fc.refined]]


#: The largest distance from a point of a facet to its nearest vertex, over its longest edge.
COVER = {2: 0.5, 3: 1.0 / np.sqrt(3.0)}  # max distance from a facet point to its nearest vertex / longest edge


def facet_check(cm: CouplingModel, x: np.ndarray, s: float, state: StepState,
                final: Evaluation | None = None, distances=None) -> FacetCheck:
    """Max psi over check points of each boundary facet that could reach into O at (x, s).

    Returns a :class:`FacetCheck`. Unrefined facets are checked
    at the points refinement would add; refined facets at the denser check points (their own
    points plus the midpoints between them). A facet can only reach into O if one of its vertices
    is within L * cover of O, cover the largest distance from a point of the facet to its nearest
    vertex (at most the longest edge / sqrt(3) on a triangle, half the edge in 2D). Check points
    whose Lipschitz bound, from the facet's vertices or from their own values at earlier checks (in
    O's body frame), is negative are not evaluated; their bound stands in for psi. The result is
    remembered for the same (x, s) (``final``: Newton's converged evaluation at x, whose distances
    stand in for the boundary vertices'; ``distances``: (d, grad d) of the state's points at x
    from elsewhere, used alike). Lower bounds of the vertices' distances (beyond an objective's lazy
    band) only weaken the bounds of the check points: more of them are evaluated, and psi_max is the
    same wherever it is positive (the only use of it: a positive psi is never bounded away).
    A check at other positions for the same s and constraint points (the warm start's, before Newton)
    stands for this one when A's boundary has moved little enough since (:func:`_carried`).
    """
    memo = state.check
    if memo is not None and memo.s == s and memo.order == state.order:
        if memo.x is x:
            return memo
        carried = _carried(cm, memo, x, state, final)
        if carried is not None:
            return carried
    facets = cm.contact_facets
    R, p = cm.pose(s)
    bv = cm.fem.boundary_vertices
    watch = _watched(cm)
    dv = np.full(cm.fem.n_vertices, np.inf)
    if final is not None and final.x is x and len(final.distances) >= len(bv):
        distances = (final.distances, final.distance_gradients)
    if distances is not None and len(distances[0]) >= len(bv):
        # Newton's converged evaluation at x, or the step objective's at a warm start (the first
        # len(bv) constraint points are the boundary vertices, in vertex_points order): exact within
        # the lazy band, lower bounds beyond it; those beyond the kernel radius get the sharper
        # nearest-sample bound
        dv[bv] = distances[0][: len(bv)]
        if watch:
            state.grad_peak = max(state.grad_peak, _max_norm(distances[1]))
        if np.isfinite(cm.field.radius):  # (an exact field has no far points: radius inf)
            out = np.flatnonzero(dv[bv] > point_dhat(cm, state.points)[: len(bv)] * C.LAZY_BAND_DHATS)
            if len(out):
                nn = cm.field.nearest_sample(x[bv[out]], (R, p))
                far = nn >= cm.field.radius
                dv[bv[out[far]]] = np.maximum(dv[bv[out[far]]], cm.field.far_bound(nn[far]))
    else:
        ev = cm.field.evaluate(x[bv], (R, p), hessian=False)
        dv[bv] = -ev.psi
        if watch:
            state.grad_peak = max(state.grad_peak, _max_norm(ev.grad))
        far = ~ev.near
        if far.any():  # far vertices: a sharper lower bound of their distance than far_distance
            dv[bv[far]] = cm.field.far_lower_bound(x[bv[far]], (R, p))
    xf = x[facets]  # (F, nv, dim)
    if cm.dim == 2:  # (the one edge of a 2D facet: slices, not EDGE_PAIRS' gathers)
        ev_ = xf[:, 0:1] - xf[:, 1:2]
    else:
        a, c = EDGE_PAIRS[cm.dim]
        ev_ = xf[:, a] - xf[:, c]
    edges2 = np.einsum("fed,fed->fe", ev_, ev_)  # (F, e) squared edge lengths
    # every point of a facet lies within `cover` of one of its vertices: half the edge (2D), and
    # longest edge / sqrt(3) on a triangle (the farthest point is the circumcentre when acute,
    # R = c / (2 sin gamma) with gamma >= 60 deg; else within half the longest edge). A facet whose
    # vertices are all farther than L * cover from O is certified outside by the vertex bounds.
    cover = np.sqrt(np.maximum.reduce(edges2, axis=1)) * COVER[cm.dim]
    dvf = dv[facets]  # (F, nv)
    slack = np.minimum.reduce(dvf, axis=1) - C.PSI_LIPSCHITZ * cover
    ids = (slack <= 0.0).nonzero()[0]
    margin = float(np.min(slack, where=slack > 0.0, initial=np.inf))
    if state.refined:
        refined = np.zeros(len(facets), dtype=bool)
        refined[list(state.refined)] = True
        refined = refined[ids]
    else:
        refined = np.zeros(len(ids), dtype=bool)
    psi_max = np.full(len(ids), -np.inf)
    n_refined = np.count_nonzero(refined)
    for is_refined in (False, True):
        count = n_refined if is_refined else len(ids) - n_refined
        if count:
            every = count == len(ids)  # (all of ids: no selection to gather)
            sel = None if every else (refined if is_refined else ~refined)
            w, gap_map = check_lattice(cm.dim, state.order, is_refined)
            f_sel = ids if every else ids[sel]
            xv = xf[f_sel]  # (f, nv, dim) the facets' vertices
            y = w @ xv  # (f, p, dim) check points
            # psi(y) <= psi(v) + L |y - v| for each vertex v of the facet: points this bounds below
            # zero are outside O and need no evaluation (their bound stands in for psi: every use
            # of psi_max only asks whether it is positive or above the tolerance)
            gap = np.sqrt(np.maximum(edges2[f_sel] @ gap_map, 0.0)).reshape(len(f_sel), len(w), -1)  # (f, p, nv)
            bound = C.PSI_LIPSCHITZ * gap - dvf[f_sel][:, None, :]
            psi = bound[:, :, 0]
            for v in range(1, bound.shape[2]):  # min over the nv vertices (faster than min(axis=2))
                psi = np.minimum(psi, bound[:, :, v])
            # the same check points' values (or bounds) from earlier checks: O moved rigidly, so in
            # O's body frame psi is the same L-Lipschitz function and psi(y) <= psi(y') + L |b - b'|
            # with b, b' the body-frame positions now and then (never checked: b' NaN, whose bound
            # fmin passes over)
            body = _body_frame(y, R, p)
            known_body, known_psi = _check_cache(cm, state, is_refined, len(w))
            step = body - known_body[f_sel]
            moved = np.sqrt(np.einsum("fpd,fpd->fp", step, step))
            psi = np.fmin(psi, known_psi[f_sel] + C.PSI_LIPSCHITZ * moved)
            todo = psi >= 0.0
            if np.count_nonzero(todo):
                ev = cm.field.evaluate(y[todo], (R, p), hessian=False)
                psi[todo] = ev.psi
                if watch:
                    state.grad_peak = max(state.grad_peak, _max_norm(ev.grad))
            known_body[f_sel], known_psi[f_sel] = body, psi
            if every:
                psi_max = np.maximum.reduce(psi, axis=1)
            else:
                psi_max[sel] = np.maximum.reduce(psi, axis=1)
    out = FacetCheck(x, s, state.order, ids, psi_max, refined, state.points, margin)
    state.check = out
    return out


def _carried(cm: CouplingModel, memo: FacetCheck, x: np.ndarray, state: StepState,
             final: Evaluation | None) -> FacetCheck | None:
    """The check at x carried over from ``memo`` (the same s and constraint points, other positions), or
    None when it certifies nothing. Every boundary vertex moved by at most delta since, and so did every
    check point (a convex combination of its facet's vertices): psi rose by at most L delta at each (the
    listed facets' bounds become psi_max + L delta), and the slack min_v d(v) - L cover of a facet not
    listed fell by at most L (1 + 2 COVER) delta (each vertex's distance by L delta, its longest edge by
    2 delta). When the listed bounds stay negative and the margin positive, the full check at x would
    find no facet crossing either: it lists the same facets, with those bounds (one vertex displacement
    instead of the check's lattice; a Newton step is usually far shorter than the gaps it certifies)."""
    if memo.points is not state.points or (len(memo.psi_max) and memo.psi_max.max() >= 0.0):
        return None
    bv = cm.fem.boundary_vertices
    delta = _max_norm(x[bv] - memo.x[bv])
    L = C.PSI_LIPSCHITZ
    fall = L * (1.0 + 2.0 * COVER[cm.dim]) * delta
    psi_max = memo.psi_max + L * delta
    if not memo.margin > fall or (len(psi_max) and psi_max.max() >= 0.0):
        return None
    if final is not None and final.x is x and _watched(cm):
        state.grad_peak = max(state.grad_peak, _max_norm(final.distance_gradients))  # (as the full check watches)
    out = FacetCheck(x, s=memo.s, order=memo.order, ids=memo.ids, psi_max=psi_max, refined=memo.refined,
                     points=memo.points, margin=memo.margin - fall)
    state.check = out
    return out


def _watched(cm: CouplingModel) -> bool:
    """Whether the field's gradient norms are watched (``state.grad_peak``): an exact field's gradient is a
    unit vector (to round-off), nothing to watch while the Lipschitz bound exceeds 1."""
    return not (getattr(cm.field, "unit_gradient", False) and C.PSI_LIPSCHITZ > 1.0 + 1e-9)


def _body_frame(y: np.ndarray, R: np.ndarray, p: np.ndarray) -> np.ndarray:
    """:func:`simfab.contact.imls.body_frame` of points y (..., dim) for O at (R, p), padded in place."""
    body = np.zeros(y.shape[:-1] + (3,))
    body[..., : y.shape[-1]] = y
    body -= p
    return body if unrotated(R) else (body.reshape(-1, 3) @ R).reshape(body.shape)


def _max_norm(v: np.ndarray) -> float:
    """Largest row norm of (k, dim) v (0 when empty)."""
    return float(np.sqrt(np.einsum("kd,kd->k", v, v).max())) if len(v) else 0.0


@functools.lru_cache(maxsize=32)
def check_lattice(dim: int, order: int, refined: bool) -> tuple[np.ndarray, np.ndarray]:
    """(w (p, nv), G (edges, p * nv)) for the check points of a facet at refinement ``order``:
    their barycentric weights (refinement points for an unrefined facet, the denser check points
    for a refined one) and the map from the facet's squared edge lengths (f, edges) to the squared
    distances (f, p * nv) from each check point to each of the facet's vertices.

    For barycentric y = sum_a w_a v_a, |y - q|^2 = sum_a w_a |v_a - q|^2 - 1/2 sum_ac w_a w_c |v_a - v_c|^2;
    with q = v_b it is linear in the squared edge lengths: one small product per check instead of
    f * p * nv difference vectors. (Cached and read-only.)
    """
    w = check_weights(dim, order) if refined else facet_weights(dim, order)
    a, c = EDGE_PAIRS[dim]
    b = np.arange(dim)
    wa, wc = w[:, a].T[:, :, None], w[:, c].T[:, :, None]  # (e, p, 1)
    G = (wa * (c[:, None, None] == b) + wc * (a[:, None, None] == b) - wa * wc).reshape(len(a), -1)
    w.flags.writeable = False
    G.flags.writeable = False
    return w, G


def _check_cache(cm: CouplingModel, state: StepState, refined: bool, p: int):
    """(body positions (F, p, 3) [m], psi or an upper bound (F, p) [m]) of every boundary facet's
    check points at its last check (NaN / +inf: never checked) for unrefined or refined facets at
    the current density; reset when the density changes."""
    key = (refined, state.order, p)
    cache = state.check_cache.get(key)
    if cache is None:
        F = len(cm.contact_facets)
        cache = state.check_cache[key] = (np.full((F, p, 3), np.nan), np.full((F, p), np.inf))
    return cache


def rebuild_points(cm: CouplingModel, state: StepState) -> None:
    """Constraint points = boundary vertices + refinement points of every refined facet."""
    facets = cm.contact_facets
    pts = vertex_points(np.asarray(cm.fem.boundary_vertices, dtype=np.int64), cm.dim)
    if state.refined:
        ids = np.array(sorted(state.refined))
        pts = pts.concat(facet_points(facets, ids, facet_weights(cm.dim, state.order)))
    state.points = pts


def add_refinement(cm: CouplingModel, state: StepState, facet_ids) -> None:
    """Give the boundary facets ``facet_ids`` (rows of ``cm.contact_facets``) refinement points."""
    state.refined.update(int(f) for f in facet_ids)
    rebuild_points(cm, state)
