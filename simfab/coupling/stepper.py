"""One insertion step after another: :class:`Stepper` moves O to a path length, lets A settle
(warm start, barrier Newton, refinement; see :mod:`simfab.coupling.simulate` for the method),
checks the rigid motions the contact leaves free and records the step. ``step`` solves a step from
the current state, ``undo`` returns to the state before it, ``keep`` appends its record to the run:
the loop over the planned steps and the search for O's rest point past them
(:func:`simfab.coupling.settle.to_rest`) are both written with these three.

The stages a step runs are public functions of the model, the :class:`~simfab.coupling.state.StepState`
and the :class:`~simfab.coupling.state.StepContext`: :func:`solve_at` (step 0, O not moving) and
:func:`advance` (O moving), which compose :mod:`.objective`, :mod:`.predictor` and :mod:`.refine`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

from simfab.coupling import config as C
from simfab.coupling import friction, predictor, rigid
from simfab.coupling.friction import FrictionLag
from simfab.coupling.guide import CoarseGuide
from simfab.coupling.model import CouplingModel
from simfab.coupling.objective import adapt_kappa, evaluation, make_objective, solve
from simfab.coupling.points import vertex_points
from simfab.coupling.record import StepResult, record_step
from simfab.coupling.refine import add_refinement, crossing_facets, warm_crossings
from simfab.coupling.rigid_check import WeakMotion, rigid_contact
from simfab.coupling.state import PastStep, StepContext, StepState, accept, step_solver
from simfab.errors import ConvergenceError


@dataclass(frozen=True, eq=False)
class StepAttempt:
    """A solved (or failed) step: its record (None when ``step(..., tolerate=True)`` could not solve
    it) and the state before it (what :meth:`Stepper.undo` returns to)."""

    record: StepResult | None
    before: StepState


class Stepper:
    """The insertion run of ``cm`` step by step (see the module docstring).

    refined : boundary facet ids (rows of ``cm.contact_facets``) carrying refinement points from the
    start; callback : optional ``callback(k, StepResult)`` after every kept step (it may raise to
    stop the run); recorder : optional ``recorder(StepResult, StepState)`` called with every kept
    record and the converged state it was recorded at, its ``pin_basis`` the pin it was solved with
    and ``prev`` the state it was solved from (the pin's and the friction anchors' origin; e.g.
    :class:`simfab.coupling.adjoint.SensitivityRecorder`); guide : optional
    :class:`simfab.coupling.guide.CoarseGuide` (warm-start candidates from a coarser run, see
    :func:`simfab.coupling.predictor.warm_start`). Attributes: ``state`` (:class:`StepState`),
    ``ctx`` (:class:`StepContext`),
    ``steps`` (the kept insertion records), ``removal`` (the kept removal records, see
    :meth:`reverse`), ``weakest`` (the least resisted rigid motion over the kept steps)."""

    def __init__(self, cm: CouplingModel, *, refined=(), callback=None, recorder=None,
                 guide: CoarseGuide | None = None):
        self.cm, self.callback, self.recorder = cm, callback, recorder
        self._states: dict[int, StepState] = {}  # id(record) -> the state it was recorded at (with a recorder)
        self.ctx = StepContext(guide=guide, solver=step_solver(cm.fem))
        order = cm.options.samples_per_edge if cm.dim == 2 else cm.options.face_lattice
        self.state = StepState(x=np.array(cm.fem.rest, dtype=np.float64), s=0.0, refined=set(), order=order,
                               points=vertex_points(np.asarray(cm.fem.boundary_vertices, dtype=np.int64), cm.dim),
                               kappa=cm.kappa)
        if len(refined) and cm.options.refine:
            ids = np.unique(np.asarray(refined, dtype=np.int64))
            if ids.min() < 0 or ids.max() >= len(cm.contact_facets):
                raise ValueError(f"refined: facet ids must lie in [0, {len(cm.contact_facets)})")
            add_refinement(cm, self.state, ids)
        self.free_motions = rigid.motion_basis(cm)
        self.state.pin_basis = self.free_motions[0]  # nothing touches A yet: every free rigid motion is pinned
        self.steps: list[StepResult] = []
        self.removal: list[StepResult] = []
        self.weakest: WeakMotion | None = None
        self._weak: dict[int, WeakMotion | None] = {}  # id(record) -> its state's least resisted motion

    def step(self, s: float, *, tolerate: bool = False) -> StepAttempt:
        """Solve the step from the current state to path length s [m] (the first step solves at s
        without moving O). With ``tolerate``, a step that cannot be solved gives a record of None
        instead of raising ConvergenceError (the state is then undefined until :meth:`undo`)."""
        cm, state, phases = self.cm, self.state, self.ctx.phases
        before = replace(state, refined=set(state.refined))
        try:
            solved_pin = state.pin_basis  # the pin the step's solution was solved with (see _states)
            solved_from = None  # the state it was solved from when that is not state.prev
            iters = self._solve(s)
            with phases.timed("rigid_check"):
                contact = rigid_contact(cm, state, self.free_motions)
            if (contact.basis.shape[1] < state.pin_basis.shape[1]
                    and self._pin_force(before.x) > C.PIN_FORCE_TOL):
                # contact now resists a motion this step held pinned, and the pin held it with a
                # force (not merely in balance): solve the step again without it (with friction from
                # the step's start: the friction of a step depends on where it started)
                if self.history_dependent:
                    self.undo(StepAttempt(None, before))
                    state.pin_basis = solved_pin = contact.basis
                    iters += self._solve(s)
                else:
                    prev, state.pin_basis = (state.prev, state.prev2), contact.basis
                    solved_pin = contact.basis
                    solved_from = PastStep(state.x, state.s)  # the second solve starts from the first's solution
                    iters += self._solve(s)
                    state.prev, state.prev2 = prev
                with phases.timed("rigid_check"):
                    contact = rigid_contact(cm, state, self.free_motions)
            state.pin_basis = contact.basis
            with phases.timed("record"):
                rec = record_step(cm, state, iters)
            self._weak[id(rec)] = contact.weakest
            if self.recorder is not None:  # the state as recorded (the bracket keeps records after later trials)
                self._states[id(rec)] = replace(state, refined=set(state.refined), pin_basis=solved_pin,
                                                prev=state.prev if solved_from is None else solved_from)
            return StepAttempt(rec, before)
        except ConvergenceError:
            if not tolerate:
                raise
            return StepAttempt(None, before)

    def undo(self, attempt: StepAttempt) -> None:
        """Return to the state before ``attempt``."""
        for f in fields(attempt.before):
            setattr(self.state, f.name, getattr(attempt.before, f.name))

    def keep(self, record: StepResult) -> None:
        """Append ``record`` (a solved step's) to the run (its insertion or removal records by its phase)."""
        kept = self.removal if record.phase == "remove" else self.steps
        kept.append(record)
        w = self._weak.get(id(record))
        if w is not None and (self.weakest is None or w.ratio < self.weakest.ratio):
            self.weakest = w
        if self.recorder is not None:
            self.recorder(record, self._states.pop(id(record)))
        if self.callback is not None:
            self.callback(len(self.steps) + len(self.removal) - 1, record)

    @property
    def history_dependent(self) -> bool:
        """A step's solution depends on the state it starts from (friction), not only on O's pose:
        the run must not step back and forth over the same path."""
        return self.cm.contact.friction > 0

    def reverse(self) -> None:
        """Turn O around: the following steps move it back along the path (removal records)."""
        self.state.direction = -1

    def _solve(self, s: float) -> int:
        if self.steps:
            return advance(self.cm, self.state, s, self.ctx)
        return solve_at(self.cm, self.state, s, self.ctx)

    def _pin_force(self, anchor: np.ndarray) -> float:
        """Largest force the step's pin (anchored at ``anchor``, the step's start) exerts along its
        motions at the converged state, relative to Newton's force tolerance (NEWTON_GRAD_TOL_REL *
        force_scale): ~1 when the pinned motions were in balance anyway."""
        cm, state = self.cm, self.state
        pin = rigid.pin_for(cm, state.pin_basis, self.free_motions[1], anchor)
        if pin is None:
            return 0.0
        return float(np.abs(pin.force(state.x.ravel())).max()) / (C.NEWTON_GRAD_TOL_REL * cm.force_scale)


def solve_at(cm: CouplingModel, state: StepState, s: float, ctx: StepContext) -> int:
    """Solve at the current pose without moving O (step 0), with refinement; Newton iterations."""
    total = 0
    for _ in range(C.MAX_REFINEMENT_ROUNDS):
        obj = make_objective(cm, state, s, ctx)
        with ctx.phases.timed("newton"):
            x, it = solve(cm, obj, state.x, ctx)
        total += it
        final = evaluation(obj, x)
        with ctx.phases.timed("facet_check"):
            new = crossing_facets(cm, x, s, state, final)
        if not new:
            accept(state, x, s, obj.kappa, final)
            return total
        add_refinement(cm, state, new)
    raise ConvergenceError("refinement did not settle at the start pose")


def lag_floor(cm: CouplingModel, lagged: FrictionLag) -> float:
    """Force residual [N] a lagging iteration's solve stops at: LAG_RESIDUAL_REL * lag_tol times the
    largest lagged normal force (see :data:`simfab.coupling.config.LAG_RESIDUAL_REL`)."""
    return C.LAG_RESIDUAL_REL * cm.contact.lag_tol * float(lagged.normal_force.max(initial=0.0))


def start_lag(cm: CouplingModel, state: StepState, s_new: float) -> FrictionLag:
    """The friction lag of the step from the current state to s_new over the state's points: anchors
    carried rigidly with O over the step, normals from the step's start (Newton's evaluation there
    when it covers the current points, else the field at the start pose) and normal forces
    extrapolated linearly in s from the last two steps when both have them over the same points (else
    the start's): the lagging iterations then start closer to the step's own normal forces."""
    pts = state.points
    rotation = cm.motion(state.s, s_new)[0]
    y = pts.positions(state.x)
    ev = state.current_evaluation()
    if ev is not None:
        d, gd, kappa = ev.distances, ev.distance_gradients, ev.kappa
    else:
        R, p = cm.pose(state.s)
        field = cm.field.evaluate(y, (R, p), hessian=False)
        d, gd, kappa = -field.psi, -field.grad, state.kappa_step or state.kappa
    anchors = cm.carry(y, state.s, s_new)
    lam = friction.normal_forces(cm, pts, d, kappa)
    prev = state.prev
    if (prev is not None and prev.points is pts and prev.normal_force is not None
            and (state.s - prev.s) * (s_new - state.s) > 0):
        lam = np.maximum(lam + (lam - prev.normal_force) * ((s_new - state.s) / (state.s - prev.s)), 0.0)
    return friction.lag(cm, pts, anchors, anchors - y, d, gd, kappa, rotation=rotation, normal_force=lam)


def advance(cm: CouplingModel, state: StepState, s_new: float, ctx: StepContext, depth: int = 0) -> int:
    """Move O from state.s to s_new and re-equilibrate A (warm start, Newton, refinement, and with
    friction the lagging iterations: the step solved again with the normal forces and tangents of
    its own solution until they change by less than ``lag_tol``, each solved to the residual
    :func:`lag_floor` only, then once more to Newton's tolerance with the settled lag); a step that
    cannot be solved is bisected up to MAX_BISECTIONS deep. Returns the Newton iterations."""
    total = 0
    start = ""
    resume = None  # converged positions to resume from after a refinement (see below)
    refined = False  # points were added since the previous state was accepted
    frictional = cm.contact.friction > 0
    lagged, lag_solves, lag_change = None, 0, 0.0
    settled = not frictional  # the lag has settled: solve to Newton's tolerance (else to lag_floor)
    rounds = 0
    while True:
        resumed = False
        try:
            with ctx.phases.timed("warm_start"), ctx.timer.into("predictor"):
                if frictional and (lagged is None or lagged.points is not state.points):
                    lagged = start_lag(cm, state, s_new)
                obj = make_objective(cm, state, s_new, ctx, lagged)
                if isinstance(resume, _Lagged):  # a lagging iteration: from the converged positions
                    x0, resumed = resume.x, True
                else:
                    x0 = None if resume is None else predictor.lift_points(cm, state.points, resume, obj, below=0.0,
                                                                           to=C.LIFT_TO * obj.dhat)
                    resumed = x0 is not None
                resting = None if x0 is not None or refined else predictor.resting_start(cm, state, obj)
                if resting is not None:  # A rests out of O's reach: its positions are the solution
                    x0 = resting
                if x0 is None:
                    if refined:  # starting over from the previous state: make it feasible for the new points
                        predictor.restore_feasibility(cm, state, ctx)
                        refined = False
                    ws = predictor.warm_start(cm, state, s_new, obj, ctx)
                    x0, start = ws.x, ws.source
                    # facets the warm start already pushes into O: refined before the solve (else
                    # Newton converges with them crossing and the step is solved again); frictionless
                    # runs only (with friction the refined set's history is part of the solution's)
                    ahead = [] if frictional else warm_crossings(cm, x0, s_new, state, obj.known_distances(x0))
                    if ahead and rounds + 1 < C.MAX_REFINEMENT_ROUNDS:
                        rounds += 1
                        add_refinement(cm, state, ahead)
                        refined, resume = True, x0
                        continue
            with ctx.phases.timed("newton"):
                x, it = solve(cm, obj, x0, ctx, floor=0.0 if settled else lag_floor(cm, lagged),
                              converged=resting is not None)
        except ConvergenceError:
            if resumed:  # the resumed solve failed: solve from the previous state instead
                resume = None
                continue
            if depth >= C.MAX_BISECTIONS:
                raise
            mid = 0.5 * (state.s + s_new)
            total += advance(cm, state, mid, ctx, depth + 1)
            total += advance(cm, state, s_new, ctx, depth + 1)
            return total
        total += it
        final = evaluation(obj, x)
        with ctx.phases.timed("facet_check"):
            new = crossing_facets(cm, x, s_new, state, final) if cm.options.refine else []
        if not new:
            if frictional:
                if final is None:
                    d, gd, _ = obj.distances(x, False)
                else:
                    d, gd = final.distances, final.distance_gradients
                fresh = friction.lag(cm, state.points, lagged.anchors, lagged.travel, d, gd, obj.kappa)
                if not settled:
                    lag_solves += 1
                    lag_change = fresh.change(lagged)
                    if lag_change > cm.contact.lag_tol and lag_solves < cm.contact.max_lag_iterations:
                        lagged, resume = fresh, _Lagged(x)
                        continue
                    settled, resume = True, _Lagged(x)  # once more, to Newton's tolerance with the same lag
                    continue
            past = PastStep(state.x, state.s, state.normal_force_points, state.normal_force)
            state.prev2, state.prev = state.prev, past
            accept(state, x, s_new, obj.kappa, final, start)
            state.friction, state.lag_solves, state.lag_change = lagged, lag_solves, lag_change
            state.normal_force = fresh.normal_force if frictional else None
            state.normal_force_points = state.points if frictional else None
            adapt_kappa(cm, state, obj)
            return total
        # solve again from x with the new points lifted out of O (see predictor.lift_points); should
        # that be infeasible or fail, from the previous state, which is feasible for the new points
        # (new facets were outside O there; denser points of refined facets were within the
        # tolerance and are pushed out first, when it comes to that)
        rounds += 1
        if rounds >= C.MAX_REFINEMENT_ROUNDS:
            raise ConvergenceError(f"refinement did not settle at s={s_new:.6g} m")
        add_refinement(cm, state, new)
        refined = True
        resume = x
        settled = not frictional


@dataclass(frozen=True, eq=False)
class _Lagged:
    """Converged positions x (n, dim) to solve a lagging iteration from (they need no lift)."""

    x: np.ndarray
