"""Warm start of a step (predictor): extrapolations of the last steps with the contact gaps restored and
near points lifted, and the contact predictor (a penalty solve pushing reachable points with O),
used when no extrapolation is feasible; see :mod:`simfab.coupling.simulate`, step 1."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simfab.coupling import config as C
from simfab.coupling import rigid
from simfab.coupling.layout import add_point_blocks, diag_slots, point_dhat, regularize
from simfab.coupling.model import CouplingModel
from simfab.coupling.objective import StepObjective, pinned
from simfab.coupling.points import ContactPoints, row_norms
from simfab.coupling.state import StepContext, StepState
from simfab.coupling.timing import TimedSolver
from simfab.errors import ConvergenceError
from simfab.fem.elastic import det_F, energy_gradient_hessian


def lift_points(cm: CouplingModel, pts: ContactPoints, x: np.ndarray, obj: StepObjective, *, below: float,
                 to: float, prev: np.ndarray | None = None):
    """x with the constraint points at distance <= ``below`` [m] from O (inside it: d <= 0) moved
    out along O's normal to ``to`` [m], their facets' vertices taking the largest of the wanted
    moves (:func:`move_points`; a local move: the rest of A keeps its shape). With ``prev`` (k,), the points'
    gaps at the last step, points that were already that close keep their place. Returns x itself
    when nothing is that close, None when the result is infeasible."""
    # the objective's (lazy) distances: exact with gradients within its band (> below), lower
    # bounds without gradients beyond it, so only points near O are evaluated
    d, gd, _ = obj.distances(x, False)
    lift = (d <= below) & np.logical_or.reduce(gd != 0.0, axis=1)
    if prev is not None:
        lift &= prev > below
    if not lift.any():
        return x
    x1 = move_points(cm, pts, x, lift, (to[lift] if np.ndim(to) else to) - d[lift], gd[lift])
    return x1 if np.isfinite(obj.value(x1)) else None


def extrapolations(state: StepState, s_new: float) -> list:
    """Linear (last two steps) and quadratic (last three, Lagrange) extrapolations of A's
    positions to s_new: warm-start candidates when the deformation evolves smoothly. Where the
    last steps went back and forth (the rest search's bisection, :mod:`simfab.coupling.settle`)
    and s_new lies between two of the last three steps, their interpolations instead: the linear
    one between the nearest step on either side of s_new, and the quadratic one through all three
    (the trial's own previous state is usually on the far side of the bracket, a poor start alone)."""
    sign = state.direction  # extrapolate along the traversal's direction only
    if state.prev is None:
        return []
    if not (state.s - state.prev.s) * sign > 0:
        return interpolations(state, s_new)
    xp, sp_ = state.prev.x, state.prev.s
    out = [state.x + (state.x - xp) * ((s_new - state.s) / (state.s - sp_))]
    if state.prev2 is not None and (sp_ - state.prev2.s) * sign > 0:
        (x2, s2), (x1, s1), (xc, sc) = (state.prev2.x, state.prev2.s), (xp, sp_), (state.x, state.s)
        out.append(_lagrange(((x2, s2), (x1, s1), (xc, sc)), s_new))
    return out


def interpolations(state: StepState, s_new: float) -> list:
    """Linear interpolation between the nearest of the last three steps below and above s_new, and
    the quadratic one through all three when they are distinct (see :func:`extrapolations`); empty
    when s_new is not between two of them."""
    past = [(state.x, state.s), (state.prev.x, state.prev.s)]
    if state.prev2 is not None:
        past.append((state.prev2.x, state.prev2.s))
    below = [p for p in past if p[1] < s_new]
    above = [p for p in past if p[1] > s_new]
    if not below or not above:
        return []
    (xa, sa), (xb, sb) = max(below, key=lambda p: p[1]), min(above, key=lambda p: p[1])
    out = [xa + (xb - xa) * ((s_new - sa) / (sb - sa))]
    if len(past) == 3 and len({p[1] for p in past}) == 3:
        out.append(_lagrange(past, s_new))
    return out


def _lagrange(past, t: float) -> np.ndarray:
    """The quadratic Lagrange polynomial through three (x, s) pairs (distinct s), at s = t."""
    (x2, s2), (x1, s1), (xc, sc) = past
    l2 = (t - s1) * (t - sc) / ((s2 - s1) * (s2 - sc))
    l1 = (t - s2) * (t - sc) / ((s1 - s2) * (s1 - sc))
    lc = (t - s2) * (t - s1) / ((sc - s2) * (sc - s1))
    return l2 * x2 + l1 * x1 + lc * xc


#: Two steps are of equal length within this fraction (a planned path's steps are, to round-off; the
#: rest search's and a bisection's are not): see :func:`_continued`.
UNIFORM_STEP_REL = 1e-6


@dataclass(frozen=True, eq=False)
class WarmStart:
    """A step's warm start: x (n, dim) [m] the positions Newton starts from; source: "linear" or
    "quadratic" (an extrapolation of the last steps), "rest" (A's rest shape, offered when no point
    was within d_hat at the last step), "coarse" or "coarse increment" (a coarser run's candidates,
    :class:`simfab.coupling.guide.CoarseGuide`) or "predictor" (the contact predictor);
    snapped: the candidate with its contact gaps restored (None when there was no contact to
    restore, or when restoring them was infeasible)."""

    x: np.ndarray
    source: str
    snapped: np.ndarray | None


def resting_start(cm: CouplingModel, state: StepState, obj: StepObjective) -> np.ndarray | None:
    """A's positions when A rests out of O's reach over the step, else None: A is at its rest shape (the
    elastic energy's minimum), no constraint point was within its d_hat of O at the step's start, and
    none is in O's new pose (the objective's lazily bounded distances, exact within its band). The
    barrier and friction then vanish at x and x is the step's solution: Newton confirms it without an
    iteration, and the warm start's candidates (each of them A's rest shape here) need no evaluation:
    O's approach before the first contact, and a part that O has left."""
    ev = state.current_evaluation()
    if ev is None or not np.array_equal(state.x, cm.fem.rest):
        return None
    dhat = point_dhat(cm, state.points)
    if not (ev.distances >= dhat).all():
        return None
    d, _, _ = obj.distances(state.x, False)
    return state.x if (d >= dhat).all() else None


def warm_start(cm: CouplingModel, state: StepState, s_new: float, obj: StepObjective, ctx: StepContext) -> WarmStart:
    """The warm start: the feasible candidate with the lowest objective among the linear and quadratic
    extrapolations of the last steps, A's rest shape when no point was within d_hat at the last step
    and, with a guide (``ctx.guide``, forward along a frictionless insertion), a coarser run's two
    candidates with the points inside O lifted out (:class:`simfab.coupling.guide.CoarseGuide`), or
    the contact predictor (:func:`predict`) when no candidate is feasible, with its contact gaps
    restored (:func:`snap_contacts`: the predictor's pushes also carry contact points along chords of
    O's curved surface) and near points lifted. Where restoring the gaps is infeasible (points new to
    the contact carried into O), the lowest of every candidate restored with those points lifted out
    (:func:`_restored`).

    A step that continues a run of equal steps whose last one started from the quadratic extrapolation
    (``state.start``) takes it again, its gaps restored, after one evaluation that finds it feasible
    (:func:`_continued`): the candidates' contest is held again otherwise.
    Raises ConvergenceError when no candidate is feasible."""
    best_x, best_f, source = None, np.inf, "predictor"
    cands = list(zip(extrapolations(state, s_new), ("linear", "quadratic")))
    ev = state.current_evaluation()
    in_contact = ev is None or (ev.distances < point_dhat(cm, state.points)).any()
    if not in_contact:
        # out of contact A relaxes toward its rest shape (its only equilibrium without O): where contact
        # ends, an extrapolation carries the last steps' release of the deformation past it
        cands.append((cm.fem.rest.copy(), "rest"))
    guided = ctx.guide is not None and state.direction > 0 and cm.contact.friction == 0
    if guided:
        for xc, kind in zip(ctx.guide.candidates(state.x, state.s, s_new), ("coarse", "coarse increment")):
            xc = lift_points(cm, state.points, xc, obj, below=0.0, to=C.LIFT_TO * obj.dhat)
            if xc is not None:
                cands.append((xc, kind))
    if in_contact and not guided:
        xs = _continued(cm, state, s_new, cands, obj, ctx)
        if xs is not None:
            return _lifted(cm, state, obj, xs, "quadratic", xs)
    for xc, kind in cands:
        fc = obj.value(xc)
        if np.isfinite(fc) and fc < best_f:
            best_x, best_f, source = xc, fc, kind
    if best_x is None:
        best_x = predict(cm, state, s_new, obj, ctx)
    xs = snap_contacts(cm, state, best_x, s_new, ctx)
    if xs is not None and not np.isfinite(obj.value(xs)):  # (+inf: infeasible, inside O or inverted)
        # restoring the gaps carried points that were not in contact into O (where the contact spreads):
        # lift those out, from every candidate, and take the lowest; a start that keeps only the contacts
        # it is given costs Newton a capped iteration for every few points it finds again
        every = cands + ([(best_x, source)] if source == "predictor" else [])
        xs, kind = _restored(cm, state, every, s_new, obj, ctx)
        source = kind or source
    if xs is not None:
        best_x = xs
    if source.startswith("coarse"):
        ctx.guided += 1
    return _lifted(cm, state, obj, best_x, source, xs)


def _lifted(cm: CouplingModel, state: StepState, obj: StepObjective, x: np.ndarray, source: str,
            snapped: np.ndarray | None) -> WarmStart:
    """The warm start from the chosen candidate x with its points that came within
    WARM_START_FLOOR * d_hat of O (and were not that close at the last step) lifted to LIFT_TO * d_hat:
    a point that ends up almost touching O costs one Newton iteration per doubling of its distance
    (the log barrier)."""
    ev = state.current_evaluation()
    prev = ev.distances if ev is not None else None
    xl = lift_points(cm, state.points, x, obj, below=C.WARM_START_FLOOR * obj.dhat,
                     to=C.LIFT_TO * obj.dhat, prev=prev)
    return WarmStart(x=x if xl is None else xl, source=source, snapped=snapped)


def _continued(cm: CouplingModel, state: StepState, s_new: float, cands: list, obj: StepObjective,
               ctx: StepContext) -> np.ndarray | None:
    """The quadratic extrapolation with its contact gaps restored (:func:`snap_contacts`) when the step
    continues a run of equal steps (the same length and direction as the last) whose last one started
    from it and it is feasible, else None (the caller holds the contest of every candidate).

    Along a smooth profile the quadratic extrapolation wins that contest step after step (cclamp2d:
    every planned step from the fourth to the seat), and the contest costs two objective evaluations
    more than this check (the linear extrapolation's and the unrestored winner's: about a tenth of a
    Newton iteration each). Measured over 26 untuned runs (docs/decisions.md): the warm starts'
    objective evaluations 2,751 -> 1,644, Newton iterations 2,718 -> 2,722."""
    if state.start != "quadratic" or state.prev is None or len(cands) != 2 or cands[1][1] != "quadratic":
        return None
    h, h_last = s_new - state.s, state.s - state.prev.s
    if not abs(h - h_last) <= UNIFORM_STEP_REL * abs(h):
        return None
    xs = snap_contacts(cm, state, cands[1][0], s_new, ctx)
    return xs if xs is not None and np.isfinite(obj.value(xs)) else None


def _restored(cm: CouplingModel, state: StepState, cands: list, s_new: float, obj: StepObjective,
              ctx: StepContext) -> tuple:
    """(x, kind): the feasible one with the lowest objective of the candidates ``cands`` ((x, kind) pairs)
    with their contact gaps restored (:func:`snap_contacts`) and then their points inside O lifted out to
    LIFT_TO * d_hat; (None, None) when none is feasible."""
    best, best_kind, best_f = None, None, np.inf
    for xc, kind in cands:
        xs = snap_contacts(cm, state, xc, s_new, ctx)
        xs = None if xs is None else lift_points(cm, state.points, xs, obj, below=0.0, to=C.LIFT_TO * obj.dhat)
        fs = np.inf if xs is None else obj.value(xs)
        if fs < best_f:
            best, best_kind, best_f = xs, kind, fs
    return best, best_kind


def snap_contacts(cm: CouplingModel, state: StepState, x: np.ndarray, s_new: float,
                  ctx: StepContext) -> np.ndarray | None:
    """x with the boundary vertices that were in contact at the end of the last step (d < d_hat)
    moved along O's normal back to their last distance to O, or None when there are none (the
    caller checks feasibility: the move may push a neighbour into O or invert an element).

    The barrier acts only within d_hat and is much stiffer than A, so the equilibrium gaps of
    contact points lie in a narrow range inside (0, d_hat). An extrapolated warm start slides
    contact points along O's curved surface by chords and typically carries them just past d_hat:
    contact is lost, and the first Newton step, which no longer sees O there, releases A's
    deformation into O (the step cap then cuts it to a few percent). Restoring the last gaps keeps
    those points in the barrier's range; the rest of A is left to Newton.
    """
    ev = state.current_evaluation()
    pts = state.points
    if ev is None:
        return None
    d_prev = ev.distances
    act = d_prev < point_dhat(cm, pts)
    if not act.any():
        return None
    R, p = cm.pose(s_new)
    with ctx.timer.timed("contact_field"):
        ev_o = cm.field.evaluate(pts.positions(x)[act], (R, p), hessian=False)
    return move_points(cm, pts, x, act, (d_prev[act] + ev_o.psi) * ev_o.near, -ev_o.grad)


def move_points(cm: CouplingModel, pts: ContactPoints, x: np.ndarray, sel: np.ndarray, dist: np.ndarray,
                 direction: np.ndarray) -> np.ndarray:
    """x with the points ``sel`` moved by ``dist`` (s,) [m] along ``direction`` (s, dim) (normalized
    here; positive: away from O). Each vertex carrying selected points moves along the weighted mean
    of their directions by the largest of their moves, so no point on it is carried closer to O
    than it asks (the mean of the moves would carry a vertex point that wants a small move toward O
    between refinement points that want larger ones into O)."""
    nrm = direction / np.maximum(row_norms(direction)[:, None], 1e-300)
    rows = sel.nonzero()[0]
    n = cm.fem.n_vertices
    on = pts.weights[rows] > 0
    far = np.full(n, -np.inf)
    np.maximum.at(far, pts.verts[rows][on], dist[on.nonzero()[0]])  # (each point's move, once per parent)
    hit = np.isfinite(far)
    mean = pts.scatter(nrm, n, rows=rows)[hit]
    x1 = x.copy()
    x1[hit] += far[hit, None] * mean / np.maximum(row_norms(mean)[:, None], 1e-300)
    return x1




def predict(cm: CouplingModel, state: StepState, s_new: float, obj: StepObjective, ctx: StepContext) -> np.ndarray:
    """Feasible warm start at s_new (see the module docstring, step 1).

    Points O can reach during the step (distance below L |O's displacement there| + d_hat) are
    pushed along O's normal (they may slide tangentially, as in frictionless contact); the rest of A
    follows through one linear solve with the previous tangent stiffness. Each point moves by what O's
    normal displacement n . delta takes out of its gap d beyond LIFT_TO * d_hat,
    n . delta - max(d - LIFT_TO d_hat, 0) where positive (pushing every reachable point by n . delta
    over-deforms A where O arrives within the step: cclamp2d's first contact started Newton at 7x the
    step's energy). Where that push leaves an element below PREDICTOR_DENT_J of its volume (a deep
    overlap met by a few points: a point load's dent) or is infeasible, the push of every reachable
    point by n . delta (the contact region moves as one) is solved too and the lower objective kept.
    Points still inside O after a push are carried fully (rigidly with O) and its solve is repeated;
    as a last resort every reachable point is carried rigidly.
    """
    x = state.x
    dim = cm.dim
    Ra, pa = cm.pose(state.s)
    M = cm.motion(state.s, s_new)[0]  # O's rotation over the step

    pts = state.points
    y = pts.positions(x)
    with ctx.timer.timed("contact_field"):
        ev_a = cm.field.evaluate(y, (Ra, pa), hessian=False)
    delta = cm.carry(y, state.s, s_new) - y
    reach = (-ev_a.psi < C.PSI_LIPSCHITZ * np.linalg.norm(delta, axis=1) + point_dhat(cm, pts)) & ev_a.near
    if not reach.any():
        return x.copy()
    # O's outward normal at each point, carried with O to the new pose
    g = -ev_a.grad
    nrm = g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-300)
    nrm = nrm @ M[:dim, :dim].T
    push = np.einsum("kd,kd->k", nrm, delta)
    need = push - np.maximum(-ev_a.psi - C.LIFT_TO * point_dhat(cm, pts), 0.0)
    x0 = _pushed(cm, state, pts, s_new, reach, reach & (need > 0), nrm, delta, nrm * need[:, None], ctx)
    with ctx.timer.timed("assembly"):
        dent = x0 is not None and float(det_F(cm.fem, x0).min()) < C.PREDICTOR_DENT_J
    if x0 is None or dent:
        x1 = _pushed(cm, state, pts, s_new, reach, reach & (push > 0), nrm, delta, delta, ctx)
        if x0 is None or (x1 is not None and obj.value(x1) < obj.value(x0)):
            x0 = x1
    if x0 is not None:
        return x0
    x0 = penalty_solve(cm, state, x, pts, np.zeros_like(reach), reach, nrm, delta, ctx)
    d_new = feasible_distances(cm, x0, s_new, pts, ctx)
    if d_new is not None and np.all(d_new > 0):
        return x0
    raise ConvergenceError(f"no feasible warm start for the step to s={s_new:.6g} m")


def _pushed(cm, state, pts, s_new, reach, normal, nrm, delta, target, ctx) -> np.ndarray | None:
    """The penalty solve moving the points ``normal`` along ``nrm`` by n . target (k, dim), with the points
    still inside O afterwards carried rigidly with O (by ``delta``) and the solve repeated (everything
    reachable once an element inverts), at most PREDICTOR_RETRIES times; None when no solve is feasible."""
    full = np.zeros(len(pts), dtype=bool)
    for _ in range(C.PREDICTOR_RETRIES + 1):
        x0 = penalty_solve(cm, state, state.x, pts, normal & ~full, full, nrm,
                           np.where(full[:, None], delta, target), ctx)
        d_new = feasible_distances(cm, x0, s_new, pts, ctx)
        if d_new is not None and np.all(d_new > 0):
            return x0
        if d_new is None:
            full |= reach  # an element inverted: carry everything reachable rigidly
            continue
        bad = (d_new <= 0) & ~full
        if not bad.any():
            return None
        full |= bad
    return None


def restore_feasibility(cm: CouplingModel, state: StepState, ctx: StepContext) -> None:
    """Push constraint points that are inside O at (state.x, state.s) (by at most the tolerance)
    out along O's normal to d_hat / 2, A following through the penalty solve."""
    R, p = cm.pose(state.s)
    pts = state.points
    for _ in range(C.PREDICTOR_RETRIES + 1):
        ev = cm.field.evaluate(pts.positions(state.x), (R, p), hessian=False)
        d = -ev.psi
        bad = d <= 0
        if not bad.any():
            return
        g = -ev.grad
        nrm = g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-300)
        delta = (0.5 * point_dhat(cm, pts) - np.minimum(d, 0.0))[:, None] * nrm
        x1 = penalty_solve(cm, state, state.x, pts, bad, np.zeros_like(bad), nrm, delta, ctx)
        if feasible_distances(cm, x1, state.s, pts, ctx) is None:
            break
        state.x = x1
    raise ConvergenceError(f"could not push the new refinement points out of the object at s={state.s:.6g} m")


def feasible_distances(cm, x0, s, pts, ctx):
    """Distances to O at s if x0 has no inverted element, else None."""
    with ctx.timer.timed("assembly"):
        ok = np.all(det_F(cm.fem, x0) > 0)
    if not ok:
        return None
    R, p = cm.pose(s)
    with ctx.timer.timed("contact_field"):
        ev = cm.field.evaluate(pts.positions(x0), (R, p), hessian=False)
    return -ev.psi


def penalty_solve(cm, state, x, pts, normal, full, nrm, delta, ctx) -> np.ndarray:
    """x + u, u minimizing 1/2 u^T H u + P/2 sum_j c_j(u)^2 over the free dofs, with
    c_j = n_j . (y_j(u) - delta_j) for ``normal`` points and |y_j(u) - delta_j| for ``full`` ones."""
    n, dim = cm.fem.n_vertices, cm.dim
    H = state.tangent
    if callable(H):  # the PSD tangent is assembled only when the predictor runs
        H = state.tangent = H()
    if H is None:
        with ctx.timer.timed("assembly"):
            _, _, H = energy_gradient_hessian(cm.fem, x)
            regularize(cm, H)
        state.tangent = H
    pen = C.PREDICTOR_PENALTY * float(np.abs(H.data[diag_slots(cm)]).max())
    sel = normal | full
    N = np.zeros((len(pts), dim, dim))
    N[normal] = np.einsum("ki,kj->kij", nrm[normal], nrm[normal])
    N[full] = np.eye(dim)
    N = N[sel]
    A = cm.fem.pattern.matrix(H.data.copy())
    add_point_blocks(cm, pts, A, np.flatnonzero(sel), pen * N)
    f_pt = pen * np.einsum("kij,kj->ki", N, delta[sel])  # penalty force per point
    rhs = pts.scatter(f_pt, n, rows=np.flatnonzero(sel)).ravel()
    fidx = np.flatnonzero(cm.free)
    pin = rigid.pin_for(cm, state.pin_basis, rigid.motion_basis(cm)[1], x)
    uf = TimedSolver(pinned(ctx.solver, pin), ctx.timer).solve_free(A, fidx, rhs[fidx])
    u = np.zeros(n * dim)
    u[fidx] = uf
    return x + u.reshape(n, dim)
