"""Pattern tuned by simulation: the insert gaps adjusted so that the deployed shape matches the target.

The gap rule (:mod:`simfab.deploy.pattern`) is first order in the cell size and ignores the
network's bending: the deployed shape misses the target where the rods cannot follow the metric
(steep caps, boundary cells). Here the growth of each insert, ``d_i = r_i - g_i`` [m], is the
unknown of a least-squares problem on the deployed shape itself.

Residual (point to plane, the quantity the deviation's RMS measures): after the best rigid
alignment (R, t) of the deployed vertices X (n,3) onto the target, ``e_j = n_j . (R x_j + t - c_j)``
with c_j the closest target point and n_j its face normal (both held fixed in one step).

Sensitivities (implicit function theorem): the equilibrium q*(d) satisfies g_q(q*, d) = 0, so
``dq*/dd_i = -H_q^{-1} dg_q/dd_i`` with the reduced Hessian at the equilibrium, one factorization
for all inserts (:meth:`simfab.rods.statics.StaticSolver.offset_sensitivity`, checked against
re-solved equilibria in tests/deploy). Growing insert i moves its beam ends' clamp points
outwards along the beams by d_i, i.e. the parameter is the clamp offset; a changed gap g_i also
changes the flat beam's length by the same amount, so at the end the re-cut pattern's own
equilibrium is solved from the tuned state (:func:`redeploy`) and the reported shape is the
re-cut pattern's.

Step (Levenberg-Marquardt): ``(J^T J + mu I) delta = -J^T e`` with J = n^T R dX/dd (n, k) and mu
= ``damping`` x the largest diagonal of J^T J (the inserts far from the boundary barely move the
aligned shape's normal distance; mu keeps their steps bounded); d + delta is clipped into the
achievable range ``min_gap <= r_i - d_i <= h_i/2 - min_beam``; the new equilibrium is solved from
the tangent prediction q + dq*/dd delta; a step that does not lower the RMS is halved (up to 3 times),
else the tuning stops.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from simfab.deploy.compare import kabsch
from simfab.deploy.network import Deployment
from simfab.errors import ConvergenceError, InputError
from simfab.rods.model import synchronize
from simfab.rods.statics import StaticSolver


@dataclass(frozen=True, kw_only=True)
class TuneConfig:
    """Scene ``[tune]`` table. iterations: Gauss-Newton steps (0: no tuning); damping [-]:
    Levenberg-Marquardt mu relative to the largest diagonal of J^T J."""

    iterations: int = 0
    damping: float = 1e-3

    def __post_init__(self):
        if isinstance(self.iterations, bool) or not isinstance(self.iterations, int) or self.iterations < 0:
            raise InputError(f"must be a non-negative integer (got {self.iterations!r})", where="tune.iterations")
        if isinstance(self.damping, bool) or not isinstance(self.damping, (int, float)) or not (
                np.isfinite(self.damping) and self.damping > 0):
            raise InputError(f"must be a positive number (got {self.damping!r})", where="tune.damping")


@dataclass
class Tuning:
    """Result: tuned gaps (n,) [m] (0 on the boundary), the tuned equilibrium (a RodState of the
    network it was computed on), point-to-plane RMS per accepted iterate [m] (first: before
    tuning), Gauss-Newton steps taken, equilibrium solves, seconds."""

    gap: np.ndarray
    state: object
    rms_history: list
    steps: int
    solves: int
    seconds: float


def _closest(target, A):
    import trimesh

    tm = trimesh.Trimesh(target.V, target.F, process=False)
    C, dist, tri = trimesh.proximity.closest_point(tm, A)
    return C, tm.face_normals[tri]


def _residual(X, Y, target):
    """(e (n,), R, N (n,3)): point-to-plane residuals after the Kabsch + ICP alignment."""
    R, t = kabsch(X, Y)
    for _ in range(10):  # ICP to the surface (as the deviation measure)
        C, N = _closest(target, X @ R.T + t)
        R, t = kabsch(X, C)
    A = X @ R.T + t
    C, N = _closest(target, A)
    return np.einsum("ij,ij->i", N, A - C), R, N


def achievable_growth(pat) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) (n,) [m]: the growth d = r - g each insert can take with its size r, from the gap
    range min_gap <= g <= h_i/2 - min_beam (h_i: mean flat length of its edges)."""
    pc = pat.config
    elen = np.linalg.norm(pat.P[pat.edges[:, 0]] - pat.P[pat.edges[:, 1]], axis=1)
    val = np.bincount(pat.edges.ravel(), minlength=len(pat.P))
    hv = np.bincount(pat.edges.ravel(), weights=np.repeat(elen, 2), minlength=len(pat.P)) / np.maximum(val, 1)
    gmax = 0.5 * hv - pc.min_beam if pat.gap_max is None else pat.gap_max  # (the layout's: seams, short edges)
    return pat.insert_size - gmax, pat.insert_size - pc.min_gap


def tune(pat, net, dep, Y: np.ndarray, target, cfg: TuneConfig, *, device: str = "cpu") -> Tuning:
    """Tune the gaps of ``pat`` from its deployment ``dep`` (network ``net``) towards ``target`` with
    correspondences Y (n,3) (see module doc). Returns the tuned gaps; the caller re-cuts and
    re-deploys."""

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
    solver = StaticSolver(model, device=device)
    solver.set_attachment_offsets(offsets(d))
    state = dep.final
    pos_of = {int(b): i for i, b in enumerate(solver.red.bodies)}
    rows = solver.red.body_trans_cols.reshape(-1, 3)[[pos_of[int(b)] for b in net.vertex_body]]  # (n,3)
    e, R, N = _residual(state.body_pos[net.vertex_body], Y, target)
    hist = [float(np.sqrt(np.mean(e**2)))]
    steps = solves = 0
    for _ in range(cfg.iterations):
        dq = solver.offset_sensitivity(state, D)  # (nq, k)
        dX = dq[rows]  # (n, 3, k)
        J = np.einsum("nj,jl,nlk->nk", N, R, dX)
        A = J.T @ J
        mu = cfg.damping * float(np.max(np.diag(A)))
        step = -np.linalg.solve(A + mu * np.eye(len(ins)), J.T @ e)
        d_try = d.copy()
        accepted = False
        alpha = 1.0
        for _ in range(4):
            d_try[ins] = np.clip(d[ins] + alpha * step, lo[ins], hi[ins])
            solver.set_attachment_offsets(offsets(d_try))
            st = solver.red.apply(state, dq @ (d_try[ins] - d[ins]))
            try:
                res = solver.solve(st)
                solves += 1
            except ConvergenceError:
                alpha *= 0.5
                continue
            e_try, R_try, N_try = _residual(res.state.body_pos[net.vertex_body], Y, target)
            rms = float(np.sqrt(np.mean(e_try**2)))
            if rms < hist[-1]:
                accepted = True
                break
            alpha *= 0.5
        if not accepted:
            solver.set_attachment_offsets(offsets(d))
            break
        d, state, e, R, N = d_try.copy(), res.state, e_try, R_try, N_try
        hist.append(rms)
        steps += 1
    gap = np.where(pat.interior, pat.insert_size - d, 0.0)
    return Tuning(gap=gap, state=state, rms_history=hist, steps=steps, solves=solves,
                  seconds=time.perf_counter() - t0)


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
