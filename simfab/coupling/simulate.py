"""Quasi-static insertion of a rigid object O into a compliant part A.

At every insertion step O is moved to its next pose along the path and A settles into

    minimize_x  E_d(x)   subject to  psi(y_j(x)) <= 0   for all constraint points y_j

(E_d: Neo-Hookean energy, psi: IMLS field of O, > 0 inside; y_j: A's boundary vertices plus
refinement points on boundary edges/faces). Method, per step (interior point / IPC style):

1. **Predictor.** Constraint points that O could reach during the step (distance to O below the
   Lipschitz bound of psi times O's displacement there, plus d_hat) are pushed along O's normal
   by O's normal displacement (free to slide tangentially) and the rest of A follows through one
   linear solve with the tangent stiffness of the previous step (a penalty in the same sparsity
   pattern, so the symbolic factorization is reused). Points still inside O are then carried
   rigidly with O (rigid motion keeps their distance to O) and the solve repeated. The result is a
   feasible, non-inverted warm start: every point outside O. The linear and quadratic
   extrapolations of the last two / three converged steps come first; the feasible one with the
   lowest objective E_d + B is the warm start (fewer Newton iterations when the deformation
   evolves smoothly along the path), with the vertices that were in contact moved back to their
   last gap to O (extrapolation slides them off O's curved surface, out of the barrier's range);
   the contact predictor above is computed only when no extrapolation is feasible (its PSD
   tangent stiffness is then assembled on demand).
2. **Corrector.** Newton (:func:`simfab.solve.newton.minimize`, exact Hessian first, the
   PSD-projected one when the exact one is indefinite) on
   E_d(x) + kappa * sum_j b(-psi(y_j)) with the log barrier b of :mod:`simfab.contact.barrier`.
   Every step is capped so that no point can reach O (a curvature-aware bound, with conservative
   advancement alpha <= 0.9 d_j / (L |dy_j|), L a Lipschitz bound of psi, as a floor), and the
   Armijo line search rejects trial points with an inverted element (E_d = +inf) or a point
   inside O (b = +inf). The iterate therefore stays feasible. kappa starts at the nodal stiffness
   of A's elements and is doubled (IPC-style) after a step that leaves a point closer than
   1e-3 d_hat to O.
3. **Refinement.** Boundary facets near O are checked at interpolated points; facets whose interior
   crosses into O receive ``samples_per_edge`` points per edge (2D) or a barycentric lattice
   (3D) as extra constraints and the step is solved again: from the current (converged) state
   with the new points that lie inside O lifted out along O's normal (a local move of their
   facets' vertices), or, when that is infeasible or fails, from the previous step's state (which
   is feasible for them, because every earlier step ended with all facets checked outside O).
   Refined facets keep their points for the rest of the simulation. If refined facets still
   penetrate O by more than the tolerance between their points, the density is doubled (the new
   points are the old check points, pushed out of O first) and the step solved again.
4. **Check.** The step ends only if the max penetration at vertices and at dense check points on
   facets near O is <= ``penetration_tol_rel * h_A`` and no element is inverted; otherwise
   ConvergenceError. A step that cannot be taken (predictor infeasible, Newton failure) is
   bisected along the path up to ``MAX_BISECTIONS`` times before giving up loudly.

Cost control: the contact field is evaluated in one Warp launch per call (two, on two threads,
for 1024 points or more), with neighbours from per-cell lists, only for points that are not
certified (by the Lipschitz bound and their travel since their last exact evaluation) to be
farther than a band of a few d_hat from O; Hessians of psi only within d_hat. (Evaluating it on a
second thread while the FEM Hessian is assembled gained nothing once its launch stopped re-binding
parameters: waking the worker cost about what the overlap saved.) CHOLMOD's symbolic analysis and
the value map of the fixed FEM sparsity pattern are reused for every solve
(:class:`simfab.solve.linear.SPDSolver`); the facet check of a converged state is memoized, takes
its vertices' distances from Newton's last evaluation, and check points already certified outside
O by the Lipschitz bound from their facet's vertices, or from their own values at earlier checks,
are not evaluated; lifting near points reads the objective's lazy distances. Per Newton iterate
only the exact FEM Hessian is assembled (the PSD-projected one, twice as expensive, only when the
exact one fails to factorize); the line search evaluates the Hessian already at its first trial
(most are accepted) unless the force residual is within NEWTON_EAGER_ABOVE_TOL of the target (the
trial is then most likely the last iterate), and the step record reuses Newton's last
evaluation. The forces of a step use the barrier stiffness its equilibrium was solved with.

Well-posedness: a rigid motion of A that the supports leave free and no contact normal opposes
(a clip sliding along a frictionless cylinder, a claw turning on a sphere) costs no energy, so the
equilibrium is not unique along it. When the supports leave any rigid motion free, every step's
objective carries a weak pin mu/2 |x - x_start|^2 on the free dofs (:func:`simfab.coupling.rigid.
pin_stiffness`): along an unresisted motion A stays where the step began, elsewhere the bias is
~1e-5. After every step the rigid motion the contact resists least is found
(:mod:`simfab.coupling.rigid`); when one is unresisted the run notes it (``InsertionResult.notes``).

Certificates: the facet check and the lazy distances certify points outside O from a Lipschitz
bound L of psi (PSI_LIPSCHITZ = 2; |grad psi| ~ 1 away from sharp features). IMLS fields can be
steeper near sharp rims of O; the run tracks the largest |grad psi| at its converged constraint
and check points and warns when it exceeds L (the certificates are then not rigorous there).

Forces: the reaction at the fixed dofs is r = dE_total/dx there (the force the support applies to
A). By equilibrium of A it equals the force A exerts on O, so the insertion force is
F = sum r . u (u: unit direction of O's translation), negative when A resists the insertion.
Contact forces on A are f_a = -dB/dx_a; the grip force is || (1/2 sum |f_x|, 1/2 sum |f_y|,
1/2 sum |f_z|) ||.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field, fields, replace

import numpy as np

from simfab.contact.barrier import barrier, barrier_hessian, point_barrier, project_psd
from simfab.contact.imls import ImlsField, body_frame, pose_matrix
from simfab.coupling import config as C
from simfab.coupling import rigid, settle
from simfab.coupling.config import InsertionOptions
from simfab.coupling.points import ContactPoints, check_weights, facet_points, facet_weights, vertex_points
from simfab.errors import ConvergenceError, InputError


@dataclass(frozen=True, kw_only=True, eq=False)
class CouplingModel:
    """Immutable description of one insertion simulation.

    fem : :class:`simfab.fem.model.FemModel` of A (SI units)
    field : :class:`ImlsField` of O in O's body frame
    path : :class:`simfab.io.mjcf.Trajectory` of O's pose, parameterized by path length [m]
    s_steps : (K+1,) path length at each step [m]; step 0 is the start pose
    fixed_vertices : (f,) vertices of A in the fixed region
    free : (n*dim,) bool, dofs solved for (fixed: the fixed vertices' dofs along the insertion axis,
        along ``options.fixed_axes``, or along all axes with ``options.fix_all_axes``)
    axis : (dim,) unit insertion axis (coordinate axis closest to O's overall translation)
    h : A's mean edge length h_A [m]; dhat [m]; kappa [N/m]; tol : penetration tolerance [m]
    object_vertices, object_faces : O's display geometry in its body frame (3D mesh, or a closed
        curve (k, 2) with faces None in 2D)
    """

    name: str
    fem: object
    field: ImlsField
    path: object
    s_steps: np.ndarray
    fixed_vertices: np.ndarray
    free: np.ndarray
    axis: np.ndarray
    options: InsertionOptions
    h: float
    dhat: float
    kappa: float
    tol: float
    force_scale: float
    object_vertices: np.ndarray
    object_faces: np.ndarray | None = None
    _cache: dict = field(default_factory=dict, repr=False, init=False)  # fresh on dataclasses.replace

    @property
    def dim(self) -> int:
        return self.fem.dim

    def pose(self, s: float):
        """O's pose at path length s: (R (3, 3), p (3,)) with world x = R x_body + p (memoized)."""
        key = ("pose", float(s))
        out = self._cache.get(key)
        if out is None:
            out = self._cache[key] = pose_matrix(self.pos_quat(s))
        return out

    def pos_quat(self, s: float):
        """O's pose at path length s as the path gives it: (pos (3,) [m], quat_wxyz (4,)) (memoized;
        do not modify the arrays)."""
        key = ("pos_quat", float(s))
        out = self._cache.get(key)
        if out is None:
            L = float(self.path.length)
            u = self.end_direction
            if s > L and u is not None:  # past the last keyframe: straight on along the last segment
                pos, quat = self.path.pose_at(L)
                pos = np.asarray(pos, dtype=float) + (s - L) * u
            else:
                pos, quat = self.path.pose_at(s)
            out = self._cache[key] = (np.asarray(pos, dtype=float), np.asarray(quat, dtype=float))
        return out

    @property
    def end_direction(self) -> np.ndarray | None:
        """(3,) unit translation of the path's last segment when that segment is a pure
        translation (O may then continue past the last keyframe until it comes to rest), else None."""
        key = "end_direction"
        if key not in self._cache:
            pos, quat = self.path.positions, self.path.quats
            d = np.asarray(pos[-1] - pos[-2], dtype=float)
            turn = abs(abs(float(np.dot(quat[-1], quat[-2]))) - 1.0) > 1e-12
            n = float(np.linalg.norm(d))
            self._cache[key] = None if (turn or n == 0) else d / n
        return self._cache[key]

    def direction(self, s: float) -> np.ndarray:
        """(dim,) unit translation direction of O at s (zero during a pure rotation; memoized)."""
        key = ("direction", float(s))
        out = self._cache.get(key)
        if out is None:
            L = float(self.path.length)
            past = s > L and self.end_direction is not None
            u = (self.end_direction if past else np.asarray(self.path.direction_at(s), dtype=float))[: self.dim]
            n = np.linalg.norm(u)
            out = self._cache[key] = u / n if n > 0 else u
        return out.copy()


def make_coupling_model(*, name: str, fem, field: ImlsField, path, fixed_vertices, options: InsertionOptions,
                        object_vertices, object_faces=None) -> CouplingModel:
    """Assemble a :class:`CouplingModel`: steps along the path, boundary conditions, barrier scales."""
    dim = fem.dim
    n = fem.n_vertices
    fixed_vertices = np.unique(np.asarray(fixed_vertices, dtype=np.int64))
    if fixed_vertices.size == 0:
        raise InputError("the fixed region contains no vertex of the compliant part", where="fixed")
    total = float(path.length)
    L = default_insertion_length(fem, path) if options.L_max is None else min(float(options.L_max), total)
    if not L > 0:
        raise InputError("the object's path has zero length (keyframes do not move it)", where="keyframes")
    if options.h_in is not None:
        k = int(np.floor(L / options.h_in + 1e-9))
        s = np.arange(k + 1) * options.h_in
        if L - s[-1] > 1e-9 * L:
            s = np.append(s, L)
    else:
        s = np.linspace(0.0, L, (options.steps or 35) + 1)
    move = np.asarray(path.positions[-1] - path.positions[0])[:dim]
    if np.linalg.norm(move) == 0:
        move = np.asarray(path.direction_at(0.0))[:dim]
    ax = int(np.argmax(np.abs(move))) if np.linalg.norm(move) > 0 else 0
    axis = np.zeros(dim)
    axis[ax] = 1.0
    free = np.ones((n, dim), dtype=bool)
    if options.fix_all_axes:
        free[fixed_vertices] = False
    elif options.fixed_axes is not None:
        held = ["xyz".index(a) for a in options.fixed_axes]
        if any(a >= dim for a in held):
            raise InputError(f"fixed_axes={options.fixed_axes!r} names an axis a {dim}D part does not have",
                             where="[simulation]")
        if ax not in held:
            raise InputError(f"fixed_axes={options.fixed_axes!r} must include the insertion axis {'xyz'[ax]!r}",
                             where="[simulation]")
        free[np.ix_(fixed_vertices, held)] = False
    else:
        free[fixed_vertices, ax] = False
    h = fem.mean_edge_length()
    E = fem.material.youngs_modulus if fem.material is not None else float(np.mean(fem.mu) * 3)
    width = h if dim == 3 else fem.thickness
    return CouplingModel(
        name=name, fem=fem, field=field, path=path, s_steps=s, fixed_vertices=fixed_vertices, free=free.ravel(),
        axis=axis, options=options, h=h, dhat=options.dhat_rel * h, kappa=options.kappa_rel * E * width,
        tol=options.penetration_tol_rel * h, force_scale=E * h * width,
        object_vertices=np.asarray(object_vertices, float),
        object_faces=None if object_faces is None else np.asarray(object_faces, int),
    )


def default_insertion_length(fem, path, samples: int = 2000) -> float:
    """L_max by default: the path length at which O's centre passes A's farthest point along the
    insertion direction (the overall translation of the path), or the whole path if it never does.
    """
    dim = fem.dim
    move = np.asarray(path.positions[-1] - path.positions[0], dtype=float)[:dim]
    total = float(path.length)
    if np.linalg.norm(move) == 0:
        return total
    u = move / np.linalg.norm(move)
    far = float(np.max(fem.rest @ u))
    for s in np.linspace(0.0, total, samples):
        if float(np.asarray(path.pose_at(s)[0])[:dim] @ u) > far:
            return float(s)
    return total


# ----------------------------------------------------------------------------- results
@dataclass(kw_only=True)
class StepResult:
    """One insertion step. Units: s, penetration [m]; energy [J]; forces [N]; stress [Pa]."""

    s: float
    pos: np.ndarray
    quat: np.ndarray
    x: np.ndarray  # (n, dim) deformed positions [m]
    energy: float
    force: float  # insertion force: support reactions along O's translation (resisting < 0)
    path_force: float  # generalized force along the path, sum_j f_j(on O) . dy_j/ds = -d(E + B)/ds [N]
    barrier_energy: float  # kappa sum_j b(d_j) at this state [J] (not part of the elastic energy)
    grip: float
    max_von_mises: float
    von_mises: np.ndarray  # (m,) per element [Pa]
    penetration: float
    min_det_F: float
    iterations: int
    contact_points: int
    kappa: float  # barrier stiffness used for this step [N/m]


@dataclass(kw_only=True)
class InsertionResult:
    """steps : one :class:`StepResult` per step (the start pose first); seconds : wall time;
    timings : seconds per resource (assembly, factorization, contact; they cut across phases);
    phases : wall seconds per phase of the insertion loop, each counted once (warm_start, newton,
    facet_check, record, rigid_check; "other" is the rest of ``seconds``);
    warnings : one line each (e.g. steps too coarse, an unfinished insertion, stress above yield);
    notes : one line each about how the run was solved (e.g. a rigid motion of A that nothing
    resists, pinned by the solver)."""

    model: CouplingModel
    steps: list
    seconds: float
    timings: dict
    phases: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    notes: list = field(default_factory=list)

    def column(self, name: str) -> np.ndarray:
        return np.array([getattr(r, name) for r in self.steps], dtype=float)


class _Timer:
    """Accumulates wall time per category (assembly, factorization, contact, ...)."""

    def __init__(self):
        self.t: dict[str, float] = {}

    def add(self, key: str, dt: float) -> None:
        self.t[key] = self.t.get(key, 0.0) + dt

    def timed(self, key: str) -> "_Span":
        """Book the wall time of a ``with`` block under ``key``."""
        return _Span(self, key)


class _Span:
    """``with`` block timed into a :class:`_Timer` (a plain class: it runs on every objective
    evaluation, where a generator-based context manager costs a few times more)."""

    __slots__ = ("timer", "key", "t0")

    def __init__(self, timer: _Timer, key: str):
        self.timer, self.key = timer, key

    def __enter__(self):
        self.t0 = time.perf_counter()

    def __exit__(self, *exc):
        self.timer.add(self.key, time.perf_counter() - self.t0)


# ----------------------------------------------------------------------------- objective
class _StepObjective:
    """E_d(x) + kappa sum_j b(d_j(x)) for a fixed pose of O and a fixed set of constraint points."""

    def __init__(self, cm: CouplingModel, points: ContactPoints, R: np.ndarray, p: np.ndarray, timer: _Timer,
                 kappa: float | None = None, pin: rigid.Pin | None = None):
        self.cm, self.points, self.R, self.p, self.timer = cm, points, R, p, timer
        self.pin = pin  # pin of the rigid motions nothing resists (simfab.coupling.rigid.Pin), or None
        self.kappa = cm.kappa if kappa is None else float(kappa)
        self.n, self.dim = cm.fem.n_vertices, cm.dim
        self.slots = _point_slots(cm, points)
        self.wpair = points.weights[:, :, None] * points.weights[:, None, :]  # (k, nv, nv)
        self.diag = _diag_slots(cm)
        self.last_x = None
        self.last_d = None
        self.last_gd = None
        self.last_H = None
        self.last_fem = None
        self.curv = 1.0 / cm.field.sigma  # curvature bound for max_step until a Hessian evaluation sets it
        # Lazy evaluation: psi is L-Lipschitz, so a point that was at distance d_ref when last
        # evaluated exactly (at y_ref) is still at least d_ref - L |y - y_ref| away. Points whose
        # bound stays above the band need no evaluation (their barrier term is exactly zero).
        self.dhat = _point_dhat(cm, points)  # (k,) activation distance per point [m]
        self.dhat_max = float(self.dhat.max()) if len(self.dhat) else cm.dhat
        self.band = C.LAZY_BAND_DHATS * self.dhat
        self.y_ref = None
        self.d_ref = None
        self.memo = None  # (x, (f, g, H)) of the last Hessian evaluation, reused once
        self.exact_first = C.EXACT_FIRST_NEWTON

    def distances(self, x: np.ndarray, hessian: bool):
        """(d (k,) [m], grad d (k, dim), hess d (k, dim, dim) or None): exact near O, lower bounds
        (zero derivatives) for points certified farther than the band."""
        with self.timer.timed("contact"):
            y = self.points.positions(x)
            k, dim = len(y), self.dim
            if self.y_ref is None:
                todo = np.arange(k)
                bound = None
            else:
                bound = self.d_ref - C.PSI_LIPSCHITZ * np.linalg.norm(y - self.y_ref, axis=1)
                todo = np.flatnonzero(bound < self.band)
            d = np.empty(k) if bound is None else bound.copy()
            gd = np.zeros((k, dim))
            hd = np.zeros((k, dim, dim)) if hessian else None
            if len(todo):
                ev = self.cm.field.evaluate(y[todo], (self.R, self.p), hessian=hessian, hessian_band=self.dhat_max)
                d[todo] = -ev.psi
                gd[todo] = -ev.grad
                if hessian:
                    hd[todo] = -ev.hess
                if self.y_ref is None:
                    self.y_ref, self.d_ref = y.copy(), d.copy()
                elif hessian:  # re-anchor at accepted iterates only (need_hessian marks them)
                    self.y_ref[todo] = y[todo]
                    self.d_ref[todo] = d[todo]
        return d, gd, hd

    def __call__(self, xf: np.ndarray, need_hessian: bool):
        """(f [J], g (N,) [N], H csr [N/m] or None); f = +inf at an inverted element or a point inside O."""
        from simfab.fem.neohookean import energy_gradient, energy_gradient_hessian

        cm = self.cm
        memo = self.memo
        if need_hessian and memo is not None and memo[0].shape == xf.shape and np.array_equal(memo[0], xf):
            self.memo = None  # hand the cached Hessian out once (the caller may modify it)
            return memo[1]
        x = xf.reshape(self.n, self.dim)
        H_exact = None
        with self.timer.timed("assembly"):
            if need_hessian and self.exact_first:
                # exact Hessian only (half the cost of the eigen-projected one); the projected one is
                # assembled on demand, when the exact one turns out indefinite (see _LazyHessian)
                E, g, H_exact = energy_gradient_hessian(cm.fem, x, project_psd=False)
                H = None
            elif need_hessian:
                E, g, H = energy_gradient_hessian(cm.fem, x)
            else:
                (E, g), H = energy_gradient(cm.fem, x), None
        if self.pin is not None:
            E, g = E + self.pin.energy(xf), g + self.pin.gradient(xf).reshape(g.shape)
        if not np.isfinite(E):
            return np.inf, g.ravel(), H
        d, gd, hd = self.distances(x, need_hessian)
        if np.any(d <= 0):
            return np.inf, g.ravel(), H
        with self.timer.timed("contact"):
            act, B, gy, Hy = self._barrier(d, gd, hd)
            gc = self.points.scatter(gy, self.n, rows=act)
            if need_hessian:
                contact = (act, Hy)
                if H_exact is not None:
                    self._add_contact(H_exact, contact, psd=False)
                    H = _LazyHessian(self, x.copy(), contact)
                else:
                    self._add_contact(H, contact, psd=True)
                self._remember(xf, d, gd, H, E, g)
                # curvature bound for the step cap: twice the largest |hess d| seen near O, at least
                # CURVATURE_FLOOR / sigma (a violated bound only costs a rejected line-search trial)
                kmax = float(np.abs(hd[act]).max()) * dim_factor(self.dim) if len(act) else 0.0
                self.curv = max(C.CURVATURE_SAFETY * kmax, C.CURVATURE_FLOOR / cm.field.sigma)
            else:
                # Newton may stop at a trial evaluated without its Hessian (see NewtonOptions.
                # eager_above_tol): this evaluation may be the final one, with the PSD Hessian deferred
                self._remember(xf, d, gd, _LazyHessian(self, x.copy(), None), E, g)
        # exact-first Newton (simfab.solve.newton): the exact Hessian is used whenever it is
        # positive definite (quadratic convergence), the PSD-projected one (built lazily) otherwise
        out = (E + B, (g + gc).ravel(), H if H_exact is None else (H_exact, H))
        if need_hessian:
            self.memo = (xf.copy(), out)
        return out

    def _barrier(self, d, gd, hd):
        """(active point indices (a,), energy [J], gradient (a, dim) [N], exact Hessian blocks
        (a, dim, dim) [N/m] or None without ``hd``) of the barrier at distances d (k,) with their
        derivatives (see :func:`simfab.contact.barrier.point_barrier`), in one pass."""
        act = np.flatnonzero(d < self.dhat)
        B, gy, Hy = point_barrier(d[act], gd[act], None if hd is None else hd[act], self.dhat[act], self.kappa,
                                  psd=False)
        return act, B, gy, Hy

    def _remember(self, xf, d, gd, H, E, g) -> None:
        """Keep the last evaluation's data (x, distances, their gradients, Hessian, elastic energy
        and gradient): Newton's final evaluation is read from it (see :func:`_final_eval`)."""
        self.last_x = xf.copy()
        self.last_d = d
        self.last_gd = gd
        self.last_H = H
        self.last_fem = (E, g)  # elastic energy and gradient at last_x (reused by _record)

    def value(self, x: np.ndarray) -> float:
        """Objective value [J] only (no derivatives) at positions x (n, dim); +inf when infeasible."""
        from simfab.fem.neohookean import energy

        with self.timer.timed("assembly"):
            E = energy(self.cm.fem, x) + (self.pin.energy(np.ravel(x)) if self.pin is not None else 0.0)
        if not np.isfinite(E):
            return np.inf
        d, _, _ = self.distances(np.asarray(x).reshape(self.n, self.dim), False)
        if np.any(d <= 0):
            return np.inf
        act = d < self.dhat
        return E + self.kappa * float(barrier(d[act], self.dhat[act]).sum())

    def _add_contact(self, H, contact, *, psd: bool) -> None:
        """Add the barrier Hessian blocks (PSD-projected per point if ``psd``) and the rigid-mode
        regularization to the FEM Hessian ``H`` (in place)."""
        act, Hy = contact  # active point indices (a,), exact barrier Hessian blocks (a, dim, dim)
        if len(act):
            if psd:
                Hy = project_psd(Hy)
            wp_act = self.wpair[act][:, :, :, None, None]
            np.add.at(H.data, self.slots[act].ravel(), (wp_act * Hy[:, None, None, :, :]).ravel())
        _regularize(self.cm, H, self.diag)

    def max_step(self, xf: np.ndarray, dx: np.ndarray) -> float:
        """Step cap keeping every constraint point outside O along the whole step (see below).

        Per point, with d its distance to O, a = grad d . dy and K a curvature bound of the field
        (from the Hessians near O, see ``__call__``), d(alpha) >= d + alpha a - alpha^2 K |dy|^2 / 2; the cap is the largest alpha
        keeping this above 0.1 d. It lets points in contact slide along O (a ~ 0) and move away
        freely, while approaching points stop short of O. Conservative advancement,
        alpha <= 0.9 d / (L |dy|) with L a Lipschitz bound of psi, is always allowed as well.
        The line search still rejects any trial point inside O (energy +inf).
        """
        if self.last_x is not None and np.array_equal(self.last_x, xf):
            d, gd = self.last_d, self.last_gd
        else:
            d, gd, _ = self.distances(xf.reshape(self.n, self.dim), False)
        dy = self.points.positions(dx.reshape(self.n, self.dim))
        sp = np.linalg.norm(dy, axis=1)
        m = sp > 0
        if not m.any():
            return 1.0
        d, gd, dy, sp = d[m], gd[m], dy[m], sp[m]
        a = np.einsum("kd,kd->k", gd, dy)
        q = 0.5 * sp**2 * self.curv
        keep = C.STEP_FRACTION * d
        alpha_curv = (a + np.sqrt(a * a + 4.0 * q * keep)) / (2.0 * q)
        cons = keep / (C.PSI_LIPSCHITZ * sp)
        return float(min(1.0, np.min(np.maximum(alpha_curv, cons))))


class _LazyHessian:
    """PSD-projected Hessian of a :class:`_StepObjective` at x, assembled on first call (once);
    ``contact`` (active points, exact barrier blocks) as found with the exact Hessian, or None to
    evaluate the distances at x again (deterministic: the same active points and blocks)."""

    def __init__(self, obj, x, contact):
        self.obj, self.x, self.contact, self.H = obj, x, contact, None

    def __call__(self):
        if self.H is None:
            from simfab.fem.neohookean import energy_gradient_hessian

            obj = self.obj
            with obj.timer.timed("assembly"):
                _, _, H = energy_gradient_hessian(obj.cm.fem, self.x)
            if self.contact is None:
                act, _, _, Hy = obj._barrier(*obj.distances(self.x, True))
                self.contact = (act, Hy)
            with obj.timer.timed("contact"):
                obj._add_contact(H, self.contact, psd=True)
            self.H = H
        return self.H


def dim_factor(dim: int) -> float:
    """Bound of the spectral norm of a dim x dim matrix by its max |entry| times this factor."""
    return float(dim)


def _regularize(cm: CouplingModel, H, diag: np.ndarray) -> None:
    """Add FACTOR_REG * mean stiffness to the diagonal of H in place (``diag``: the CSR slots of
    the diagonal, :func:`_diag_slots`) when the supports leave rigid motions free: the sparse
    factorization then succeeds, and the Woodbury pin (rigid.PinnedSolver) removes the near-null
    directions from the solve; the term is in the Hessian only (not the energy)."""
    if rigid.motion_basis(cm)[0].shape[1]:
        H.data[diag] += C.FACTOR_REG * rigid.mean_stiffness(cm)


def _diag_slots(cm: CouplingModel) -> np.ndarray:
    s = cm._cache.get("diag")
    if s is None:
        n, dim = cm.fem.n_vertices, cm.dim
        b = cm.fem.pattern.block_slots(np.arange(n), np.arange(n))
        s = cm._cache["diag"] = b[:, np.arange(dim), np.arange(dim)].ravel()
    return s


# ----------------------------------------------------------------------------- simulation
@dataclass(kw_only=True)
class _State:
    x: np.ndarray  # (n, dim)
    s: float
    points: ContactPoints
    refined: set
    order: int  # refinement density (2D: points per edge, 3D: face lattice order), doubled on demand
    check: tuple | None = None  # memo of the last facet check (x, s, order, result)
    check_cache: dict = field(default_factory=dict)  # earlier check points' values (_check_cache)
    kappa: float = 0.0  # current barrier stiffness [N/m] (adapted, see _adapt_kappa)
    H: object = None  # last PSD Hessian (for the predictor; a _LazyHessian until first needed)
    final: tuple | None = None  # Newton's last evaluation at x (see _final_eval), for _record
    kappa_step: float = 0.0  # barrier stiffness the current x was solved with [N/m] (kappa may
    # grow for the following steps; forces at x must use the stiffness of its own equilibrium)
    prev: tuple | None = None  # (x, s) of the step before (for the extrapolating predictor)
    prev2: tuple | None = None  # (x, s) two steps before
    grad_peak: float = 0.0  # largest |grad psi| seen at converged constraint and check points [-]
    pin_basis: np.ndarray | None = None  # (k, r) rigid motions (rigid.motion_basis coordinates) the
    # contact of the last step left unresisted: pinned in the next step (rigid.Pin)


def simulate(cm: CouplingModel, *, quiet: bool = True, callback=None) -> InsertionResult:
    """Run the insertion along all steps of ``cm``; see the module docstring for the method.

    Returns :class:`InsertionResult` (one :class:`StepResult` per step including the start pose).
    Raises ConvergenceError when a step cannot be solved to tolerance, InputError when O starts
    inside A.
    """
    from simfab.solve.linear import SPDSolver
    from simfab.progress import progress

    t_start = time.perf_counter()
    timer = _Timer()
    fem = cm.fem
    dim = cm.dim
    bverts = np.asarray(fem.boundary_vertices, dtype=np.int64)
    points = vertex_points(bverts, dim)
    order = cm.options.samples_per_edge if dim == 2 else cm.options.face_lattice
    state = _State(x=np.array(fem.rest, dtype=np.float64), s=0.0, points=points, refined=set(), order=order,
                   kappa=cm.kappa)
    phases = _Timer()
    ctx = dict(timer=timer, phases=phases, solver=SPDSolver())
    check_start(cm)
    steps = []
    free_motions = rigid.motion_basis(cm)
    state.pin_basis = free_motions[0]  # nothing touches A yet: every free rigid motion is pinned
    weakest = [None]  # (ratio, motion, s, contact radius) of the least resisted rigid motion of A

    def step_to(s, tolerate=False):
        """Solve the step from the current state to path length s; (record, undo token). With
        ``tolerate``, a step that cannot be solved gives (None, token) instead of ConvergenceError."""
        saved = replace(state, refined=set(state.refined))
        try:
            iters = _advance(cm, state, s, ctx, depth=0) if steps else _solve_at(cm, state, s, ctx)
            with phases.timed("rigid_check"):
                basis = _unresisted_basis(cm, state, free_motions)
            if basis.shape[1] < state.pin_basis.shape[1]:
                # contact now resists a motion this step held pinned: solve the step again without it
                prev, state.pin_basis = (state.prev, state.prev2), basis
                iters += _advance(cm, state, s, ctx, depth=0) if steps else _solve_at(cm, state, s, ctx)
                state.prev, state.prev2 = prev
                with phases.timed("rigid_check"):
                    basis = _unresisted_basis(cm, state, free_motions)
            state.pin_basis = basis
            with phases.timed("record"):
                return _record(cm, state, iters, ctx), saved
        except ConvergenceError:
            if not tolerate:
                raise
            return None, saved

    def undo(saved):
        for f in fields(saved):
            setattr(state, f.name, getattr(saved, f.name))

    def keep(rec):
        steps.append(rec)
        with phases.timed("rigid_check"):
            w = _weakest_rigid_motion(cm, state, free_motions)
        if w is not None and (weakest[0] is None or w[0] < weakest[0][0]):
            weakest[0] = w
        if callback is not None:
            callback(len(steps) - 1, rec)

    for s in progress(cm.s_steps, total=len(cm.s_steps), desc=f"insertion {cm.name}", quiet=quiet):
        keep(step_to(float(s))[0])
    rest = settle.to_rest(cm, steps, step_to, undo, keep)
    weakest = weakest[0]
    seconds = time.perf_counter() - t_start
    timer.add("total", seconds)
    warnings = settle.warnings(cm, steps, rest)
    notes = []
    if weakest is not None and weakest[0] < rigid.UNRESISTED_REL:
        notes.append(
            f"{cm.name}: nothing resists the part's rigid {rigid.describe(weakest[1], dim, weakest[3])} at "
            f"s={weakest[2]:.4g} m (the supports leave it free and the contact normals are perpendicular to "
            "it): the solver pins it where each step starts (no force acts along it)")
    if state.grad_peak > C.PSI_LIPSCHITZ:
        warnings.append(
            f"{cm.name}: the contact field's gradient reached {state.grad_peak:.3g} near the part (sharp features of "
            f"the object, e.g. rims, at the IMLS width sigma={cm.field.sigma:.3g} m), above the Lipschitz bound "
            f"{C.PSI_LIPSCHITZ:g} that certifies points outside the object between samples: penetrations between "
            "constraint points may go undetected there; sample the object more finely (smaller sigma)")
    phase_split = dict(phases.t)
    phase_split["other"] = seconds - sum(phase_split.values())
    return InsertionResult(model=cm, steps=steps, seconds=seconds, timings=dict(timer.t), phases=phase_split,
                           warnings=warnings, notes=notes)


def _unresisted_basis(cm: CouplingModel, state: _State, free_motions) -> np.ndarray:
    """(k, r) the free rigid motions that the contact at the current state leaves unresisted
    (:func:`simfab.coupling.rigid.unresisted`; all of them without contact)."""
    fin = _state_final(state)
    Q, c = free_motions
    if Q.shape[1] == 0:
        return Q
    if fin is None:
        return state.pin_basis if state.pin_basis is not None else Q
    d, gd = fin[4], fin[5]
    dh = _point_dhat(cm, state.points)
    act = (d < dh) & (np.einsum("kd,kd->k", gd, gd) > 0)
    if not act.any():
        return Q
    y = state.points.positions(state.x)[act]
    nrm = gd[act] / np.linalg.norm(gd[act], axis=1, keepdims=True)
    return rigid.unresisted(Q, c, y, nrm, barrier_hessian(d[act], dh[act]))


def _weakest_rigid_motion(cm: CouplingModel, state: _State, free_motions):
    """(ratio, motion, s, radius) of the rigid motion of A that the contact at the current state
    resists least (see :func:`simfab.coupling.rigid.weakest_motion`), or None without contact or
    free motion."""
    fin = _state_final(state)
    Q, c = free_motions
    if fin is None or Q.shape[1] == 0:
        return None
    d, gd = fin[4], fin[5]
    dh = _point_dhat(cm, state.points)
    act = (d < dh) & (np.einsum("kd,kd->k", gd, gd) > 0)
    if not act.any():
        return None
    y = state.points.positions(state.x)[act]
    nrm = gd[act] / np.linalg.norm(gd[act], axis=1, keepdims=True)
    out = rigid.weakest_motion(Q, c, y, nrm, barrier_hessian(d[act], dh[act]))
    if out is None:
        return None
    return out[0], out[1], state.s, float(np.sqrt(np.mean(np.sum((y - c) ** 2, axis=1))))


def check_start(cm: CouplingModel) -> None:
    """InputError unless O starts outside A (every boundary vertex of A outside O at s = 0)."""
    R, p = cm.pose(0.0)
    y = cm.fem.rest[np.asarray(cm.fem.boundary_vertices)]
    ev = cm.field.evaluate(y, (R, p), hessian=False)
    if np.any(ev.psi >= 0):
        raise InputError(f"the object starts inside the compliant part ({int((ev.psi >= 0).sum())} vertices inside "
                         "it at the first keyframe); move the first keyframe away", where="keyframes")


def _objective(cm, state, s, ctx) -> _StepObjective:
    """The step objective at path length s over the state's points, with its barrier stiffness and
    the pin of its unresisted rigid motions anchored at the state's positions."""
    R, p = cm.pose(s)
    pin = rigid.pin_for(cm, state.pin_basis, rigid.motion_basis(cm)[1], state.x)
    return _StepObjective(cm, state.points, R, p, ctx["timer"], state.kappa, pin)


def _adapt_kappa(cm: CouplingModel, state: _State, obj: _StepObjective) -> None:
    """IPC-style stiffness adaptation: when a converged step leaves a point closer to O than
    KAPPA_GROW_BELOW * d_hat (the barrier then works in its ill-conditioned 1/d^2 range), double
    kappa for the following steps (at most KAPPA_MAX_GROWTH times the initial value); a stiffer
    barrier keeps contact gaps ~ kappa d_hat^2 / f larger."""
    d = obj.last_d
    if d is None or not len(d):
        return
    if np.any(d < C.KAPPA_GROW_BELOW * obj.dhat) and state.kappa < C.KAPPA_MAX_GROWTH * cm.kappa:
        state.kappa = min(2.0 * state.kappa, C.KAPPA_MAX_GROWTH * cm.kappa)


def _newton(cm: CouplingModel, obj: _StepObjective, x0: np.ndarray, ctx) -> tuple[np.ndarray, int]:
    """Barrier Newton from x0. Stops when the free-dof force residual is below
    max(NEWTON_GRAD_TOL_REL * force_scale, NEWTON_GRAD_TOL_START * |residual at x0|) or the Newton
    step is below NEWTON_STEP_TOL_REL * h_A (projected Newton converges linearly once the PSD
    projections are active, so a purely absolute force target would spend many iterations on the
    last digits)."""
    from simfab.solve.newton import NewtonOptions, minimize

    _, g0, _ = obj(x0.ravel(), True)  # memoized: minimize's first evaluation reuses it
    g0n = float(np.abs(g0[cm.free]).max()) if cm.free.any() else 0.0
    scale = max(C.NEWTON_GRAD_TOL_REL * cm.force_scale, C.NEWTON_GRAD_TOL_START * g0n)
    opts = NewtonOptions(max_iter=C.NEWTON_MAX_ITER, grad_tol=1.0, grad_scale=scale,
                         step_tol=C.NEWTON_STEP_TOL_REL, x_scale=cm.h, eager_hessian=C.NEWTON_EAGER_HESSIAN,
                         eager_above_tol=C.NEWTON_EAGER_ABOVE_TOL)
    solver = _TimedSolver(_pinned(ctx["solver"], obj.pin), ctx["timer"])
    res = minimize(obj, x0.ravel(), free=cm.free, options=opts, max_step=obj.max_step, solver=solver)
    return res.x.reshape(x0.shape), res.iterations


def _pinned(solver, pin):
    """``solver`` with the rigid-mode pin's Woodbury update (rigid.PinnedSolver) when there is one."""
    return solver if pin is None else rigid.PinnedSolver(solver, pin)


class _TimedSolver:
    """SPDSolver wrapper that books factorization + solve time."""

    def __init__(self, solver, timer):
        self.solver, self.timer = solver, timer

    def solve(self, A, b):
        return self._timed(self.solver.solve, A, b)

    def solve_free(self, A, free, b):
        return self._timed(self.solver.solve_free, A, free, b)

    def _timed(self, fn, *args):
        with self.timer.timed("factorization"):
            return fn(*args)


def _solve_at(cm: CouplingModel, state: _State, s: float, ctx) -> int:
    """Solve at the current pose without moving O (step 0), with refinement."""
    total = 0
    for _ in range(C.MAX_REFINEMENT_ROUNDS):
        obj = _objective(cm, state, s, ctx)
        with ctx["phases"].timed("newton"):
            x, it = _newton(cm, obj, state.x, ctx)
        total += it
        final = _final_eval(obj, x)
        with ctx["phases"].timed("facet_check"):
            new = _crossing_facets(cm, x, s, state, final)
        if not new:
            _accept(state, x, s, obj, final)
            return total
        _add_refinement(cm, state, new)
    raise ConvergenceError("refinement did not settle at the start pose")


def _accept(state: _State, x: np.ndarray, s: float, obj: _StepObjective, final) -> None:
    """Make the converged x at path length s the current state, with the Hessian, final
    evaluation (``_final_eval(obj, x)``) and barrier stiffness of the objective it was solved with."""
    state.x, state.s = x, s
    state.final = final
    # the objective's last evaluation may be a rejected line-search trial (Newton stopping at the
    # round-off floor): its Hessian belongs to x only when the evaluation does
    state.H = obj.last_H if state.final is not None else None
    state.kappa_step = obj.kappa


def _advance(cm: CouplingModel, state: _State, s_new: float, ctx, depth: int) -> int:
    """Move O from state.s to s_new and re-equilibrate A (predictor, Newton, refinement)."""
    total = 0
    resume = None  # converged positions to resume from after a refinement (see below)
    refined = False  # points were added since the previous state was accepted
    for _ in range(C.MAX_REFINEMENT_ROUNDS):  # refinement restarts
        resumed = False
        try:
            with ctx["phases"].timed("warm_start"):
                obj = _objective(cm, state, s_new, ctx)
                x0 = None if resume is None else _lift_points(cm, state.points, resume, obj, below=0.0,
                                                              to=C.LIFT_TO * obj.dhat)
                resumed = x0 is not None
                if x0 is None:
                    if refined:  # starting over from the previous state: make it feasible for the new points
                        _restore_feasibility(cm, state, ctx)
                        refined = False
                    x0 = _warm_start(cm, state, s_new, obj, ctx)
            with ctx["phases"].timed("newton"):
                x, it = _newton(cm, obj, x0, ctx)
        except ConvergenceError:
            if resumed:  # the resumed solve failed: solve from the previous state instead
                resume = None
                continue
            if depth >= C.MAX_BISECTIONS:
                raise
            mid = 0.5 * (state.s + s_new)
            total += _advance(cm, state, mid, ctx, depth + 1)
            total += _advance(cm, state, s_new, ctx, depth + 1)
            return total
        total += it
        final = _final_eval(obj, x)
        with ctx["phases"].timed("facet_check"):
            new = _crossing_facets(cm, x, s_new, state, final) if cm.options.refine else []
        if not new:
            state.prev2, state.prev = state.prev, (state.x, state.s)
            _accept(state, x, s_new, obj, final)
            _adapt_kappa(cm, state, obj)
            return total
        # solve again from x with the new points lifted out of O (see _lift_points); should that
        # be infeasible or fail, from the previous state, which is feasible for the new points
        # (new facets were outside O there; denser points of refined facets were within the
        # tolerance and are pushed out first, when it comes to that)
        _add_refinement(cm, state, new)
        refined = True
        resume = x
    raise ConvergenceError(f"refinement did not settle at s={s_new:.6g} m")


def _lift_points(cm: CouplingModel, pts: ContactPoints, x: np.ndarray, obj, *, below: float,
                 to: float, prev: np.ndarray | None = None):
    """x with the constraint points at distance <= ``below`` [m] from O (inside it: d <= 0) moved
    out along O's normal to ``to`` [m], their facets' vertices taking the weighted mean of the
    wanted moves (a local move: the rest of A keeps its shape). With ``prev`` (k,), the points'
    gaps at the last step, points that were already that close keep their place. Returns x itself
    when nothing is that close, None when the result is infeasible."""
    # the objective's (lazy) distances: exact with gradients within its band (> below), lower
    # bounds without gradients beyond it, so only points near O are evaluated
    d, gd, _ = obj.distances(x, False)
    below, to = np.broadcast_to(below, d.shape), np.broadcast_to(to, d.shape)
    lift = (d <= below) & np.any(gd != 0.0, axis=1)
    if prev is not None:
        lift &= prev > below
    if not lift.any():
        return x
    x1 = _move_points(cm, pts, x, lift, to[lift] - d[lift], gd[lift])
    return x1 if np.isfinite(obj.value(x1)) else None


def _extrapolations(state: _State, s_new: float) -> list:
    """Linear (last two steps) and quadratic (last three, Lagrange) extrapolations of A's
    positions to s_new: warm-start candidates when the deformation evolves smoothly."""
    if state.prev is None or not state.prev[1] < state.s:
        return []
    xp, sp_ = state.prev
    out = [state.x + (state.x - xp) * ((s_new - state.s) / (state.s - sp_))]
    if state.prev2 is not None and state.prev2[1] < sp_:
        (x2, s2), (x1, s1), (xc, sc) = state.prev2, state.prev, (state.x, state.s)
        t = s_new
        l2 = (t - s1) * (t - sc) / ((s2 - s1) * (s2 - sc))
        l1 = (t - s2) * (t - sc) / ((s1 - s2) * (s1 - sc))
        lc = (t - s2) * (t - s1) / ((sc - s2) * (sc - s1))
        out.append(l2 * x2 + l1 * x1 + lc * xc)
    return out


def _warm_start(cm: CouplingModel, state: _State, s_new: float, obj, ctx) -> np.ndarray:
    """The feasible warm-start candidate with the lowest objective: the extrapolations (the chosen
    one with its contact gaps restored, :func:`_snap_contacts`) and the contact predictor
    (:func:`_predict`; with PREDICTOR_PENALTY_FALLBACK_ONLY only when no extrapolation is
    feasible). Raises ConvergenceError when no candidate is feasible."""
    best_x, best_f = None, np.inf
    if C.PREDICTOR_EXTRAPOLATE:
        for xc in _extrapolations(state, s_new):
            fc = obj.value(xc)
            if np.isfinite(fc) and fc < best_f:
                best_x, best_f = xc, fc
    if best_x is not None and C.PREDICTOR_SNAP_CONTACTS:
        xs = _snap_contacts(cm, state, best_x, s_new, ctx)
        fs = np.inf if xs is None else obj.value(xs)  # +inf: infeasible (inside O or inverted)
        if np.isfinite(fs):
            best_x, best_f = xs, fs
    if best_x is not None and C.WARM_START_FLOOR > 0:
        # a point that ends up almost touching O costs one Newton iteration per doubling of its
        # distance (the log barrier): start such points at LIFT_TO * d_hat instead
        fin = _state_final(state)
        prev = fin[4] if fin is not None else None
        xl = _lift_points(cm, state.points, best_x, obj, below=C.WARM_START_FLOOR * obj.dhat,
                          to=C.LIFT_TO * obj.dhat, prev=prev)
        if xl is not None and xl is not best_x:
            best_x, best_f = xl, obj.value(xl)
    if best_x is not None and C.PREDICTOR_PENALTY_FALLBACK_ONLY:
        return best_x
    try:
        x0 = _predict(cm, state, s_new, ctx)
    except ConvergenceError:
        if best_x is None:
            raise
        return best_x
    if best_x is None or obj.value(x0) <= best_f:
        return x0
    return best_x


def _snap_contacts(cm: CouplingModel, state: _State, x: np.ndarray, s_new: float, ctx) -> np.ndarray | None:
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
    fin = _state_final(state)
    pts = state.points
    if fin is None:
        return None
    d_prev = fin[4]
    act = d_prev < _point_dhat(cm, pts)
    if not act.any():
        return None
    R, p = cm.pose(s_new)
    with ctx["timer"].timed("contact"):
        ev = cm.field.evaluate(pts.positions(x)[act], (R, p), hessian=False)
    g = -ev.grad
    return _move_points(cm, pts, x, act, (d_prev[act] + ev.psi) * ev.near, g)


def _move_points(cm: CouplingModel, pts: ContactPoints, x: np.ndarray, sel: np.ndarray, dist: np.ndarray,
                 direction: np.ndarray) -> np.ndarray:
    """x with the points ``sel`` moved by ``dist`` (s,) [m] along ``direction`` (s, dim) (normalized
    here): each vertex takes the weighted mean of the moves of the selected points on it."""
    nrm = direction / np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-300)
    move = dist[:, None] * nrm
    rows = np.flatnonzero(sel)
    n = cm.fem.n_vertices
    wsum = pts.scatter(np.ones((len(move), 1)), n, rows=rows)[:, 0]
    shift = pts.scatter(move, n, rows=rows)
    hit = wsum > 0
    x1 = x.copy()
    x1[hit] += shift[hit] / wsum[hit, None]
    return x1


def _predict(cm: CouplingModel, state: _State, s_new: float, ctx) -> np.ndarray:
    """Feasible warm start at s_new (see the module docstring, step 1).

    Points O can reach during the step (distance below L |O's displacement there| + d_hat) are
    pushed along O's normal by O's normal displacement (they may slide tangentially, as in
    frictionless contact); the rest of A follows through one linear solve with the previous
    tangent stiffness. Points still inside O afterwards are carried fully (rigidly with O) and the
    solve is repeated; as a last resort every reachable point is carried rigidly.
    """
    timer = ctx["timer"]
    x = state.x
    dim = cm.dim
    Ra, pa = cm.pose(state.s)
    Rb, pb = cm.pose(s_new)
    M = Rb @ Ra.T  # world rigid map of the step: y -> M (y - pa) + pb

    def carry(z):
        z3 = np.zeros((len(z), 3))
        z3[:, :dim] = z
        return ((z3 - pa) @ M.T + pb)[:, :dim]

    pts = state.points
    y = pts.positions(x)
    with timer.timed("contact"):
        ev_a = cm.field.evaluate(y, (Ra, pa), hessian=False)
    delta = carry(y) - y
    reach = (-ev_a.psi < C.PSI_LIPSCHITZ * np.linalg.norm(delta, axis=1) + _point_dhat(cm, pts)) & ev_a.near
    if not reach.any():
        return x.copy()
    # O's outward normal at each point, carried with O to the new pose
    g = -ev_a.grad
    nrm = g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-300)
    nrm = nrm @ M[:dim, :dim].T
    push = np.einsum("kd,kd->k", nrm, delta)
    normal = reach & (push > 0)
    full = np.zeros(len(pts), dtype=bool)
    for _ in range(C.PREDICTOR_RETRIES + 1):
        x0 = _penalty_solve(cm, state, x, pts, normal & ~full, full, nrm, delta, ctx)
        d_new = _feasible_distances(cm, x0, s_new, pts, ctx)
        if d_new is not None and np.all(d_new > 0):
            return x0
        if d_new is None:
            full |= reach  # an element inverted: carry everything reachable rigidly
            continue
        bad = (d_new <= 0) & ~full
        if not bad.any():
            break
        full |= bad
    full = reach
    x0 = _penalty_solve(cm, state, x, pts, np.zeros_like(full), full, nrm, delta, ctx)
    d_new = _feasible_distances(cm, x0, s_new, pts, ctx)
    if d_new is not None and np.all(d_new > 0):
        return x0
    raise ConvergenceError(f"no feasible warm start for the step to s={s_new:.6g} m")


def _restore_feasibility(cm: CouplingModel, state: _State, ctx) -> None:
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
        delta = (0.5 * _point_dhat(cm, pts) - np.minimum(d, 0.0))[:, None] * nrm
        x1 = _penalty_solve(cm, state, state.x, pts, bad, np.zeros_like(bad), nrm, delta, ctx)
        if _feasible_distances(cm, x1, state.s, pts, ctx) is None:
            break
        state.x = x1
    raise ConvergenceError(f"could not push the new refinement points out of the object at s={state.s:.6g} m")


def _feasible_distances(cm, x0, s, pts, ctx):
    """Distances to O at s if x0 has no inverted element, else None."""
    from simfab.fem.neohookean import det_F

    with ctx["timer"].timed("assembly"):
        ok = np.all(det_F(cm.fem, x0) > 0)
    if not ok:
        return None
    R, p = cm.pose(s)
    with ctx["timer"].timed("contact"):
        ev = cm.field.evaluate(pts.positions(x0), (R, p), hessian=False)
    return -ev.psi


def _point_dhat(cm: CouplingModel, pts: ContactPoints) -> np.ndarray:
    """(k,) barrier activation distance of each constraint point [m]: dhat_rel times the local
    edge length there (the mean length of the boundary edges at a vertex, interpolated with the
    point's weights), so that the standoff stays a fixed small fraction of the local element size
    on graded meshes (memoized per point set)."""
    dh = pts.cache.get("dhat")
    if dh is None:
        hv = cm._cache.get("vertex_h")
        if hv is None:
            facets = np.asarray(cm.fem.boundary_facets, dtype=np.int64)
            a, c = _EDGE_PAIRS[cm.dim]
            e = np.vstack([facets[:, [i, j]] for i, j in zip(a, c)])
            L = np.linalg.norm(cm.fem.rest[e[:, 0]] - cm.fem.rest[e[:, 1]], axis=1)
            n = cm.fem.n_vertices
            cnt = np.bincount(e.ravel(), minlength=n)
            tot = np.bincount(e.ravel(), weights=np.repeat(L, 2), minlength=n)
            hv = cm._cache["vertex_h"] = np.where(cnt > 0, tot / np.maximum(cnt, 1), cm.h)
        dh = pts.cache["dhat"] = cm.options.dhat_rel * np.einsum("km,km->k", pts.weights, hv[pts.verts])
    return dh


def _point_slots(cm: CouplingModel, pts: ContactPoints) -> np.ndarray:
    """(k, nv, nv, dim, dim) positions in the Hessian's data of the blocks coupling each point's parents."""
    slots = pts.cache.get("slots")
    if slots is None:
        nv = pts.verts.shape[1]
        ia, ib = np.meshgrid(np.arange(nv), np.arange(nv), indexing="ij")
        rows = pts.verts[:, ia.ravel()].ravel()
        cols = pts.verts[:, ib.ravel()].ravel()
        slots = pts.cache["slots"] = cm.fem.pattern.block_slots(rows, cols).reshape(len(pts), nv, nv, cm.dim, cm.dim)
    return slots


def _penalty_solve(cm, state, x, pts, normal, full, nrm, delta, ctx) -> np.ndarray:
    """x + u, u minimizing 1/2 u^T H u + P/2 sum_j c_j(u)^2 over the free dofs, with
    c_j = n_j . (y_j(u) - delta_j) for ``normal`` points and |y_j(u) - delta_j| for ``full`` ones."""
    from simfab.fem.neohookean import energy_gradient_hessian

    n, dim = cm.fem.n_vertices, cm.dim
    H = state.H
    if isinstance(H, _LazyHessian):  # the PSD tangent is assembled only when the predictor runs
        H = state.H = H()
    if H is None:
        with ctx["timer"].timed("assembly"):
            _, _, H = energy_gradient_hessian(cm.fem, x)
            _regularize(cm, H, _diag_slots(cm))
        state.H = H
    pen = C.PREDICTOR_PENALTY * float(np.abs(H.data[_diag_slots(cm)]).max())
    sel = normal | full
    N = np.zeros((len(pts), dim, dim))
    N[normal] = np.einsum("ki,kj->kij", nrm[normal], nrm[normal])
    N[full] = np.eye(dim)
    N = N[sel]
    w = pts.weights[sel]
    blocks = pen * w[:, :, None, None, None] * w[:, None, :, None, None] * N[:, None, None, :, :]
    data = H.data.copy()
    np.add.at(data, _point_slots(cm, pts)[sel].ravel(), blocks.ravel())
    A = cm.fem.pattern.matrix(data)
    f_pt = pen * np.einsum("kij,kj->ki", N, delta[sel])  # penalty force per point
    rhs = pts.scatter(f_pt, n, rows=np.flatnonzero(sel)).ravel()
    fidx = np.flatnonzero(cm.free)
    pin = rigid.pin_for(cm, state.pin_basis, rigid.motion_basis(cm)[1], x)
    uf = _TimedSolver(_pinned(ctx["solver"], pin), ctx["timer"]).solve_free(A, fidx, rhs[fidx])
    u = np.zeros(n * dim)
    u[fidx] = uf
    return x + u.reshape(n, dim)


def _crossing_facets(cm: CouplingModel, x: np.ndarray, s: float, state: _State, final=None) -> list:
    """Facets to (re)refine at (x, s): unrefined boundary facets near O whose interior crosses into
    O, and, when a refined facet still penetrates O by more than the tolerance between its points,
    every refined facet again at twice the density (returned as the full list)."""
    if not cm.options.refine:
        return []
    ids, psi_max, refined = _facet_check(cm, x, s, state, final)
    if len(ids) == 0:
        return []
    if np.any(psi_max[refined] > cm.tol):
        limit = C.MAX_EDGE_SAMPLES if cm.dim == 2 else C.MAX_FACE_LATTICE
        if 2 * state.order > limit:
            raise ConvergenceError(f"refinement at density {state.order} still leaves a penetration of "
                                   f"{psi_max[refined].max():.3e} m > {cm.tol:.3e} m at s={s:.6g} m")
        state.order = 2 * state.order + (1 if cm.dim == 2 else 0)  # new points = the old check points
        _rebuild_points(cm, state)
        return sorted(state.refined | {int(f) for f in ids[psi_max > 0]})
    return [int(f) for f in ids[(psi_max > 0) & ~refined]]


_COVER = {2: 0.5, 3: 1.0 / np.sqrt(3.0)}  # max distance from a facet point to its nearest vertex / longest edge


def _facet_check(cm: CouplingModel, x: np.ndarray, s: float, state: _State, final=None):
    """Max psi over check points of each boundary facet that could reach into O at (x, s).

    Returns (facet ids (f,), max psi (f,) [m], refined (f,) bool). Unrefined facets are checked
    at the points refinement would add; refined facets at the denser check points (their own
    points plus the midpoints between them). A facet can only reach into O if one of its vertices
    is within L * cover of O, cover the largest distance from a point of the facet to its nearest
    vertex (at most the longest edge / sqrt(3) on a triangle, half the edge in 2D). Check points
    whose Lipschitz bound, from the facet's vertices or from their own values at earlier checks (in
    O's body frame), is negative are not evaluated; their bound stands in for psi. The result is
    remembered for the same (x, s).
    """
    memo = state.check
    if memo is not None and memo[0] is x and memo[1] == s and memo[2] == state.order:
        return memo[3]
    facets = np.asarray(cm.fem.boundary_facets, dtype=np.int64)
    R, p = cm.pose(s)
    bv = np.asarray(cm.fem.boundary_vertices)
    dv = np.full(cm.fem.n_vertices, np.inf)
    if final is not None and final[0] is x and len(final[4]) >= len(bv):
        # Newton's converged evaluation at x (the first len(bv) constraint points are the boundary
        # vertices, in vertex_points order): exact within the lazy band, lower bounds beyond it;
        # those beyond the kernel radius get the sharper nearest-sample bound
        dv[bv] = final[4][: len(bv)]
        state.grad_peak = max(state.grad_peak, _max_norm(final[5]))
        out = np.flatnonzero(dv[bv] > _point_dhat(cm, state.points)[: len(bv)] * C.LAZY_BAND_DHATS)
        nn = cm.field.nearest_sample(x[bv[out]], (R, p))
        far = nn >= cm.field.radius
        dv[bv[out[far]]] = np.maximum(dv[bv[out[far]]], cm.field.far_bound(nn[far]))
    else:
        ev = cm.field.evaluate(x[bv], (R, p), hessian=False)
        dv[bv] = -ev.psi
        state.grad_peak = max(state.grad_peak, _max_norm(ev.grad))
        far = ~ev.near
        if far.any():  # far vertices: a sharper lower bound of their distance than far_distance
            dv[bv[far]] = cm.field.far_lower_bound(x[bv[far]], (R, p))
    xf = x[facets]  # (F, nv, dim)
    a, c = _EDGE_PAIRS[cm.dim]
    edges2 = np.einsum("fed,fed->fe", xf[:, a] - xf[:, c], xf[:, a] - xf[:, c])  # (F, e) squared edge lengths
    # every point of a facet lies within `cover` of one of its vertices: half the edge (2D), and
    # longest edge / sqrt(3) on a triangle (the farthest point is the circumcentre when acute,
    # R = c / (2 sin gamma) with gamma >= 60 deg; else within half the longest edge). A facet whose
    # vertices are all farther than L * cover from O is certified outside by the vertex bounds.
    cover = np.sqrt(edges2.max(axis=1)) * _COVER[cm.dim]
    ids = np.flatnonzero(np.min(dv[facets], axis=1) <= C.PSI_LIPSCHITZ * cover)
    refined = np.zeros(len(facets), dtype=bool)
    refined[list(state.refined)] = True
    refined = refined[ids]
    psi_max = np.full(len(ids), -np.inf)
    for is_refined in (False, True):
        sel = refined if is_refined else ~refined
        if sel.any():
            w, gap_map = _check_lattice(cm.dim, state.order, is_refined)
            f_sel = ids[sel]
            xv = xf[f_sel]  # (f, nv, dim) the facets' vertices
            y = w @ xv  # (f, p, dim) check points
            # psi(y) <= psi(v) + L |y - v| for each vertex v of the facet: points this bounds below
            # zero are outside O and need no evaluation (their bound stands in for psi: every use
            # of psi_max only asks whether it is positive or above the tolerance)
            gap = np.sqrt(np.maximum(edges2[f_sel] @ gap_map, 0.0)).reshape(len(f_sel), len(w), -1)  # (f, p, nv)
            bound = C.PSI_LIPSCHITZ * gap - dv[facets[f_sel]][:, None, :]
            psi = bound[:, :, 0]
            for v in range(1, bound.shape[2]):  # min over the nv vertices (faster than min(axis=2))
                psi = np.minimum(psi, bound[:, :, v])
            # the same check points' values (or bounds) from earlier checks: O moved rigidly, so in
            # O's body frame psi is the same L-Lipschitz function and psi(y) <= psi(y') + L |b - b'|
            # with b, b' the body-frame positions now and then
            body = body_frame(y, (R, p))
            known_body, known_psi = _check_cache(cm, state, is_refined, len(w))
            step = body - known_body[f_sel]
            moved = np.sqrt(np.einsum("fpd,fpd->fp", step, step))
            psi = np.minimum(psi, np.where(np.isfinite(moved), known_psi[f_sel] + C.PSI_LIPSCHITZ * moved, np.inf))
            todo = psi >= 0.0
            if todo.any():
                ev = cm.field.evaluate(y[todo], (R, p), hessian=False)
                psi[todo] = ev.psi
                state.grad_peak = max(state.grad_peak, _max_norm(ev.grad))
            known_body[f_sel], known_psi[f_sel] = body, psi
            psi_max[sel] = psi.max(axis=1)
    out = (ids, psi_max, refined)
    state.check = (x, s, state.order, out)
    return out


def _max_norm(v: np.ndarray) -> float:
    """Largest row norm of (k, dim) v (0 when empty)."""
    return float(np.sqrt(np.einsum("kd,kd->k", v, v).max())) if len(v) else 0.0


_EDGE_PAIRS = {2: (np.array([0]), np.array([1])), 3: (np.array([0, 0, 1]), np.array([1, 2, 2]))}  # facet edges (a, c)


@functools.lru_cache(maxsize=32)
def _check_lattice(dim: int, order: int, refined: bool) -> tuple[np.ndarray, np.ndarray]:
    """(w (p, nv), G (edges, p * nv)) for the check points of a facet at refinement ``order``:
    their barycentric weights (refinement points for an unrefined facet, the denser check points
    for a refined one) and the map from the facet's squared edge lengths (f, edges) to the squared
    distances (f, p * nv) from each check point to each of the facet's vertices.

    For barycentric y = sum_a w_a v_a, |y - q|^2 = sum_a w_a |v_a - q|^2 - 1/2 sum_ac w_a w_c |v_a - v_c|^2;
    with q = v_b it is linear in the squared edge lengths: one small product per check instead of
    f * p * nv difference vectors. (Cached and read-only.)
    """
    w = check_weights(dim, order) if refined else facet_weights(dim, order)
    a, c = _EDGE_PAIRS[dim]
    b = np.arange(dim)
    wa, wc = w[:, a].T[:, :, None], w[:, c].T[:, :, None]  # (e, p, 1)
    G = (wa * (c[:, None, None] == b) + wc * (a[:, None, None] == b) - wa * wc).reshape(len(a), -1)
    w.flags.writeable = False
    G.flags.writeable = False
    return w, G


def _check_cache(cm: CouplingModel, state: _State, refined: bool, p: int):
    """(body positions (F, p, 3) [m], psi or an upper bound (F, p) [m]) of every boundary facet's
    check points at its last check (NaN / +inf: never checked) for unrefined or refined facets at
    the current density; reset when the density changes."""
    key = (refined, state.order, p)
    cache = state.check_cache.get(key)
    if cache is None:
        F = len(cm.fem.boundary_facets)
        cache = state.check_cache[key] = (np.full((F, p, 3), np.nan), np.full((F, p), np.inf))
    return cache


def _rebuild_points(cm: CouplingModel, state: _State) -> None:
    """Constraint points = boundary vertices + refinement points of every refined facet."""
    facets = np.asarray(cm.fem.boundary_facets, dtype=np.int64)
    pts = vertex_points(np.asarray(cm.fem.boundary_vertices, dtype=np.int64), cm.dim)
    if state.refined:
        ids = np.array(sorted(state.refined))
        pts = pts.concat(facet_points(facets, ids, facet_weights(cm.dim, state.order)))
    state.points = pts


def _add_refinement(cm: CouplingModel, state: _State, facet_ids: list) -> None:
    state.refined.update(int(f) for f in facet_ids)
    _rebuild_points(cm, state)


def _path_velocity(cm: CouplingModel, s: float, y: np.ndarray) -> np.ndarray:
    """(k, dim) velocity per unit path length of O's material points currently at y (central
    differences of O's pose, one-sided at the ends of the path)."""
    L = float(cm.path.length)
    h = 1e-6 * max(L, 1e-12)
    s0 = max(0.0, s - h)
    s1 = s + h if cm.end_direction is not None else min(L, s + h)  # straight on past the end
    R, p = cm.pose(s)
    dim = cm.dim
    y3 = np.zeros((len(y), 3))
    y3[:, :dim] = y
    out = []
    for si in (s0, s1):
        Ri, pi = cm.pose(si)
        out.append((y3 - p) @ (Ri @ R.T).T + pi)
    return ((out[1] - out[0]) / (s1 - s0))[:, :dim]


def _final_eval(obj: _StepObjective, x: np.ndarray):
    """(x, kappa, E, grad E (n, dim), d (k,), grad d (k, dim)) of the objective's last Hessian
    evaluation when it was at x (Newton's converged point), else None."""
    if obj.last_x is None or not np.array_equal(obj.last_x, x.ravel()):
        return None
    E, gE = obj.last_fem
    return (x, obj.kappa, E, gE, obj.last_d, obj.last_gd)


def _state_final(state: _State):
    """Newton's last evaluation (see :func:`_final_eval`) when it belongs to the current state:
    at state.x and over the current constraint points (a refinement since changes the points);
    else None."""
    fin = state.final
    if fin is None or fin[0] is not state.x or len(fin[4]) != len(state.points):
        return None
    return fin


def _record(cm: CouplingModel, state: _State, iters: int, ctx) -> StepResult:
    from simfab.fem.neohookean import energy_gradient
    from simfab.fem.stress import det_and_von_mises

    x = state.x
    n, dim = cm.fem.n_vertices, cm.dim
    R, p = cm.pose(state.s)
    pts = state.points
    fin = _state_final(state)
    if fin is not None and fin[1] == state.kappa_step:
        # Newton's last evaluation at x: exact distances within the lazy band (which contains the
        # barrier's support), certified lower bounds beyond it (zero barrier, outside O)
        E, gE, d, gd = fin[2], fin[3], fin[4], fin[5]
        psi_pts = -d
    else:
        E, gE = energy_gradient(cm.fem, x)
        ev = cm.field.evaluate(pts.positions(x), (R, p), hessian=False)
        d, gd, psi_pts = -ev.psi, -ev.grad, ev.psi
    B, gy, _ = point_barrier(d, gd, None, _point_dhat(cm, pts), state.kappa_step)
    gc = pts.scatter(gy, n)
    g = gE + gc
    fixed = ~cm.free.reshape(n, dim)
    reaction = np.where(fixed, g, 0.0).sum(axis=0)  # force of the support on A = force of A on O
    u = cm.direction(state.s)
    force = float(reaction @ u)
    path_force = float(np.einsum("kd,kd->", gy, _path_velocity(cm, state.s, pts.positions(x))))
    fc = -gc  # contact force on A's vertices
    grip = float(np.linalg.norm(0.5 * np.abs(fc).sum(axis=0)))
    dets, vm = det_and_von_mises(cm.fem, x)
    min_det = float(dets.min())
    if not min_det > 0:
        raise ConvergenceError(f"an element is inverted at s={state.s:.6g} m (min det F = {min_det:.3e})")
    _, psi_check, _ = _facet_check(cm, x, state.s, state)
    pen = float(max(0.0, psi_pts.max(initial=-np.inf), psi_check.max(initial=-np.inf)))
    if pen > cm.tol:
        raise ConvergenceError(f"penetration {pen:.3e} m exceeds the tolerance {cm.tol:.3e} m at s={state.s:.6g} m")
    pos, quat = (a.copy() for a in cm.pos_quat(state.s))
    return StepResult(
        s=state.s, pos=np.asarray(pos), quat=np.asarray(quat), x=x.copy(), energy=float(E), force=force,
        path_force=path_force, barrier_energy=float(B), grip=grip,
        max_von_mises=float(vm.max()), von_mises=vm, penetration=pen, min_det_F=min_det, iterations=int(iters),
        contact_points=len(pts), kappa=float(state.kappa_step),
    )
