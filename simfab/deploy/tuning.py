"""Pattern tuned by simulation: the insert gaps adjusted so that the deployed shape matches the target.

The gap rule (:mod:`simfab.deploy.pattern`) is first order in the cell size and ignores the
network's bending; here the growth of each insert, ``d_i = r_i - g_i`` [m], is the unknown of a
least-squares problem on the deployed shape itself. Residual: the distance to the surface stacked
with a weighted point-to-point term towards each vertex's own target point y_j,

    e = [ |R x_j + t - c_j| ,  sqrt(w) (R x_j + t - y_j) ,  sqrt(w_h n) s(H(x) - H(y)) ]   (n + 3n + 1 rows),

E = |e|^2 / 2, c_j the closest target point, w = ``point_weight``, H the out-of-plane extent
(:func:`simfab.deploy.compare.out_of_plane_extent`, the deployed height the bounds read; its maximum
and minimum smoothed as softmax-weighted means over ``HEIGHT_SMOOTHING`` of the height), w_h = ``height_weight``,
s(x) = sign(x) max(|x| - tol, 0) with tol = ``target_height`` x H(y) (the height row acts only on a
height outside the stop's tolerance), (R, t) the ICP alignment minimising the same E (H is invariant
under it, so dE/d(R, t) = 0 and the Gauss-Newton gradient J^T e needs no alignment term).

Sensitivities (implicit function theorem): ``dq*/dd_i = -H_q^{-1} dg_q/dd_i`` at the equilibrium,
one factorization for all inserts (:meth:`simfab.rods.statics.StaticSolver.offset_sensitivity`).
Step (Levenberg-Marquardt): ``(J^T J + mu I) delta = -J^T e``, mu = ``damping`` x the largest
diagonal of J^T J, d + delta clipped into the achievable range ``min_gap <= r_i - d_i <= h_i/2 -
min_beam``, halved while it does not lower E (a trial whose Newton iterates' E rises above the accepted
one's is rejected before it converges), then retried with mu x 10 (``escalations``).
After every step the pattern is re-cut and its own equilibrium solved (:func:`tune_pattern`,
:func:`redeploy`); the tuning stops at the deviation bound, when progress stalls, at its budget or
when no step lowers E. The full derivation: docs/methods.md, "simfab.deploy.tuning".
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np
import trimesh

from simfab.deploy.compare import deviation, height_error, kabsch, out_of_plane_extent
from simfab.deploy.network import Deployment, build_network
from simfab.errors import ConvergenceError, InputError
from simfab.rods.model import synchronize
from simfab.rods.statics import StaticsConfig, StaticSolver

ESCALATION_FACTOR = 10.0  # mu's factor per escalation (TuneConfig.escalations)
#: Newton iterations a trial equilibrium of :func:`tune` may take before the trial is abandoned like one
#: that does not converge (the step halved). The static solver's own limit: the iteration counts of
#: rejected and accepted trials overlap, so no shorter cap separates them (docs/decisions.md,
#: "Deployment tuning: where its time goes")
TRIAL_NEWTON_ITERATIONS = 200
HALVINGS = 4  # trials per escalation: the step, then halved three times
#: :func:`tune_pattern` starts a step this many trials before the one its last step was accepted at (a
#: step up to 4 x as long; one before cut a saddle's long second step short: docs/decisions.md,
#: "Deployment tuning: where its time goes")
RESTART_BACK = 2
#: a trial's equilibrium solve is checked every this many Newton iterations: it is rejected early when the
#: objective E at the iterate is above (1 + ``EARLY_REJECT_MARGIN``) x the accepted one's and higher than at
#: the previous check (its fit getting worse, away from the accepted state: docs/decisions.md,
#: "Deployment tuning: rejecting a trial early"); an accepted trial is always a converged solve
FIT_CHECK_ITERATIONS = 10
EARLY_REJECT_MARGIN = 0.05
#: consecutive steps each gaining less than ``min_gain`` that stop the tuning (progress stalled): one short
#: step is often the damping adapting, with long ones after it (docs/validation/deploy.md)
STALL_STEPS = 2
HEIGHT_SMOOTHING = 0.003  # the height row's smoothing tau, relative to the target points' height


@dataclass(frozen=True, kw_only=True)
class TuneConfig:
    """Scene ``[tune]`` table. iterations: Gauss-Newton steps (0: no tuning); damping [-]: Levenberg-Marquardt mu
    relative to the largest diagonal of J^T J; point_weight [-]: w, the weight of the point-to-point residual
    towards each vertex's own target point against the distance to the surface (0: fit the surface only; at w =
    1 a vertex 1 mm from its own target point weighs as much as one 1 mm off the surface). The point term also
    pulls on tangential offsets the gaps cannot remove (a network whose deployed metric is off along the
    surface), so it is a per-scene choice (scenes/deploy/README.md). escalations: how many times a step whose
    halvings all fail to lower E is retried with mu x ``ESCALATION_FACTOR`` (a shorter step turned towards the
    gradient) before the tuning stops (0: stop at the first such step). Stops, each 0 for none: target_rms [-]:
    the RMS distance of the deployed vertices to the surface over the target's diameter at which the tuning
    stops (the bound is met); min_gain [-]: it stops when ``STALL_STEPS`` steps in a row each lower the
    objective by less than this fraction (progress stalls); seconds: the time budget (no step starts after it).
    The bound is measured as the deployment's deviation is (the RMS distance after the alignment to the surface
    alone, :func:`simfab.deploy.compare.deviation`), not by the tuning's own objective; target_height [-]: with
    ``target_rms``, the bound is met only once the deployed out-of-plane height is also within this fraction of
    the target's (0: not checked); height_weight [-]: w_h, the weight of the height row (the deployed
    out-of-plane extent against the target's, beyond ``target_height`` of it): at w_h = 1 a height 1 mm beyond
    that weighs as much as every vertex 1 mm off the surface (0: no height row; the surface distance alone
    leaves the height free where the shape can bend within it)."""

    iterations: int = 0
    damping: float = 1e-3
    point_weight: float = 0.0
    escalations: int = 0
    target_rms: float = 0.0
    min_gain: float = 0.0
    seconds: float = 0.0
    target_height: float = 0.0
    height_weight: float = 0.0

    def __post_init__(self):
        for f in ("target_rms", "min_gain", "seconds", "target_height", "height_weight"):
            v = getattr(self, f)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (np.isfinite(v) and v >= 0):
                raise InputError(f"must be a non-negative number (got {v!r})", where=f"tune.{f}")
        if isinstance(self.iterations, bool) or not isinstance(self.iterations, int) or self.iterations < 0:
            raise InputError(f"must be a non-negative integer (got {self.iterations!r})", where="tune.iterations")
        if isinstance(self.damping, bool) or not isinstance(self.damping, (int, float)) or not (
                np.isfinite(self.damping) and self.damping > 0):
            raise InputError(f"must be a positive number (got {self.damping!r})", where="tune.damping")
        if isinstance(self.point_weight, bool) or not isinstance(self.point_weight, (int, float)) or not (
                np.isfinite(self.point_weight) and self.point_weight >= 0):
            raise InputError(f"must be a non-negative number (got {self.point_weight!r})", where="tune.point_weight")
        if isinstance(self.escalations, bool) or not isinstance(self.escalations, int) or self.escalations < 0:
            raise InputError(f"must be a non-negative integer (got {self.escalations!r})", where="tune.escalations")


@dataclass
class Tuning:
    """Result: tuned gaps (n,) [m] (0 on the boundary), the tuned equilibrium (a RodState of the
    network it was computed on), per accepted iterate (first: before tuning) the RMS distance to the
    surface [m] (``rms_history``) and the RMS distance to the vertices' own target points [m]
    (``point_rms_history``), Gauss-Newton steps taken, equilibrium solves (converged trials), seconds,
    trials abandoned (not converged within ``TRIAL_NEWTON_ITERATIONS``), the last accepted step's trial
    (:func:`tune`), trials rejected early by their fit check (:data:`FIT_CHECK_ITERATIONS`), the trials'
    Newton iterations."""

    gap: np.ndarray
    state: object
    rms_history: list
    point_rms_history: list
    steps: int
    solves: int
    seconds: float
    abandoned: int = 0
    trial: int = 0
    rejected_early: int = 0
    newton_iterations: int = 0


class _RejectedEarly(Exception):
    """A trial's equilibrium solve stopped by its fit check (:data:`FIT_CHECK_ITERATIONS`)."""

    def __init__(self, iterations: int):
        super().__init__(iterations)
        self.iterations = iterations


class _FitCheck:
    """The fit check of a trial's Newton iterates (a :meth:`StaticSolver.solve` monitor): every
    :data:`FIT_CHECK_ITERATIONS` iterations, E at the iterate (vertex positions ``X_of(state)``); it
    raises :class:`_RejectedEarly` when E is above (1 + :data:`EARLY_REJECT_MARGIN`) x ``accepted_cost``
    and above E at the previous check (evaluated only then); with ``reject`` False it only counts.
    ``iterations``: the last iterate it saw."""

    def __init__(self, X_of, Y: np.ndarray, target, cfg: TuneConfig, accepted_cost: float, *, reject: bool = True):
        self.X_of, self.Y, self.target, self.cfg, self.accepted = X_of, Y, target, cfg, accepted_cost
        self.reject = reject
        self.previous = None  # the previous check's iterate, or its E once evaluated
        self.iterations = 0

    def _cost(self, state) -> float:
        return _fit(self.X_of(state), self.Y, self.target, self.cfg).cost

    def __call__(self, it: int, state) -> None:
        self.iterations = it
        if not self.reject or it % FIT_CHECK_ITERATIONS:
            return
        prev, self.previous = self.previous, state
        if prev is None:
            return
        c = self.previous = self._cost(state)
        if c > (1.0 + EARLY_REJECT_MARGIN) * self.accepted and c > (prev if isinstance(prev, float) else
                                                                      self._cost(prev)):
            raise _RejectedEarly(it)


@dataclass(frozen=True)
class Fit:
    """The tuning's residual at deployed vertices X (see module doc): e (4n + 1,) [m] (n distances to the
    surface, then the 3n weighted point-to-point rows, vertex-major, then the weighted height row), the
    alignment R (3,3), t (3,), the unit directions N (n,3) from the closest points (the distances'
    gradients), the point weight w, the objective E = |e|^2 / 2 [m^2], the RMS distance to the surface
    [m] (``plane_rms``), the RMS distance of the aligned vertices to their target points [m], the height
    weight w_h and the gradient of the deployed height H over the aligned vertices (n,3) [-]."""

    e: np.ndarray
    R: np.ndarray
    t: np.ndarray
    N: np.ndarray
    point_weight: float
    cost: float
    plane_rms: float
    point_rms: float
    height_weight: float = 0.0
    height_grad: np.ndarray = None


def _closest(tm, A):
    C, _, tri = trimesh.proximity.closest_point(tm, A)
    return C, tm.face_normals[tri]


def fit_residual(X: np.ndarray, Y: np.ndarray, target, point_weight: float, *, height_weight: float = 0.0,
                 height_tolerance: float = 0.0, icp_iters: int = 30) -> Fit:
    """Residual of deployed vertices X (n,3) [m] against the target surface (``target.V``, ``target.F``),
    the vertices' target points Y (n,3) [m] and the target points' height (``height_weight``, beyond
    ``height_tolerance`` of it), after the
    alignment that minimises the same objective (ICP from the Kabsch fit onto Y, until E changes by less
    than 1e-12 relative)."""
    tm = trimesh.Trimesh(target.V, target.F, process=False)
    w = float(point_weight)
    R, t = kabsch(X, Y)
    prev = np.inf
    for _ in range(icp_iters):
        A = X @ R.T + t
        C, _ = _closest(tm, A)
        E = float(np.sum((A - C) ** 2) + w * np.sum((A - Y) ** 2))
        if abs(prev - E) <= 1e-12 * max(E, 1e-300):
            break
        prev = E
        R, t = kabsch(X, (C + w * Y) / (1.0 + w))
    A = X @ R.T + t
    C, N = _closest(tm, A)
    dist = np.linalg.norm(A - C, axis=1)
    far = dist > 1e-12 * target.diameter
    N[far] = (A - C)[far] / dist[far, None]  # grad of the distance (the face normal inside a face)
    wh = float(height_weight)
    tau = HEIGHT_SMOOTHING * (out_of_plane_extent(Y) or target.diameter)
    H, G = _height_and_gradient(A, tau)
    HY = _height_and_gradient(Y, tau)[0]
    dh = H - HY
    tol = height_tolerance * HY
    dh, G = np.sign(dh) * max(abs(dh) - tol, 0.0), G * float(abs(dh) > tol)
    e = np.concatenate([dist, np.sqrt(w) * (A - Y).ravel(), [np.sqrt(wh * len(A)) * dh]])
    return Fit(e=e, R=R, t=t, N=N, point_weight=w, cost=0.5 * float(e @ e), plane_rms=float(np.sqrt(np.mean(dist**2))),
               point_rms=float(np.sqrt(np.mean(np.sum((A - Y) ** 2, axis=1)))), height_weight=wh, height_grad=G)


def _fit(X: np.ndarray, Y: np.ndarray, target, cfg: TuneConfig) -> Fit:
    """:func:`fit_residual` with the weights and height tolerance of ``cfg``."""
    return fit_residual(X, Y, target, cfg.point_weight, height_weight=cfg.height_weight,
                        height_tolerance=cfg.target_height)


def _height_and_gradient(A: np.ndarray, tau: float) -> tuple[float, np.ndarray]:
    """The out-of-plane extent of points A (n,3) [m], smoothed: H = M - m, M = sum p_j z_j and m = sum q_j z_j
    the softmax-weighted means (p = softmax(z / tau), q = softmax(-z / tau)) of z_j = (a_j - mean) . n along
    their best-fit plane's normal n: the extent's maximum and minimum, smooth where extreme points tie (a
    symmetric saddle's corners, a cap's rim) and, unlike log-sum-exp, not shifted by the number of points
    that tie (each within tau of the true extreme, exact where they tie); and dH/da_j (n,3): w_j n, w_j =
    p_j (1 + (z_j - M) / tau) - q_j (1 - (z_j - m) / tau), plus the normal's turn, dn = -sum_k v_k (v_k^T dC n)
    / (s_k^2 - s_3^2) (first-order perturbation of the smallest eigenvector of C = A_c^T A_c, v_k its other
    eigenvectors, s the singular values)."""
    Ac = A - A.mean(axis=0)
    _, sv, Vt = np.linalg.svd(Ac, full_matrices=False)
    n = Vt[2]
    z = Ac @ n
    p, q = np.exp((z - z.max()) / tau), np.exp((z.min() - z) / tau)
    p, q = p / p.sum(), q / q.sum()
    top, bottom = float(p @ z), float(q @ z)
    H = top - bottom
    w = p * (1.0 + (z - top) / tau) - q * (1.0 - (z - bottom) / tau)
    G = w[:, None] * n[None, :]
    span = w @ Ac
    for k in (0, 1):  # v_k^T dC n = sum_j (v_k . da_j) z_j + (a_j . v_k)(n . da_j)
        gap = sv[k] ** 2 - sv[2] ** 2
        if gap > 0:
            c = float(span @ Vt[k]) / gap
            G -= c * (z[:, None] * Vt[k][None, :] + (Ac @ Vt[k])[:, None] * n[None, :])
    return float(H), G


def fit_jacobian(fit: Fit, dX: np.ndarray) -> np.ndarray:
    """J (4n + 1, k) = de/dp of :func:`fit_residual` for vertex derivatives dX (n,3,k) [m per unit p],
    with the closest points, normals, alignment, best-fit plane and the height's extreme vertices held
    fixed (rows as ``fit.e``)."""
    RdX = np.einsum("jl,nlk->njk", fit.R, dX)  # (n,3,k)
    Jp = np.einsum("nj,njk->nk", fit.N, RdX)
    Jh = np.sqrt(fit.height_weight * len(dX)) * np.einsum("nj,njk->k", fit.height_grad, RdX)
    return np.concatenate([Jp, np.sqrt(fit.point_weight) * RdX.reshape(-1, dX.shape[2]), Jh[None, :]])


def achievable_growth(pat) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) (n,) [m]: the growth d = r - g each insert can take with its size r, from the gap
    range min_gap <= g <= h_i/2 - min_beam (h_i: mean flat length of its edges)."""
    pc = pat.config
    elen = np.linalg.norm(pat.P[pat.edges[:, 0]] - pat.P[pat.edges[:, 1]], axis=1)
    val = np.bincount(pat.edges.ravel(), minlength=len(pat.P))
    hv = np.bincount(pat.edges.ravel(), weights=np.repeat(elen, 2), minlength=len(pat.P)) / np.maximum(val, 1)
    gmax = 0.5 * hv - pc.min_beam if pat.gap_max is None else pat.gap_max  # (the layout's: seams, short edges)
    return pat.insert_size - gmax, pat.insert_size - pc.min_gap


def tune(pat, net, dep, Y: np.ndarray, target, cfg: TuneConfig, *, device: str = "cpu",
         first_trial: int = 0, early_reject: bool = True) -> Tuning:
    """Tune the gaps of ``pat`` from its deployment ``dep`` (network ``net``) towards ``target`` with
    correspondences Y (n,3) (see module doc). Returns the tuned gaps; the caller re-cuts and
    re-deploys.

    Trials in order (``trial`` = ``HALVINGS`` x escalation + halvings): the step at mu x
    ``ESCALATION_FACTOR``^k, then halved ``HALVINGS - 1`` times, for k = 0 .. ``cfg.escalations``;
    ``first_trial`` skips the first ones (the first step only: :func:`tune_pattern` starts a step
    ``RESTART_BACK`` trials before the one its last step was accepted at). ``Tuning.trial``: the
    accepted step's. ``early_reject``: trials may be abandoned by their fit check (:class:`_FitCheck`);
    when every trial is rejected and some early, the trials are solved again to equilibrium."""

    t0 = time.perf_counter()
    model = net.model
    ins = np.flatnonzero(pat.interior)
    d = pat.insert_size - pat.gap  # growth per vertex (0 on the boundary)
    lo, hi = achievable_growth(pat)
    offset0 = model.node_offset.copy() + (0.0 if net.tie_offset is None else net.tie_offset)  # seams closed

    def offsets(dv):
        o = offset0.copy()
        o[net.pull_nodes] += net.pull_dir * dv[net.pull_vertex][:, None]
        return o

    D = np.zeros((len(ins), *offset0.shape))
    col = {int(v): j for j, v in enumerate(ins)}
    for row, (n_, v) in enumerate(zip(net.pull_nodes, net.pull_vertex)):
        D[col[int(v)], n_] = net.pull_dir[row]
    solver = StaticSolver(model, device=device, options=StaticsConfig(max_iter=TRIAL_NEWTON_ITERATIONS))
    solver.set_attachment_offsets(offsets(d))
    state = dep.final
    pos_of = {int(b): i for i, b in enumerate(solver.red.bodies)}
    rows = solver.red.body_trans_cols.reshape(-1, 3)[[pos_of[int(b)] for b in net.vertex_body]]  # (n,3)
    fit = _fit(state.body_pos[net.vertex_body], Y, target, cfg)
    hist, phist = [fit.plane_rms], [fit.point_rms]
    steps = solves = abandoned = trial = early = newton = 0
    vertices = lambda st: st.body_pos[net.vertex_body]  # noqa: E731
    skip = min(int(first_trial), HALVINGS * (cfg.escalations + 1) - 1)
    for _ in range(cfg.iterations):
        dq = solver.offset_sensitivity(state, D)  # (nq, k)
        dX = dq[rows]  # (n, 3, k)
        J = fit_jacobian(fit, dX)
        A = J.T @ J
        d_try = d.copy()
        accepted = False
        # a step whose trials were all rejected, some early by their fit check, is searched again
        # with every trial solved to equilibrium: the tuning stops only on converged trials' fits
        for checked in (True, False):
            step_early = 0
            for k in range(skip // HALVINGS, cfg.escalations + 1):
                mu = cfg.damping * ESCALATION_FACTOR**k * float(np.max(np.diag(A)))
                step = -np.linalg.solve(A + mu * np.eye(len(ins)), J.T @ fit.e)
                h0 = skip % HALVINGS if k == skip // HALVINGS else 0
                alpha = 0.5**h0
                for h in range(h0, HALVINGS):
                    trial = HALVINGS * k + h
                    d_try[ins] = np.clip(d[ins] + alpha * step, lo[ins], hi[ins])
                    solver.set_attachment_offsets(offsets(d_try))
                    st = solver.red.apply(state, dq @ (d_try[ins] - d[ins]))
                    check = _FitCheck(vertices, Y, target, cfg, fit.cost, reject=checked and early_reject)
                    try:
                        res = solver.solve(st, monitor=check)
                        solves += 1
                        newton += res.iterations
                    except (ConvergenceError, _RejectedEarly) as err:  # the step too long: halved
                        # not converged (no equilibrium near the predictor), or its fit worse than the
                        # accepted one's and getting worse
                        step_early += isinstance(err, _RejectedEarly)
                        abandoned += isinstance(err, ConvergenceError)
                        newton += check.iterations + isinstance(err, ConvergenceError)
                        alpha *= 0.5
                        continue
                    fit_try = _fit(vertices(res.state), Y, target, cfg)
                    if fit_try.cost < fit.cost:
                        accepted = True
                        break
                    alpha *= 0.5
                if accepted:
                    break
            early += step_early
            if accepted or not step_early:
                break
        if not accepted:
            solver.set_attachment_offsets(offsets(d))
            break
        d, state, fit = d_try.copy(), res.state, fit_try
        skip = 0
        hist.append(fit.plane_rms)
        phist.append(fit.point_rms)
        steps += 1
    gap = np.where(pat.interior, pat.insert_size - d, 0.0)
    return Tuning(gap=gap, state=state, rms_history=hist, point_rms_history=phist, steps=steps, solves=solves,
                  seconds=time.perf_counter() - t0, abandoned=abandoned, trial=trial, rejected_early=early,
                  newton_iterations=newton)


def retuned_pattern(pat, gap: np.ndarray):
    """The pattern with the tuned gaps cut (springs, numbering and sizes unchanged)."""
    return dataclasses.replace(pat, gap=np.asarray(gap, dtype=np.float64))


def redeploy(pat, net, dep, tuned: Tuning, *, device: str = "cpu"):
    """The re-cut pattern's deployment: its network ``net`` (built from :func:`retuned_pattern`) at
    its deployed clamp offsets, in equilibrium from the tuned state (same topology, so the tuned
    node and body positions are its Newton start; only the beams' flat lengths differ, by the gap
    changes). The earlier increments of ``dep`` are kept for the USD timeline."""

    t0 = time.perf_counter()
    solver = StaticSolver(net.model, device=device)
    o = net.model.node_offset.copy() + (0.0 if net.tie_offset is None else net.tie_offset)
    o[net.pull_nodes] += net.pull_dir * net.pull_grow[:, None]
    solver.set_attachment_offsets(o)
    s = tuned.state
    try:
        res = solver.solve(synchronize(solver.model, s, s.x, s.theta, s.body_pos, s.body_rot))
    except ConvergenceError as e:
        raise ConvergenceError(f"re-cut pattern after tuning: {e}") from None
    return Deployment(network=net, states=[*dep.states[:-1], res.state], stable=bool(solver.is_stable(res.state)),
                      iterations=[*dep.iterations, res.iterations], energy=float(res.energy),
                      seconds=dep.seconds + tuned.seconds + time.perf_counter() - t0)


def bound_met(pat, dep, Y: np.ndarray, target, cfg: TuneConfig) -> bool:
    """Whether the deployment ``dep`` of ``pat`` meets the tuning's stop bound (``cfg.target_rms``, and
    ``cfg.target_height`` when set), measured as the run's deviation and height are."""
    if not cfg.target_rms:
        return False
    dv = deviation(dep.vertex_positions(), Y, pat.quads, target)
    if dv.rms > cfg.target_rms:
        return False
    if not cfg.target_height:
        return True
    return abs(height_error(dv.aligned, Y)) <= cfg.target_height


@dataclass
class TunedPattern:
    """Result of :func:`tune_pattern`: the last accepted re-cut pattern, its network and deployment;
    per accepted step (first: before tuning) the RMS distances to the surface and to the vertices'
    target points of the re-cut pattern's equilibrium [m]; steps, equilibrium solves (trial and
    re-cut), seconds; stop: why it stopped ("iterations", "bound met", "time budget", "progress
    stalled", "no step lowers the objective"); trials abandoned (:data:`TRIAL_NEWTON_ITERATIONS`), trials
    rejected early (:data:`FIT_CHECK_ITERATIONS`), Newton iterations (trials and re-cuts)."""

    pattern: object
    network: object
    deployment: Deployment
    rms_history: list
    point_rms_history: list
    steps: int
    solves: int
    seconds: float
    stop: str = "iterations"
    abandoned: int = 0
    rejected_early: int = 0
    newton_iterations: int = 0


@dataclass(frozen=True)
class _Step:
    """One accepted tuning step of :func:`tune_pattern`: its escalation k, the tuning, the re-cut
    pattern, its network, deployment and fit."""

    k: int
    tuned: Tuning
    pattern: object
    network: object
    deployment: object
    fit: Fit


def tune_pattern(pat, net, dep, Y: np.ndarray, target, cfg: TuneConfig, deploy_cfg, *, ties=None,
                 device: str = "cpu") -> TunedPattern:
    """Up to ``cfg.iterations`` Gauss-Newton steps (:func:`tune`, one at a time), each followed by
    the re-cut pattern (:func:`retuned_pattern`), its network (``deploy_cfg``, ``ties`` as built
    for ``net``) and its own equilibrium (:func:`redeploy`); a step whose re-cut equilibrium does not
    lower the objective E is retried with mu x ``ESCALATION_FACTOR`` (up to ``cfg.escalations``
    times), else the tuning stops (see module doc). Each step's trials start ``RESTART_BACK`` before the
    trial its last step was accepted at (Levenberg-Marquardt's damping kept between steps, loosened),
    all of them when none of those lowers E."""
    t0 = time.perf_counter()
    fit = _fit(dep.vertex_positions(), Y, target, cfg)
    hist, phist = [fit.plane_rms], [fit.point_rms]
    steps = solves = abandoned = early = newton = last = slow = 0
    stop = "iterations"
    for _ in range(cfg.iterations):
        if bound_met(pat, dep, Y, target, cfg):
            stop = "bound met"
            break
        if cfg.seconds and time.perf_counter() - t0 >= cfg.seconds:
            stop = "time budget"
            break
        def attempt(check: bool):
            """One tuning step (its re-cut escalated at mu x 10 when it does not lower E): the accepted
            :class:`_Step`, or None; adds to the run's counts."""
            nonlocal solves, abandoned, early, newton
            for k in range(cfg.escalations + 1):
                one = dataclasses.replace(cfg, iterations=1, damping=cfg.damping * ESCALATION_FACTOR**k,
                                          escalations=cfg.escalations - k)
                first = max(0, last - RESTART_BACK) if k == 0 else 0
                tuned = tune(pat, net, dep, Y, target, one, device=device, first_trial=first, early_reject=check)
                solves, abandoned = solves + tuned.solves, abandoned + tuned.abandoned
                early, newton = early + tuned.rejected_early, newton + tuned.newton_iterations
                if tuned.steps == 0 and first > 0:  # none of the shorter steps: the longer ones skipped too
                    tuned = tune(pat, net, dep, Y, target, one, device=device, early_reject=check)
                    solves, abandoned = solves + tuned.solves, abandoned + tuned.abandoned
                    early, newton = early + tuned.rejected_early, newton + tuned.newton_iterations
                if tuned.steps == 0:
                    return None
                pat2 = retuned_pattern(pat, tuned.gap)
                net2 = build_network(pat2, deploy_cfg, ties=ties)
                try:
                    dep2 = redeploy(pat2, net2, dep, tuned, device=device)
                except ConvergenceError:
                    continue
                solves += 1
                newton += dep2.iterations[-1]
                fit2 = _fit(dep2.vertex_positions(), Y, target, cfg)
                if fit2.cost < fit.cost:
                    return _Step(k, tuned, pat2, net2, dep2, fit2)
            return None

        got = attempt(True)
        # the tuning stalls only on trials solved to equilibrium: a step that gained too little after
        # rejecting longer trials early by their fit check is searched again without it (a step that
        # found nothing is, within :func:`tune`)
        short = got is not None and cfg.min_gain and 1.0 - got.fit.cost / fit.cost < cfg.min_gain
        if short and got.tuned.rejected_early:
            full = attempt(False)
            if full is not None and full.fit.cost < got.fit.cost:
                got = full
        if got is None:
            stop = "no step lowers the objective"
            break
        last = HALVINGS * got.k + got.tuned.trial
        gain = 1.0 - got.fit.cost / fit.cost if fit.cost > 0 else 0.0
        pat, net, dep, fit = got.pattern, got.network, got.deployment, got.fit
        hist.append(fit.plane_rms)
        phist.append(fit.point_rms)
        steps += 1
        slow = slow + 1 if cfg.min_gain and gain < cfg.min_gain else 0
        if slow >= STALL_STEPS:
            stop = "progress stalled"
            break
    if stop == "iterations" and bound_met(pat, dep, Y, target, cfg):
        stop = "bound met"
    return TunedPattern(pattern=pat, network=net, deployment=dep, rms_history=hist, point_rms_history=phist,
                        steps=steps, solves=solves, seconds=time.perf_counter() - t0, stop=stop, abandoned=abandoned,
                        rejected_early=early, newton_iterations=newton)
