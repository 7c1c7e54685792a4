"""Static equilibrium of rod networks with rigid bodies (Newton with line search).

Unknowns ``q`` (all in length units so one tolerance fits all): free node coordinates [m], free
twist angles times ``model.length_scale`` [m], and per free rigid body its translation [m] and
rotation-vector update times ``length_scale``.

``q`` is an *increment* from a base state: node coordinates and angles add, bodies move as
``c = c0 + dc``, ``R = exp(w) R0``. Attached nodes follow their bodies (``x = c + R p``), clamped
edges take the body's material frame, reference directors are time-parallel transported from the
base (:func:`simfab.rods.model.synchronize`).

The reduced gradient and Hessian are exact at ``q = 0``: ``g_q = J^T g`` with ``J = dx/dq``, and
``H_q = J^T H J`` plus the geometric term of the attached nodes, ``1/2 (g r^T + r g^T) - (g.r) I``
per node (``r`` its world offset). A clamped edge's angle changes by ``t . w`` (swing-twist
decomposition, no second-order term).

Newton iteration (own loop, not :func:`simfab.solve.newton.minimize`): after every accepted step
the state becomes the new base, so reference directors are transported *between Newton iterates*
and ``q`` restarts at 0 (transporting from an older base would make the gradient inexact and
Newton linear in 3D). Each iteration: shifted-Cholesky solve (:class:`ShiftedCholesky`), step
capped by ``max_step``, Armijo backtracking on the total potential; converged when
``||g_q||_inf <= grad_tol * force_scale`` (or the step / the predicted decrease reach round-off),
else ConvergenceError. Full notes: docs/methods.md, "simfab.rods.statics".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from simfab.errors import ConvergenceError
from simfab.rods.energy import Evaluator
from simfab.rods.model import RodModel, RodState, synchronize
from simfab.rotations import expmap, skew
from simfab.solve.banded import BandedOrSparseCholesky, ShiftedCholesky  # noqa: F401 (used and re-exported)
from simfab.solve.linear import NotPositiveDefinite, SPDSolver


@dataclass(frozen=True, kw_only=True)
class StaticsConfig:
    """Tolerances of the static solver (the one place they live for rods).

    grad_tol : equilibrium residual ||g_q||_inf <= grad_tol * model.force_scale [N]. The
        residual moves a rod by about grad_tol * L, far below discretization errors.
    step_tol : a full Newton step below step_tol * (longest rod) [m] (taken) also counts as
        converged: with stiff stretching (EA L^2 / B ~ 1e8) the residual's round-off floor
        can lie above grad_tol * force_scale while the configuration no longer changes.
    max_iter : Newton iterations per solve.
    max_step : largest change of any unknown per Newton step, in units of the longest rod
        (keeps the first iterations of a buckling step from overshooting).
    armijo, max_backtracks : sufficient-decrease constant and backtracking limit.
    roundoff : relative energy change below which f cannot resolve a decrease; such a step
        is accepted when it reduces the residual.
    stretch_homotopy : when set, every solve first relaxes with all axial stiffnesses EA
        scaled by this factor (to ``homotopy_grad_tol``), then solves the real problem from
        there. Nearly inextensible rods (EA L^2 / B ~ 1e8) make Newton's quadratic model poor
        far from equilibrium (small transverse moves stretch edges at second order); the
        softened problem gets close cheaply (fewer iterations for the elastica, docs/decisions.md;
        it does not help networks whose nonlinearity is not axial, hence off by default). Only the
        final, unscaled solve is reported.
    """

    grad_tol: float = 1e-8
    step_tol: float = 1e-11
    max_iter: int = 200
    max_step: float = 0.05
    armijo: float = 1e-4
    max_backtracks: int = 40
    roundoff: float = 1e-12
    stretch_homotopy: float | None = None
    homotopy_grad_tol: float = 1e-3


class Reduction:
    """Map between reduced unknowns ``q`` and full DOFs ``[x (3N), theta (E)]`` (see module doc)."""

    def __init__(self, model: RodModel):
        self.model = model
        N, E = model.n_nodes, model.n_edges
        self.n_full = 3 * N + E
        free_x = (model.node_body[:, None] < 0) & ~model.node_fixed
        self.x_dofs = np.flatnonzero(free_x.ravel())
        self.th_edges = np.flatnonzero((model.edge_body < 0) & ~model.theta_fixed)
        self.bodies = np.flatnonzero(~model.body_driven)
        self.ell = model.length_scale
        nx, nt = len(self.x_dofs), len(self.th_edges)
        self.nq = nx + nt + 6 * len(self.bodies)
        body_col0 = nx + nt + 6 * np.arange(len(self.bodies))  # first q column of each free body
        # translation columns of the free bodies, (Bf*3,) in the order of ``bodies``
        self.body_trans_cols = (body_col0[:, None] + np.arange(3)).ravel()
        # constant part of J: q column i (free coordinate / scaled angle) -> full DOF full_index[i],
        # factor full_scale[i]
        self.full_index = np.concatenate([self.x_dofs, 3 * N + self.th_edges])
        self.full_scale = np.concatenate([np.ones(nx), np.full(nt, 1.0 / self.ell)])
        # no free bodies: J is a constant selection and scaling (fast path)
        self.simple = len(self.bodies) == 0
        self._blk = None
        # attached nodes / clamped edges of the free bodies, flattened for one vectorized J assembly:
        # global index, position of the body in ``bodies`` and the body's first column in q
        k_of = np.full(model.n_bodies + 1, -1)  # last entry: "no body" (index -1)
        k_of[self.bodies] = np.arange(len(self.bodies))
        cols0 = np.full(model.n_bodies + 1, -1, dtype=np.int64)
        cols0[self.bodies] = body_col0
        self._jn = np.flatnonzero(k_of[model.node_body] >= 0)
        self._jn_k = k_of[model.node_body[self._jn]]
        self._jn_c = cols0[model.node_body[self._jn]]
        self._je = np.flatnonzero(k_of[model.edge_body] >= 0)
        self._je_c = cols0[model.edge_body[self._je]]

    def block(self, H: sp.csr_matrix) -> sp.csr_matrix:
        """``D H[idx][:, idx] D`` for the fast path (index map cached per CSR pattern)."""
        if self._blk is None or self._blk[0] is not H.indices and not np.array_equal(self._blk[0], H.indices):
            n = H.shape[0]
            new = np.full(n, -1, dtype=np.int64)
            new[self.full_index] = np.arange(len(self.full_index))
            rows = np.repeat(np.arange(n), np.diff(H.indptr))
            keep = (new[rows] >= 0) & (new[H.indices] >= 0)
            r, c = new[rows[keep]], new[H.indices[keep]]
            order = np.lexsort((c, r))
            sel = np.flatnonzero(keep)[order]
            scale = self.full_scale[r[order]] * self.full_scale[c[order]]
            indptr = np.concatenate([[0], np.cumsum(np.bincount(r, minlength=self.nq))]).astype(np.int32)
            self._blk = (H.indices, sel, scale, c[order].astype(np.int32), indptr)
        _, sel, scale, idx, indptr = self._blk
        return sp.csr_matrix((H.data[sel] * scale, idx, indptr), shape=(self.nq, self.nq))

    def split(self, q):
        nx, nt = len(self.x_dofs), len(self.th_edges)
        body = q[nx + nt:].reshape(-1, 6)
        return q[:nx], q[nx:nx + nt] / self.ell, body[:, :3], body[:, 3:] / self.ell

    def apply(self, base: RodState, q: np.ndarray) -> RodState:
        """State at increment ``q`` from ``base``."""
        dx, dth, dc, dw = self.split(q)
        x = base.x.copy().ravel()
        x[self.x_dofs] += dx
        theta = base.theta.copy()
        theta[self.th_edges] += dth
        pos, rot = base.body_pos.copy(), base.body_rot.copy()
        if len(self.bodies):
            pos[self.bodies] += dc
            rot[self.bodies] = expmap(dw) @ rot[self.bodies]
        return synchronize(self.model, base, x.reshape(-1, 3), theta, pos, rot)

    def jacobian(self, state: RodState) -> sp.csr_matrix:
        """J = d(full DOFs)/dq at ``q = 0`` around ``state`` (the solver re-bases after every step,
        so the rotation increments are zero and exp's left Jacobian is the identity)."""
        rows, cols, vals = [self.full_index], [np.arange(len(self.full_index))], [self.full_scale]
        N = self.model.n_nodes
        three = np.arange(3)
        if len(self.bodies):
            nodes, k, c0 = self._jn, self._jn_k, self._jn_c
            if len(nodes):
                r = state.x[nodes] - state.body_pos[self.bodies[k]]
                rr = (3 * nodes[:, None] + three).ravel()
                # translation: identity blocks
                rows.append(rr)
                cols.append((c0[:, None] + three).ravel())
                vals.append(np.ones(len(rr)))
                # rotation: dx = w x r = -[r]x w, w = (scaled unknown) / ell
                blk = -skew(r) / self.ell  # (m,3,3)
                rows.append(np.repeat(rr, 3))
                cols.append(np.broadcast_to(c0[:, None, None] + 3 + three, blk.shape).ravel())
                vals.append(blk.reshape(-1))
            edges, c0 = self._je, self._je_c
            if len(edges):
                blk = state.t[edges] / self.ell  # (m,3): dtheta = t . w
                rows.append(np.repeat(3 * N + edges, 3))
                cols.append((c0[:, None] + 3 + three).ravel())
                vals.append(blk.reshape(-1))
        return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                             shape=(self.n_full, self.nq))

    def geometric(self, state: RodState, g: np.ndarray) -> sp.csr_matrix | None:
        """Second-order term of the body rotations acting on attached-node forces ``g``: per
        attached node ``1/2 (g r^T + r g^T) - (g.r) I`` on its body's rotation block (summed by
        the sparse assembly), all nodes of all free bodies at once."""
        nodes, k, c0 = self._jn, self._jn_k, self._jn_c
        if not len(nodes):
            return None
        r = state.x[nodes] - state.body_pos[self.bodies[k]]
        gn = g[: 3 * self.model.n_nodes].reshape(-1, 3)[nodes]
        gr = gn[:, :, None] * r[:, None, :]  # (m,3,3): g r^T
        G = 0.5 * (gr + gr.transpose(0, 2, 1)) - np.sum(gn * r, axis=1)[:, None, None] * np.eye(3)
        c = c0[:, None] + 3 + np.arange(3)  # (m,3): the body's rotation columns
        rows = np.repeat(c, 3, axis=1)  # row-major (i, j) -> (c_i, c_j)
        cols = np.tile(c, (1, 3))
        return sp.csr_matrix((G.reshape(-1) / self.ell**2, (rows.ravel(), cols.ravel())), shape=(self.nq, self.nq))


@dataclass
class StaticResult:
    """Converged equilibrium.

    Args:
        state: the equilibrium :class:`RodState`.
        energy: total potential energy [J].
        iterations: Newton iterations.
        grad_norm: the residual's infinity norm [N].
        parts: elastic energy per term (stretch, bend, twist, ...) [J].
        history: per Newton iteration: (energy [J], ||g||_inf [N], step fraction alpha); None unless recorded.
    """

    state: RodState
    energy: float
    iterations: int
    grad_norm: float
    parts: dict
    history: list = None  # per Newton iteration: (energy [J], ||g||_inf [N], step fraction alpha)


class StaticSolver:
    """Equilibrium solves of one model (keeps the Warp buffers and the Cholesky analysis).

    Loads: ``node_forces`` (N,3) [N] act on nodes (potential ``-f.x``); ``body_forces``
    (B,3) [N] act on body origins.
    """

    def __init__(self, model: RodModel, *, device: str = "cpu", options: StaticsConfig = StaticsConfig()):
        self.model = model
        self.options = options
        self.evaluator = Evaluator(model, device=device)
        self.red = Reduction(model)
        self.linear = ShiftedCholesky()
        self._definiteness = SPDSolver()  # unshifted factorizations for is_stable (pattern analysis reused)
        self.length = max(float(np.sum(model.rest_len[r.edges])) for r in model.rods)
        self._last = None  # (state, node_forces, body_forces, reduced Hessian) of the last converged solve

    # -- objective in reduced unknowns -----------------------------------------------------
    def objective(self, st: RodState, need_grad: bool, need_hess: bool, node_forces, body_forces):
        """Total potential, reduced gradient and Hessian at ``st`` (q = 0 around ``st``)."""
        E, g, H = self.evaluator(st, need_grad or need_hess, need_hess)
        if node_forces is not None:
            E -= float(np.sum(node_forces * st.x))
        if body_forces is not None and len(self.red.bodies):
            E -= float(np.sum(body_forces[self.red.bodies] * st.body_pos[self.red.bodies]))
        if not (need_grad or need_hess):
            return E, None, None
        if node_forces is not None:
            g[: 3 * self.model.n_nodes] -= node_forces.ravel()
        if self.red.simple:
            gq = g[self.red.full_index] * self.red.full_scale
            Hq = self.red.block(H) if need_hess else None
            return E, gq, Hq
        J = self.red.jacobian(st)
        gq = J.T @ g
        if body_forces is not None:
            gq[self.red.body_trans_cols] -= body_forces[self.red.bodies].ravel()
        Hq = None
        if need_hess:
            Hq = (J.T @ H @ J).tocsr()
            G = self.red.geometric(st, g)
            if G is not None:
                Hq = Hq + G
        return E, gq, Hq

    def solve(self, state: RodState, *, node_forces=None, body_forces=None, monitor=None) -> StaticResult:
        """Equilibrium reached from ``state`` (prescribed values already set, e.g. by :func:`prescribe`).
        ``monitor(iteration, iterate)``, when given, is called at every Newton iterate of the final
        (unscaled) solve that is not yet converged; an exception it raises abandons the solve."""
        opts = self.options
        nf = None if node_forces is None else np.asarray(node_forces, dtype=np.float64)
        bf = None if body_forces is None else np.asarray(body_forces, dtype=np.float64)
        if self.red.nq == 0:
            E, _, _ = self.evaluator(state, False, False)
            return StaticResult(state, E, 0, 0.0, dict(self.evaluator.parts), [])
        extra = 0
        if opts.stretch_homotopy is not None:
            self.evaluator.buf.set_stretch_scale(opts.stretch_homotopy)
            try:
                pre = self._newton(state, nf, bf, opts.homotopy_grad_tol)
                state, extra = pre.state, pre.iterations
            except ConvergenceError:
                pass  # the softened stage is only a predictor; solve the real problem from the start
            finally:
                self.evaluator.buf.set_stretch_scale(1.0)
        res = self._newton(state, nf, bf, opts.grad_tol, monitor)
        res.iterations += extra
        return res

    def _newton(self, state: RodState, nf, bf, grad_tol: float, monitor=None) -> StaticResult:
        opts = self.options
        gtol = grad_tol * self.model.force_scale
        cap = opts.max_step * self.length
        st = state
        E, gq, Hq = self.objective(st, True, True, nf, bf)
        gnorm = float(np.max(np.abs(gq)))
        if not (np.isfinite(E) and np.isfinite(gnorm)):
            raise ConvergenceError("rod equilibrium: energy or forces are not finite at the start state")
        hist = [(E, gnorm, 0.0)]
        for it in range(opts.max_iter + 1):
            if gnorm <= gtol:
                self._last = (st, nf, bf, Hq)
                return StaticResult(st, E, it, gnorm, dict(self.evaluator.parts), hist)
            if it == opts.max_iter:
                break
            if monitor is not None:
                monitor(it, st)
            d = -self.linear.solve(Hq, gq)
            slope = float(gq @ d)
            if not slope < 0.0:
                d, slope = -gq, -float(gq @ gq)
            dmax = float(np.max(np.abs(d)))
            alpha = min(1.0, cap / dmax) if dmax > 0 else 1.0
            accepted = False
            for _ in range(opts.max_backtracks):
                trial = self.red.apply(st, alpha * d)
                Et, _, _ = self.objective(trial, False, False, nf, bf)
                if np.isfinite(Et) and Et <= E + opts.armijo * alpha * slope:
                    accepted = True
                    break
                if np.isfinite(Et) and abs(Et - E) <= opts.roundoff * max(abs(E), 1e-300):
                    # f cannot resolve the decrease: accept when the residual drops
                    _, gt, _ = self.objective(trial, True, False, nf, bf)
                    if float(np.max(np.abs(gt))) < gnorm:
                        accepted = True
                        break
                alpha *= 0.5
            if not accepted:
                raise ConvergenceError(f"rod equilibrium: line search failed at Newton iteration {it + 1} "
                                       f"(||g||_inf = {gnorm:.3e} N, target {gtol:.3e} N)")
            st = trial
            E, gq, Hq = self.objective(st, True, True, nf, bf)
            gnorm = float(np.max(np.abs(gq)))
            if not np.isfinite(gnorm):
                raise ConvergenceError(f"rod equilibrium: forces became non-finite at Newton iteration {it + 1}")
            hist.append((E, gnorm, alpha))
            if dmax <= opts.step_tol * self.length:  # the full Newton step itself is at round-off
                return StaticResult(st, E, it + 1, gnorm, dict(self.evaluator.parts), hist)
        raise ConvergenceError(f"rod equilibrium did not converge in {opts.max_iter} Newton iterations "
                               f"(||g||_inf = {gnorm:.3e} N > target {gtol:.3e} N)")

    def set_attachment_offsets(self, node_offset: np.ndarray) -> None:
        """Move attachment points within their bodies (N,3) [m] (e.g. beam ends drawn onto an
        insert's edge in increments). Topology and stiffness are unchanged."""
        import dataclasses

        self.model = dataclasses.replace(self.model, node_offset=np.asarray(node_offset, dtype=np.float64))
        self.red.model = self.model
        self._last = None  # a cached Hessian belongs to the old offsets

    def offset_sensitivity(self, state: RodState, d_offset, *, node_forces=None, body_forces=None) -> np.ndarray:
        """Derivative dq/dp (nq,) or (nq,k) of the equilibrium ``state`` with respect to parameters p
        that move attachment points within their bodies, ``node_offset = offset + sum_j p_j D_j``;
        ``d_offset``: D (N,3) [m per unit p] or a sequence of k of them.

        Implicit function theorem: the equilibrium satisfies g_q(q*(p), p) = 0, so
        H_q dq*/dp = -dg_q/dp with the reduced Hessian H_q at the equilibrium (shifted if indefinite,
        see :class:`ShiftedCholesky`; one factorization for all k right-hand sides when it is
        positive definite). dg_q/dp is the
        central difference of the exact reduced gradient in p, step h = 1e-6 x length_scale / max|D|
        (the gradient is smooth in the offsets; the O(h^2) error is far below the Newton tolerance).
        Directions whose effects on g_q cannot overlap share one pair of gradient evaluations
        (Curtis-Powell-Reid grouping): D_j moves full DOFs m_j, which change the full gradient on the
        rows coupled to them by the Hessian's pattern and the reduced gradient on the columns of J
        those rows reach (support S_j); directions are coloured greedily so that supports in one
        colour are disjoint, and each colour's difference is split by the supports (a grid of inserts
        needs 2-4 colours instead of k).
        The returned increments are applied with the offsets moved accordingly (``set_attachment_offsets``
        then ``Reduction.apply``)."""
        D = np.asarray(d_offset, dtype=np.float64)
        single = D.ndim == 2
        D = D[None] if single else D
        nf = None if node_forces is None else np.asarray(node_forces, dtype=np.float64)
        bf = None if body_forces is None else np.asarray(body_forces, dtype=np.float64)
        base = self.model
        last = self._last

        def same(a, b):
            return (a is None and b is None) or (a is not None and b is not None and np.array_equal(a, b))

        cached = last if last is not None and last[0] is state and same(last[1], nf) and same(last[2], bf) else None
        if len(D) == 1:  # one direction: nothing to group
            supports = [np.arange(self.red.nq)]
        else:
            supports = self._offset_supports(state, D)
        colours: list[list[int]] = []
        used: list[np.ndarray] = []
        for j, S in enumerate(supports):
            for c, u in enumerate(used):
                if not np.any(u[S]):
                    colours[c].append(j)
                    u[S] = True
                    break
            else:
                colours.append([j])
                u = np.zeros(self.red.nq, dtype=bool)
                u[S] = True
                used.append(u)
        B = np.zeros((self.red.nq, len(D)))
        try:
            for members in colours:
                Dc = D[members].sum(axis=0)
                h = 1e-6 * base.length_scale / (float(np.max(np.abs(Dc))) or 1.0)
                gs = []
                for sgn in (1.0, -1.0):
                    self.set_attachment_offsets(base.node_offset + sgn * h * Dc)
                    st = synchronize(self.model, state, state.x, state.theta, state.body_pos, state.body_rot)
                    gs.append(self.objective(st, True, False, nf, bf)[1])
                diff = (gs[0] - gs[1]) / (2.0 * h)
                for j in members:
                    B[supports[j], j] = diff[supports[j]]
        finally:
            self.set_attachment_offsets(base.node_offset)
        if cached is not None:
            Hq = cached[3]  # the converged Newton iterate's own Hessian (same state, loads and offsets)
        else:
            _, _, Hq = self.objective(state, True, True, nf, bf)
        try:
            dq = -np.asarray(self._definiteness.solve(Hq, B)).reshape(self.red.nq, len(D))
        except NotPositiveDefinite:  # unstable equilibrium: the shifted solve, column by column
            dq = -np.stack([self.linear.solve(Hq, B[:, j]) for j in range(len(D))], axis=1)
        return dq[:, 0] if single else dq

    def _offset_supports(self, state: RodState, D: np.ndarray) -> list[np.ndarray]:
        """Per direction D_j (N,3): the reduced-gradient entries (indices into q) that moving the
        attachment offsets along D_j can change (see :meth:`offset_sensitivity`)."""
        _, _, H = self.evaluator(state, False, True)
        Hp = sp.csr_matrix((np.ones(H.nnz, dtype=np.int8), H.indices, H.indptr), shape=H.shape)
        n_full = self.red.n_full
        if self.red.simple:
            col = np.full(n_full, -1)
            col[self.red.full_index] = np.arange(len(self.red.full_index))
        else:
            J = self.red.jacobian(state).tocsr()
            Jp = sp.csr_matrix((np.ones(J.nnz, dtype=np.int8), J.indices, J.indptr), shape=J.shape)
        out = []
        for Dj in D:
            moved = np.flatnonzero(np.abs(Dj).ravel() > 0)  # full DOFs 3 n + c of the moved nodes
            rows = np.zeros(n_full, dtype=bool)
            rows[moved] = True
            rows[np.unique(Hp[:, moved].tocoo().row)] = True if len(moved) else False
            f = np.flatnonzero(rows)
            if self.red.simple:
                S = col[f][col[f] >= 0]
            else:
                S = np.unique(Jp[f].tocoo().col)
            out.append(S.astype(np.int64))
        return out

    def reduced_system(self, state: RodState):
        """(gradient (nq,), Hessian CSR (nq,nq)) of the elastic energy in reduced unknowns at ``state``."""
        _, gq, Hq = self.objective(state, True, True, None, None)
        return gq, Hq

    def is_stable(self, state: RodState) -> bool:
        """True when the reduced Hessian at ``state`` is positive definite (Cholesky succeeds)."""
        _, H = self.reduced_system(state)
        try:
            self._definiteness.solve(H, np.ones(H.shape[0]))
            return True
        except NotPositiveDefinite:
            return False

    def reactions(self, state: RodState) -> np.ndarray:
        """Full elastic gradient (3N+E,) at ``state``: on fixed/attached DOFs the force (N) / moment
        (N m) the rods exert is ``-g``."""
        _, g, _ = self.evaluator(state, True, False)
        return g


def prescribe(model: RodModel, state: RodState, *, x=None, theta=None, body_pos=None, body_rot=None) -> RodState:
    """Set prescribed values (fixed node coordinates, fixed angles, driven body poses) and
    synchronize frames from ``state``. Arguments are full arrays; only prescribed entries are
    taken from them (``body_*`` for driven bodies only)."""
    nx = state.x.copy()
    if x is not None:
        nx[model.node_fixed] = np.asarray(x, dtype=np.float64)[model.node_fixed]
    th = state.theta.copy()
    if theta is not None:
        th[model.theta_fixed] = np.asarray(theta, dtype=np.float64)[model.theta_fixed]
    pos, rot = state.body_pos.copy(), state.body_rot.copy()
    drv = model.body_driven
    if body_pos is not None:
        pos[drv] = np.asarray(body_pos, dtype=np.float64)[drv]
    if body_rot is not None:
        rot[drv] = np.asarray(body_rot, dtype=np.float64)[drv]
    return synchronize(model, state, nx, th, pos, rot)
