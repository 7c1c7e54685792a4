"""The per-step objective E_d(x) + kappa sum_j b(d_j(x)) (+ the rigid-mode pin) and its Newton solve.

See :mod:`simfab.coupling.simulate` for the method. :class:`StepObjective` evaluates the objective
with lazy contact distances and caps Newton's steps so that no constraint point reaches O;
:func:`make_objective` builds it for a step, :func:`solve` runs the barrier Newton,
:func:`evaluation` reads Newton's converged evaluation as an :class:`~simfab.coupling.state.Evaluation`
and :func:`adapt_kappa` stiffens the barrier for the following steps."""

from __future__ import annotations

import math

import numpy as np

from simfab.contact.barrier import barrier_value, point_barrier, project_psd
from simfab.coupling import config as C
from simfab.coupling import rigid
from simfab.coupling.friction import FrictionLag
from simfab.coupling.layout import add_point_blocks, point_dhat, regularize
from simfab.coupling.model import CouplingModel
from simfab.coupling.points import ContactPoints
from simfab.coupling.state import Evaluation, StepContext, StepState
from simfab.coupling.timing import TimedSolver, Timer
from simfab.fem.elastic import energy, energy_gradient, energy_gradient_hessian
from simfab.solve.newton import NewtonConfig, minimize


def _equal(a: np.ndarray, b: np.ndarray) -> bool:
    """``np.array_equal(a, b)`` for two arrays (the memo checks of every evaluation: without its dispatch)."""
    return a.shape == b.shape and np.count_nonzero(a != b) == 0


class StepObjective:
    """E_d(x) + kappa sum_j b(d_j(x)) (+ the lagged friction potential D(x)) for a fixed pose of O and a
    fixed set of constraint points; called as Newton's objective ``obj(x, need_hessian)``.

    Args:
        cm: the coupling model.
        points: the constraint points on A's boundary.
        R: O's rotation (dim, dim) at the step's pose.
        p: O's position (dim,) [m].
        timer: where the evaluations' time books.
        kappa: barrier stiffness [N/m] (None: the model's initial one).
        pin: pin of the rigid motions nothing resists (:class:`simfab.coupling.rigid.Pin`), or None.
        friction: the lagged friction over the step (:mod:`simfab.coupling.friction`), or None.
    """

    def __init__(self, cm: CouplingModel, points: ContactPoints, R: np.ndarray, p: np.ndarray, timer: Timer,
                 kappa: float | None = None, pin: rigid.Pin | None = None, friction: FrictionLag | None = None):
        self.cm, self.points, self.R, self.p, self.timer = cm, points, R, p, timer
        self.pin = pin  # pin of the rigid motions nothing resists (simfab.coupling.rigid.Pin), or None
        if friction is not None and friction.points is not points:
            raise ValueError("the friction lag belongs to another set of constraint points")
        self.friction = friction  # lagged friction over the step (simfab.coupling.friction), or None
        self.kappa = cm.kappa if kappa is None else float(kappa)
        self.n, self.dim = cm.fem.n_vertices, cm.dim
        self.last_x = None
        self.last_d = None
        self.last_gd = None
        self.last_H = None
        self.last_fem = None
        self.last_barrier = None
        self.curv = 1.0 / cm.field.sigma  # curvature bound for max_step until a Hessian evaluation sets it
        # Lazy evaluation: psi is L-Lipschitz, so a point that was at distance d_ref when last
        # evaluated exactly (at y_ref) is still at least d_ref - L |y - y_ref| away. Points whose
        # bound stays above the band need no evaluation (their barrier term is exactly zero).
        self.dhat = point_dhat(cm, points)  # (k,) activation distance per point [m]
        self.dhat_max = float(self.dhat.max()) if len(self.dhat) else cm.dhat
        self.band = C.LAZY_BAND_DHATS * self.dhat
        self.y_ref = None
        self.d_ref = None
        self.memo = None  # (x, (f, g, H)) of the last Hessian evaluation, reused once
        # (x, d, grad d, the points' positions y, the points evaluated exactly) of the last evaluation
        # without Hessians (e.g. a warm start's value, then its lift, then Newton's start): the same x
        # gives the same distances until the lazy bounds are re-anchored
        self._distances = None
        self.anchored = None  # see distances
        # Newton's Hessians within a solve are assembled when Newton asks for them (linear elements,
        # see _DeferredHessian); set by solve after the start's evaluation
        self.defer_hessian = False
        self._curv_from = None  # a _DeferredHessian whose curvature bound curv awaits
        # P2: the exact Hessian too is assembled on demand (LazyHessian), so that Newton, once it
        # has stopped offering it (NewtonConfig.retry_exact), assembles the projected one only; the
        # elastic energy and gradient then come from a gradient launch (~1/15 of a Hessian's),
        # reused from the line-search trial at the same positions (_fem: (x, E, gradient))
        self.lazy_exact = cm.fem.element_order == 2
        self._fem = None
        # ... except at a solve's start when Newton will offer the exact Hessian (set by solve for
        # that one evaluation): one Hessian launch gives the energy and gradient too (bit for bit those
        # of the gradient launch), instead of a gradient launch now and a Hessian launch at the first
        # Newton direction
        self.eager_exact = False

    def distances(self, x: np.ndarray, hessian: bool, anchor: bool | None = None):
        """Distances of the constraint points to O: exact near O, lower bounds (zero derivatives) for points
        certified farther than the band.

        Args:
            x: positions (n, dim) [m].
            hessian: also the distances' Hessians.
            anchor: re-anchor the lazy bounds at x (None: with ``hessian``, which marks Newton's
                iterates); without ``hessian`` the points evaluated exactly are kept in ``anchored``
                ((their positions (t, dim), their indices (t,))) for :class:`_DeferredHessian`.

        Returns:
            (d (k,) [m], grad d (k, dim), hess d (k, dim, dim) [1/m] or None).
        """
        anchor = hessian if anchor is None else anchor
        memo = self._distances
        if not hessian and memo is not None and _equal(memo[0], x):
            _, d, gd, y, todo = memo
            if anchor:  # (the warm start's value, now Newton's start: its exact points anchor the bounds)
                if len(todo):
                    self.y_ref[todo] = y[todo]
                    self.d_ref[todo] = d[todo]
                    self._distances = None
                self.anchored = (y[todo], todo)
            return d, gd, None
        with self.timer.timed("contact_field"):
            y = self.points.positions(x)
            k, dim = len(y), self.dim
            if self.y_ref is None:
                todo = np.arange(k)
                bound = None
            else:
                r = y - self.y_ref
                bound = self.d_ref - C.PSI_LIPSCHITZ * np.sqrt(np.add.reduce(r * r, axis=1))  # (np.linalg.norm's sum)
                todo = (bound < self.band).nonzero()[0]
            d = np.empty(k) if bound is None else bound  # (a fresh array)
            gd = np.zeros((k, dim)) if bound is not None or not k else None
            hd = np.zeros((k, dim, dim)) if hessian and gd is not None else None
            if bound is None and k:  # (the first evaluation: every point, no gathers)
                ev = self.cm.field.evaluate(y, (self.R, self.p), hessian=hessian, hessian_band=self.dhat_max)
                d, gd = -ev.psi, -ev.grad
                if hessian:
                    hd = -ev.hess
                self.y_ref, self.d_ref = y.copy(), d.copy()
            elif len(todo):
                ev = self.cm.field.evaluate(y[todo], (self.R, self.p), hessian=hessian, hessian_band=self.dhat_max)
                d[todo] = -ev.psi
                gd[todo] = -ev.grad
                if hessian:
                    hd[todo] = -ev.hess
                if self.y_ref is None:
                    self.y_ref, self.d_ref = y.copy(), d.copy()
                elif anchor:  # re-anchor at accepted iterates only (need_hessian marks them)
                    self.y_ref[todo] = y[todo]
                    self.d_ref[todo] = d[todo]
                    self._distances = None  # (the bounds beyond the band have moved)
            if anchor and not hessian:
                self.anchored = (y[todo], todo)
            elif not hessian:
                self._distances = (np.array(x, copy=True), d, gd, y, todo)
        return d, gd, hd

    def known_distances(self, x: np.ndarray):
        """The distances and their gradients of the last evaluation without Hessians when it was at x
        (as :meth:`distances` gives them: exact within the lazy band, lower bounds beyond), else None.

        Args:
            x: positions (n, dim) [m].

        Returns:
            (d (k,) [m], grad d (k, dim)) or None.
        """
        memo = self._distances
        if memo is not None and _equal(memo[0], x):
            return memo[1], memo[2]
        return None

    def __call__(self, xf: np.ndarray, need_hessian: bool):
        """(f [J], g (N,) [N], H csr [N/m] or None); f = +inf at an inverted element or a point inside O.
        An evaluation without the Hessian (a line-search trial) books its whole time under
        "line_search"; one with it books the FEM terms under "assembly", the contact field under
        "contact_field" and the barrier (and friction) terms under "barrier"."""
        if not need_hessian:
            with self.timer.into("line_search"):
                return self._evaluate(xf, False)
        return self._evaluate(xf, True)

    def _evaluate(self, xf: np.ndarray, need_hessian: bool):
        cm = self.cm
        memo = self.memo
        if need_hessian and memo is not None and memo[0].shape == xf.shape and _equal(memo[0], xf):
            self.memo = None  # hand the cached Hessian out once (the caller may modify it)
            return memo[1]
        x = xf.reshape(self.n, self.dim)
        if need_hessian and self.defer_hessian and not self.lazy_exact:
            return self._evaluate_deferred(xf, x)
        H_exact = None
        with self.timer.timed("assembly"):
            H = None
            H_fem = None  # the exact FEM Hessian assembled now for a LazyHessian (eager_exact)
            if need_hessian and not self.lazy_exact:
                # exact Hessian only (half the cost of the eigen-projected one); the projected one is
                # assembled on demand, when the exact one turns out indefinite (see LazyHessian)
                E, g, H_exact = energy_gradient_hessian(cm.fem, x, project_psd=False)
            elif need_hessian and self.eager_exact:
                E, g, H_fem = energy_gradient_hessian(cm.fem, x, project_psd=False)
                self._fem = (xf.copy(), E, g)
            else:
                E, g = self._fem_value(xf, x)
        if self.pin is not None:
            E, g = E + self.pin.energy(xf), g + self.pin.gradient(xf).reshape(g.shape)
        if not math.isfinite(E):
            return np.inf, g.ravel(), H
        d, gd, hd = self.distances(x, need_hessian)
        if np.count_nonzero(d <= 0):
            return np.inf, g.ravel(), H
        with self.timer.timed("barrier"):
            act, B, gy, Hy = self.contact_barrier(d, gd, hd)
            barrier = (act, B, gy)
            gc = self.points.scatter(gy, self.n, rows=act)
            Hf = None
            if self.friction is not None:
                fr = self.friction.evaluate(x, hessian=need_hessian)
                B += float(fr.energy.sum())
                gc += self.points.scatter(fr.gradient, self.n, rows=self.friction.rows)
                Hf = fr.hessian
            if need_hessian:
                contact = (act, Hy, Hf)
                if self.lazy_exact:
                    xc = x.copy()
                    H_exact, H = LazyHessian(self, xc, contact, psd=False, fem=H_fem), LazyHessian(self, xc, contact)
                elif H_exact is not None:
                    self.add_contact(H_exact, contact, psd=False)
                    H = LazyHessian(self, x.copy(), contact)
                else:
                    self.add_contact(H, contact, psd=True)
                self._remember(xf, d, gd, H, E, g, barrier)
                # curvature bound for the step cap: twice the largest |hess d| seen near O, at least
                # CURVATURE_FLOOR / sigma (a violated bound only costs a rejected line-search trial)
                self.curv, self._curv_from = self.curvature_bound(act, hd), None
            else:
                # Newton may stop at a trial evaluated without its Hessian (see solve): this
                # evaluation may be the final one, with the PSD Hessian deferred
                self._remember(xf, d, gd, LazyHessian(self, x.copy(), None), E, g, barrier)
        # exact-first Newton (simfab.solve.newton): the exact Hessian is used whenever it is
        # positive definite (quadratic convergence), the PSD-projected one (built lazily) otherwise
        out = (E + B, (g + gc).ravel(), H if H_exact is None else (H_exact, H))
        if need_hessian:
            self.memo = (xf.copy(), out)
        return out

    def _fem_value(self, xf: np.ndarray, x: np.ndarray):
        """The FEM energy and gradient at x, remembered for the last x (Newton asks for the Hessian at
        the line search's accepted trial, whose value was evaluated without it)."""
        fem = self._fem
        if fem is not None and _equal(fem[0], xf):
            return fem[1], fem[2]
        E, g = energy_gradient(self.cm.fem, x)
        self._fem = (xf.copy(), E, g)
        return E, g

    def _evaluate_deferred(self, xf: np.ndarray, x: np.ndarray):
        """:meth:`_evaluate` with the Hessian for a solve's iterates on linear elements: the value and
        gradient as with it, the lazy bounds re-anchored at x; the distances' Hessians, the contact
        blocks, the FEM Hessian and the curvature bound follow when Newton asks for the Hessian or
        the step cap (:class:`_DeferredHessian`): a line-search trial that ends the solve needs none."""
        with self.timer.timed("assembly"):
            E, g = self._fem_value(xf, x)
        if self.pin is not None:
            E, g = E + self.pin.energy(xf), g + self.pin.gradient(xf).reshape(g.shape)
        if not math.isfinite(E):
            return np.inf, g.ravel(), None
        d, gd, _ = self.distances(x, False, anchor=True)
        if np.count_nonzero(d <= 0):
            return np.inf, g.ravel(), None
        with self.timer.timed("barrier"):
            act, B, gy, _ = self.contact_barrier(d, gd, None)
            barrier = (act, B, gy)
            gc = self.points.scatter(gy, self.n, rows=act)
            if self.friction is not None:
                fr = self.friction.evaluate(x, hessian=False)
                B += float(fr.energy.sum())
                gc += self.points.scatter(fr.gradient, self.n, rows=self.friction.rows)
        deferred = _DeferredHessian(self, x.copy(), d, gd, act, self.anchored)
        self._curv_from = deferred
        H = LazyHessian(self, deferred.x, deferred)
        self._remember(xf, d, gd, H, E, g, barrier)
        out = (E + B, (g + gc).ravel(), (deferred, H))
        self.memo = (xf.copy(), out)
        return out

    def curvature_bound(self, act: np.ndarray, hd: np.ndarray) -> float:
        """The step cap's curvature bound [1/m] from the distances' Hessians hd (k, dim, dim) at the
        active points ``act``: twice the largest |hess d| seen near O, at least CURVATURE_FLOOR /
        sigma (a violated bound only costs a rejected line-search trial)."""
        kmax = float(np.abs(hd[act]).max()) * dim_factor(self.dim) if len(act) else 0.0
        return max(C.CURVATURE_SAFETY * kmax, C.CURVATURE_FLOOR / self.cm.field.sigma)

    def contact_barrier(self, d, gd, hd):
        """The barrier of the active points (``d < d_hat``), in one pass.

        Args:
            d: distances (k,) [m].
            gd: their gradients (k, dim).
            hd: their Hessians (k, dim, dim), or None.

        Returns:
            (active point indices (a,), energy [J], gradient (a, dim) [N], exact Hessian blocks
            (a, dim, dim) [N/m] or None without ``hd``); see :func:`simfab.contact.barrier.point_barrier`.
        """
        act = (d < self.dhat).nonzero()[0]
        B, gy, Hy = point_barrier(d[act], gd[act], None if hd is None else hd[act], self.dhat[act], self.kappa,
                                  psd=False)
        return act, B, gy, Hy

    def _remember(self, xf, d, gd, H, E, g, barrier) -> None:
        """Keep the last evaluation's data (x, distances, their gradients, Hessian, elastic energy
        and gradient, the contact barrier's (active points, energy, gradient)): Newton's final
        evaluation is read from it (see :func:`evaluation`)."""
        self.last_x = xf.copy()
        self.last_d = d
        self.last_gd = gd
        self.last_H = H
        self.last_fem = (E, g)  # elastic energy and gradient at last_x (reused by the step record)
        self.last_barrier = barrier

    def value(self, x: np.ndarray) -> float:
        """The objective's value only (no derivatives); its time books under "line_search".

        Args:
            x: positions (n, dim) [m].

        Returns:
            The value [J]; +inf when infeasible.
        """
        with self.timer.into("line_search"):
            return self._value(x)

    def _value(self, x: np.ndarray) -> float:
        with self.timer.timed("assembly"):
            E = energy(self.cm.fem, x) + (self.pin.energy(np.ravel(x)) if self.pin is not None else 0.0)
        if not math.isfinite(E):
            return np.inf
        x = np.asarray(x).reshape(self.n, self.dim)
        d, _, _ = self.distances(x, False)
        if np.count_nonzero(d <= 0):
            return np.inf
        act = d < self.dhat  # (all d > 0 here)
        D = float(self.friction.evaluate(x, hessian=False).energy.sum()) if self.friction is not None else 0.0
        return E + self.kappa * float(np.add.reduce(barrier_value(d[act], self.dhat[act]))) + D

    def add_contact(self, H, contact, *, psd: bool) -> None:
        """Add the barrier Hessian blocks and the rigid-mode regularization to a FEM Hessian, in place.

        Args:
            H: the FEM Hessian (CSR, the model's pattern).
            contact: (active points (a,), exact barrier blocks (a, dim, dim), friction blocks or None).
            psd: project each point's barrier block to PSD.
        """
        act, Hy, Hf = contact  # active points (a,), exact barrier blocks (a, dim, dim), friction blocks or None
        add_point_blocks(self.cm, self.points, H, act, project_psd(Hy) if psd and len(act) else Hy)
        if Hf is not None:  # PSD by construction (simfab.contact.friction)
            add_point_blocks(self.cm, self.points, H, self.friction.rows, Hf)
        regularize(self.cm, H)

    def max_step(self, xf: np.ndarray, dx: np.ndarray) -> float:
        """Step cap keeping every constraint point outside O along the whole step.

        Per point, with d its distance to O, a = grad d . dy and K a curvature bound of the field,
        d(alpha) >= d + alpha a - alpha^2 K |dy|^2 / 2; the cap is the largest alpha keeping this above
        t = 0.1 d within the barrier's range (d < d_hat, STEP_FRACTION), t = CAP_LAND_DHATS d_hat
        outside it (a point the step's model does not see lands inside the range, where the next Newton
        step sees it, but not deep in its steep part). Points in contact slide along O (a ~ 0) and move away freely,
        approaching points stop short of O. Conservative advancement, alpha <= (d - t) / (L |dy|) with L a
        Lipschitz bound of psi, is always allowed as well. The line search still rejects any trial point
        inside O. Its time books under "line_search".

        Args:
            xf: positions (flat) [m].
            dx: the Newton direction (flat) [m].

        Returns:
            alpha_max in (0, 1].
        """
        with self.timer.into("line_search"):
            return self._max_step(xf, dx)

    def _max_step(self, xf: np.ndarray, dx: np.ndarray) -> float:
        if self._curv_from is not None:
            self.curv = self._curv_from.contact()[3]
            self._curv_from = None
        if self.last_x is not None and _equal(self.last_x, xf):
            d, gd = self.last_d, self.last_gd
        else:
            d, gd, _ = self.distances(xf.reshape(self.n, self.dim), False)
        dy = self.points.positions(dx.reshape(self.n, self.dim))
        sp = np.sqrt(np.add.reduce(dy * dy, axis=1))  # (np.linalg.norm's sum)
        m = sp > 0
        if not np.count_nonzero(m):
            return 1.0
        d, gd, dy, sp = d[m], gd[m], dy[m], sp[m]
        a = np.einsum("kd,kd->k", gd, dy)
        q = 0.5 * sp**2 * self.curv
        dhat = self.dhat[m]
        keep = d - np.where(d < dhat, (1.0 - C.STEP_FRACTION) * d, C.CAP_LAND_DHATS * dhat)
        alpha_curv = (a + np.sqrt(a * a + 4.0 * q * keep)) / (2.0 * q)
        cons = keep / (C.PSI_LIPSCHITZ * sp)
        return float(min(1.0, np.minimum.reduce(np.maximum(alpha_curv, cons))))


class LazyHessian:
    """PSD-projected or exact Hessian of a :class:`StepObjective` at x, assembled on first call (once).

    Args:
        obj: the objective.
        x: positions (flat) [m].
        contact: (active points, exact barrier blocks, friction blocks) as found with the exact Hessian,
            or None to evaluate the distances at x again (deterministic: the same blocks).
        psd: the PSD-projected Hessian (else the exact one).
        fem: the FEM Hessian at x of that kind, already assembled (the contact blocks are added on
            the call), or None.
    """

    def __init__(self, obj, x, contact, psd: bool = True, fem=None):
        self.obj, self.x, self.contact, self.H, self.psd = obj, x, contact, None, psd
        self._fem = fem

    def __call__(self):
        if self.H is None:
            obj = self.obj
            H, self._fem = self._fem, None
            if H is None:
                with obj.timer.timed("assembly"):
                    _, _, H = energy_gradient_hessian(obj.cm.fem, self.x, project_psd=self.psd)
            if isinstance(self.contact, _DeferredHessian):
                self.contact = self.contact.contact()[:3]
            if self.contact is None:
                act, _, _, Hy = obj.contact_barrier(*obj.distances(self.x, True))
                Hf = obj.friction.evaluate(self.x, hessian=True).hessian if obj.friction is not None else None
                self.contact = (act, Hy, Hf)
            with obj.timer.timed("barrier"):
                obj.add_contact(H, self.contact, psd=self.psd)
            self.H = H
        return self.H


class _DeferredHessian:
    """The exact Hessian of a :class:`StepObjective` at x as :meth:`StepObjective._evaluate` assembles
    it, from the state of that evaluation (x, the distances d and gradients gd, the active points,
    the points evaluated exactly ``anchored``), assembled on first call (once); :meth:`contact`
    gives its contact blocks and the curvature bound (also read by the step cap)."""

    def __init__(self, obj, x, d, gd, act, anchored):
        self.obj, self.x, self.d, self.gd, self.act, self.anchored = obj, x, d, gd, act, anchored
        self._contact = None
        self.H = None

    def contact(self) -> tuple:
        """(active points, exact barrier blocks, friction blocks or None, curvature bound [1/m])."""
        if self._contact is None:
            obj = self.obj
            k, dim = len(self.d), obj.dim
            hd = np.zeros((k, dim, dim))
            y, todo = self.anchored
            if len(todo):
                with obj.timer.timed("contact_field"):
                    ev = obj.cm.field.evaluate(y, (obj.R, obj.p), hessian=True, hessian_band=obj.dhat_max)
                hd[todo] = -ev.hess
            with obj.timer.timed("barrier"):
                act, _, _, Hy = obj.contact_barrier(self.d, self.gd, hd)
                Hf = obj.friction.evaluate(self.x, hessian=True).hessian if obj.friction is not None else None
            self._contact = (act, Hy, Hf, obj.curvature_bound(act, hd))
        return self._contact

    def __call__(self):
        if self.H is None:
            obj = self.obj
            contact = self.contact()[:3]
            with obj.timer.timed("assembly"):
                _, _, H = energy_gradient_hessian(obj.cm.fem, self.x, project_psd=False)
            with obj.timer.timed("barrier"):
                obj.add_contact(H, contact, psd=False)
            self.H = H
        return self.H


def dim_factor(dim: int) -> float:
    """Bound of the spectral norm of a dim x dim matrix by its max |entry| times this factor.

    Args:
        dim: 2 or 3.

    Returns:
        The factor.
    """
    return float(dim)


def make_objective(cm: CouplingModel, state: StepState, s: float, ctx: StepContext,
                   friction: FrictionLag | None = None) -> StepObjective:
    """The step objective at path length s over the state's points.

    Args:
        cm: the coupling model.
        state: the step's state (points, barrier stiffness, pin basis, positions).
        s: path length [m].
        ctx: the run's context (timer).
        friction: the lagged friction, or None.

    Returns:
        The objective, with the pin of the unresisted rigid motions anchored at the state's positions.
    """
    R, p = cm.pose(s)
    pin = rigid.pin_for(cm, state.pin_basis, rigid.motion_basis(cm)[1], state.x)
    return StepObjective(cm, state.points, R, p, ctx.timer, state.kappa, pin, friction)


def adapt_kappa(cm: CouplingModel, state: StepState, obj: StepObjective) -> None:
    """IPC-style stiffness adaptation: when a converged step leaves a point closer to O than
    KAPPA_GROW_BELOW * d_hat, double kappa for the following steps (at most KAPPA_MAX_GROWTH times the
    initial value); a stiffer barrier keeps contact gaps ~ kappa d_hat^2 / f larger.

    Args:
        cm: the coupling model.
        state: the state whose ``kappa`` is updated in place.
        obj: the step's objective (its last distances).
    """
    d = obj.last_d
    if d is None or not len(d):
        return
    if (d < C.KAPPA_GROW_BELOW * obj.dhat).any() and state.kappa < C.KAPPA_MAX_GROWTH * cm.kappa:
        state.kappa = min(2.0 * state.kappa, C.KAPPA_MAX_GROWTH * cm.kappa)


def solve(cm: CouplingModel, obj: StepObjective, x0: np.ndarray, ctx: StepContext, *,
          floor: float = 0.0, converged: bool = False) -> tuple[np.ndarray, int]:
    """Barrier Newton from x0.

    Stops when the free-dof force residual is below max(NEWTON_GRAD_TOL_REL * force_scale,
    NEWTON_GRAD_TOL_START * |residual at x0|, ``floor``) or the Newton step is below
    NEWTON_STEP_TOL_REL * h_A. On quadratic elements line-search trials are evaluated without the
    Hessian (it costs many energy evaluations there), on linear ones the first trial carries it (unless
    the residual is within NEWTON_EAGER_ABOVE_TOL of the target). Once the exact Hessian has failed to
    factorize, the rest of the solve uses the PSD-projected one; on quadratic elements the next solve
    too. The measured reasons: docs/decisions.md.

    Args:
        cm: the coupling model.
        obj: the step's objective.
        x0: start positions (n, dim) [m].
        ctx: the run's context (solver, timer, whether the last exact Hessian failed).
        floor: [N] raises the force tolerance of a solve that is not final (a lagging iteration).
        converged: x0 is expected to be the solution (:func:`simfab.coupling.predictor.resting_start`):
            its Hessian is not assembled with its gradient.

    Returns:
        (x (n, dim) [m], Newton iterations).
    """
    exact_first = not (obj.lazy_exact and ctx.exact_failed)
    obj.eager_exact = exact_first and not converged  # (P2: the start's exact Hessian assembled with its gradient)
    obj.defer_hessian = converged  # (linear elements: a start expected to be the solution gets its Hessian on demand)
    try:
        _, g0, _ = obj(x0.ravel(), True)  # memoized: minimize's first evaluation reuses it
    finally:
        obj.eager_exact = False
    obj.defer_hessian = True  # (the start's Hessian is wanted unless x0 already converged: assembled now)
    g0n = float(np.abs(g0[cm.free]).max()) if cm.free.any() else 0.0
    scale = max(C.NEWTON_GRAD_TOL_REL * cm.force_scale, C.NEWTON_GRAD_TOL_START * g0n, floor)
    opts = NewtonConfig(max_iter=C.NEWTON_MAX_ITER, grad_tol=1.0, grad_scale=scale,
                         step_tol=C.NEWTON_STEP_TOL_REL, x_scale=cm.h, eager_hessian=cm.fem.element_order == 1,
                         eager_above_tol=C.NEWTON_EAGER_ABOVE_TOL, retry_exact=False,
                         exact_first=exact_first,
                         chord_within=C.NEWTON_CHORD_WITHIN)
    solver = TimedSolver(pinned(ctx.solver, obj.pin, target=scale), ctx.timer)
    res = minimize(obj, x0.ravel(), free=cm.free, options=opts, max_step=obj.max_step, solver=solver)
    ctx.exact_failed = res.exact_failures > 0
    return res.x.reshape(x0.shape), res.iterations


def pinned(solver, pin, target: float | None = None):
    """A solver with the rigid-mode pin's Woodbury update.

    Args:
        solver: the SPD solver.
        pin: the pin, or None.
        target: Newton's force target [N] (the accuracy of an iterative pinned solve), or None.

    Returns:
        :class:`simfab.coupling.rigid.PinnedSolver` with a pin; without one
        :class:`simfab.coupling.rigid.ForcedSolver` when a target is given and the solver can lag
        (its iterative solves then stop at the target, as the pinned ones do), else ``solver`` itself.
    """
    if pin is not None:
        return rigid.PinnedSolver(solver, pin, target)
    if target is not None and hasattr(solver, "solve_free_lagged"):
        return rigid.ForcedSolver(solver, target)
    return solver


def evaluation(obj: StepObjective, x: np.ndarray) -> Evaluation | None:
    """The objective's last evaluation when it was at x (Newton's converged point).

    Args:
        obj: the objective.
        x: positions (n, dim) [m].

    Returns:
        The :class:`simfab.coupling.state.Evaluation`, or None.
    """
    if obj.last_x is None or not _equal(obj.last_x, x.ravel()):
        return None
    E, gE = obj.last_fem
    act, B, gy = obj.last_barrier
    return Evaluation(x=x, kappa=obj.kappa, points=obj.points, elastic_energy=float(E), elastic_gradient=gE,
                      barrier_points=act, barrier_energy=float(B), barrier_gradient=gy,
                      distances=obj.last_d, distance_gradients=obj.last_gd, hessian=obj.last_H)
