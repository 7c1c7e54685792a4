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
   evolves smoothly along the path); the contact predictor above is computed only when no
   extrapolation is feasible (its PSD tangent stiffness is then assembled on demand). Either way
   the vertices that were in contact are moved back to their last gap to O (extrapolations and
   the predictor's pushes slide them along chords off O's curved surface, out of the barrier's
   range).
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

Layout: :func:`simulate` composes the stages, each in its own module: :mod:`.model` (the
CouplingModel and its steps), :mod:`.objective` (the per-step objective and its Newton solve),
:mod:`.predictor` (warm start), :mod:`.refine` (facet check and refinement), :mod:`.rigid` and
:mod:`.rigid_check` (unresisted rigid motions and their pin), :mod:`.settle` (continuing to rest,
profile checks), :mod:`.state` and :mod:`.timing`.

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

Element order: with ``options.element_order = 2`` A is the scene's mesh lifted to quadratic
elements (:class:`simfab.fem.p2.P2Model`); every stage reads the energy, det F and stress through
:mod:`simfab.fem.elastic` and the boundary it works on from ``cm.contact_facets`` (the linear
sub-facets of the quadratic boundary), so the loop is the same for both orders: constraint points
are all boundary nodes (corners and edge midpoints) plus refinement points on sub-facets, whose
parents share an element (the contact Hessian stays inside the FEM pattern). Inversion is checked
at the quadrature points (det F there), as the energy sees it.

Forces: the reaction at the fixed dofs is r = dE_total/dx there (the force the support applies to
A). By equilibrium of A it equals the force A exerts on O, so the insertion force is
F = sum r . u (u: unit direction of O's translation), negative when A resists the insertion.
Contact forces on A are f_a = -dB/dx_a; the grip force is || (1/2 sum |f_x|, 1/2 sum |f_y|,
1/2 sum |f_z|) ||.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, fields, replace

import numpy as np

from simfab.contact.barrier import point_barrier
from simfab.coupling import config as C
from simfab.coupling import predictor, rigid, settle
from simfab.coupling.model import CouplingModel, default_insertion_length, make_coupling_model  # noqa: F401 (public API)
from simfab.coupling.objective import _StepObjective, _adapt_kappa, _final_eval, _newton, _objective, _point_dhat  # noqa: F401
from simfab.coupling.points import vertex_points
from simfab.coupling.refine import _add_refinement, _crossing_facets, _facet_check
from simfab.coupling.rigid_check import _rigid_contact
from simfab.coupling.state import _State, _accept, _state_final
from simfab.coupling.timing import _Timer
from simfab.errors import ConvergenceError, InputError


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
    resists, pinned by the solver); refined_facets : ids (rows of ``model.contact_facets``) of the
    facets that carried refinement points at the end (``simulate``'s ``refined`` for a similar run)."""

    model: CouplingModel
    steps: list
    seconds: float
    timings: dict
    phases: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    refined_facets: tuple = ()

    def column(self, name: str) -> np.ndarray:
        return np.array([getattr(r, name) for r in self.steps], dtype=float)


def simulate(cm: CouplingModel, *, quiet: bool = True, callback=None, refined=()) -> InsertionResult:
    """Run the insertion along all steps of ``cm``; see the module docstring for the method.

    callback : optional ``callback(k, StepResult)`` after every step (it may raise to stop the run)
    refined : boundary facet ids (rows of ``cm.contact_facets``) to carry refinement points
        from the start, e.g. a similar run's ``refined_facets``. Facets are otherwise refined when
        a converged step finds them crossing into O, and that step is solved again: seeding a
        design candidate's run with the facets its initial shape's run refined saves those second
        solves (stand side: 20-28 % fewer Newton iterations). The figures differ by the contact
        discretization: facets dipping into O by less than the penetration tolerance are held out
        of it too (stand side: E_max, E_ss, F_rm, F_grip within 0.1 %, a near-jam F_in 1.2 %).

    Returns :class:`InsertionResult` (one :class:`StepResult` per step including the start pose).
    Raises ConvergenceError when a step cannot be solved to tolerance, InputError when O starts
    inside A.
    """
    from simfab._threads import single_threaded_blas

    with single_threaded_blas():  # small dense products in the loop (see simfab._threads)
        return _simulate(cm, quiet=quiet, callback=callback, refined=refined)


def _simulate(cm: CouplingModel, *, quiet: bool, callback, refined) -> InsertionResult:
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
    if len(refined) and cm.options.refine:
        ids = np.unique(np.asarray(refined, dtype=np.int64))
        if ids.min() < 0 or ids.max() >= len(cm.contact_facets):
            raise ValueError(f"refined: facet ids must lie in [0, {len(cm.contact_facets)})")
        _add_refinement(cm, state, [int(f) for f in ids])
    check_start(cm)
    steps = []
    free_motions = rigid.motion_basis(cm)
    state.pin_basis = free_motions[0]  # nothing touches A yet: every free rigid motion is pinned
    weakest = [None]  # (ratio, motion, s, contact radius) of the least resisted rigid motion of A
    weak_of = {}  # id(record) -> the least resisted rigid motion at its state (see _rigid_contact)

    def step_to(s, tolerate=False):
        """Solve the step from the current state to path length s; (record, undo token). With
        ``tolerate``, a step that cannot be solved gives (None, token) instead of ConvergenceError."""
        saved = replace(state, refined=set(state.refined))
        try:
            iters = _advance(cm, state, s, ctx, depth=0) if steps else _solve_at(cm, state, s, ctx)
            with phases.timed("rigid_check"):
                basis, weak = _rigid_contact(cm, state, free_motions)
            if basis.shape[1] < state.pin_basis.shape[1] and _pin_force(cm, state, saved.x) > C.PIN_FORCE_TOL:
                # contact now resists a motion this step held pinned, and the pin held it with a
                # force (not merely in balance): solve the step again without it
                prev, state.pin_basis = (state.prev, state.prev2), basis
                iters += _advance(cm, state, s, ctx, depth=0) if steps else _solve_at(cm, state, s, ctx)
                state.prev, state.prev2 = prev
                with phases.timed("rigid_check"):
                    basis, weak = _rigid_contact(cm, state, free_motions)
            state.pin_basis = basis
            with phases.timed("record"):
                rec = _record(cm, state, iters, ctx)
            weak_of[id(rec)] = weak
            return rec, saved
        except ConvergenceError:
            if not tolerate:
                raise
            return None, saved

    def undo(saved):
        for f in fields(saved):
            setattr(state, f.name, getattr(saved, f.name))

    def keep(rec):
        steps.append(rec)
        w = weak_of.get(id(rec))
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
                           warnings=warnings, notes=notes,
                           refined_facets=tuple(sorted(state.refined)))


def _pin_force(cm: CouplingModel, state: _State, anchor: np.ndarray) -> float:
    """Largest force the step's pin (anchored at ``anchor``, the step's start) exerts along its
    motions at the converged state, relative to Newton's force tolerance (NEWTON_GRAD_TOL_REL *
    force_scale): ~1 when the pinned motions were in balance anyway."""
    pin = rigid.pin_for(cm, state.pin_basis, rigid.motion_basis(cm)[1], anchor)
    if pin is None:
        return 0.0
    return float(np.abs(pin.force(state.x.ravel())).max()) / (C.NEWTON_GRAD_TOL_REL * cm.force_scale)


def check_start(cm: CouplingModel) -> None:
    """InputError unless O starts outside A (every boundary vertex of A outside O at s = 0)."""
    R, p = cm.pose(0.0)
    y = cm.fem.rest[np.asarray(cm.fem.boundary_vertices)]
    ev = cm.field.evaluate(y, (R, p), hessian=False)
    if np.any(ev.psi >= 0):
        raise InputError(f"the object starts inside the compliant part ({int((ev.psi >= 0).sum())} vertices inside "
                         "it at the first keyframe); move the first keyframe away", where="keyframes")


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
                x0 = None if resume is None else predictor._lift_points(cm, state.points, resume, obj, below=0.0,
                                                              to=C.LIFT_TO * obj.dhat)
                resumed = x0 is not None
                if x0 is None:
                    if refined:  # starting over from the previous state: make it feasible for the new points
                        predictor._restore_feasibility(cm, state, ctx)
                        refined = False
                    x0 = predictor._warm_start(cm, state, s_new, obj, ctx)
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


def _record(cm: CouplingModel, state: _State, iters: int, ctx) -> StepResult:
    from simfab.fem.elastic import det_and_von_mises, energy_gradient

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
