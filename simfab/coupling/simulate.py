"""Quasi-static insertion of a rigid object O into a compliant part A.

At every insertion step O is moved to its next pose along the path and A settles into

    minimize_x  E_d(x)   subject to  psi(y_j(x)) <= 0   for all constraint points y_j

(E_d: Neo-Hookean energy, psi: IMLS or exact signed distance of O, > 0 inside; y_j: A's boundary
nodes plus refinement points on boundary facets). Per step (interior point / IPC style):

1. predictor: the feasible extrapolation of the last converged steps with the lowest objective, or
   a contact predictor (points O could reach pushed along its normal, one linear solve);
2. corrector: Newton on E_d(x) + kappa sum_j b(-psi(y_j)) (log barrier b, :mod:`simfab.contact.barrier`),
   every step capped so that no point reaches O, kappa doubled after a step that ends too close;
3. refinement: facets whose interior crosses into O get extra constraint points, before the solve
   when the warm start already pushes them into O, else after it and the step re-solved;
4. check: max penetration <= ``penetration_tol_rel * h_A`` and no inverted element, else the step
   is bisected along the path up to ``MAX_BISECTIONS`` times, then ConvergenceError.

:func:`simulate_insertion` runs a :class:`simfab.coupling.stepper.Stepper` over the planned steps and
then to O's rest point (:mod:`.settle`); the stages are modules over typed state (:mod:`.state`,
:mod:`.objective`, :mod:`.predictor`, :mod:`.refine`, :mod:`.rigid_check`, :mod:`.rigid`, :mod:`.record`,
:mod:`.layout`, :mod:`.timing`). The same loop serves linear and quadratic elements (``element_order``).
The full method - cost control, the weak pin on unresisted rigid motions, the Lipschitz certificates,
element orders - is in docs/methods.md, "simfab.coupling.simulate"; forces: :mod:`simfab.coupling.record`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from simfab._threads import single_threaded_blas
from simfab.coupling import config as C
from simfab.coupling import rigid, settle
from simfab.coupling.guide import CoarseGuide
from simfab.coupling.model import CouplingModel, default_insertion_length, make_coupling_model  # noqa: F401
from simfab.coupling.record import StepResult  # noqa: F401 (public API)
from simfab.coupling.stepper import Stepper
from simfab.errors import InputError
from simfab.progress import progress


@dataclass(kw_only=True)
class InsertionResult:
    """One insertion run: its records, timings and notes.

    Args:
        model: the :class:`CouplingModel` simulated.
        steps: one :class:`StepResult` per step (the start pose first).
        seconds: wall time [s].
        timings: seconds per stage, each counted once (assembly, factorization, solves, contact_field,
            barrier, line_search, predictor; :mod:`simfab.coupling.timing`; they cut across phases) [s].
        phases: wall seconds per phase of the insertion loop, each counted once (warm_start, newton,
            facet_check, record, rigid_check; "other" is the rest of ``seconds``) [s].
        warnings: one line each (e.g. steps too coarse, an unfinished insertion, stress above yield).
        notes: one line each about how the run was solved (e.g. a rigid motion of A that nothing
            resists, pinned by the solver).
        refined_facets: ids (rows of ``model.contact_facets``) of the facets that carried refinement
            points at the end (``simulate_insertion``'s ``refined`` for a similar run).
        removal: with friction, one :class:`StepResult` per step of the removal (O moved back from where
            the insertion left it over the insertion's step positions, phase "remove"); empty without
            friction (removal is then the insertion played backwards).
        jammed_at: the path length [m] where a frictional insertion self-locked (see :func:`jammed`),
            None when it did not.
        guided_steps: solves whose warm start was a coarser run's candidate (``simulate_insertion``'s ``guide``).
        counts: how many times each stage of ``timings`` ran (machine-independent: "factorization" the
            numeric factorizations, "solves" Newton's linear solves, i.e. its iterations over every solve of
            the run, the rest search's discarded trials included, "assembly" the Hessian evaluations; the
            predictor's work books under "predictor" only).
    """

    model: CouplingModel
    steps: list
    seconds: float
    timings: dict
    phases: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    refined_facets: tuple = ()
    removal: list = field(default_factory=list)
    jammed_at: float | None = None
    guided_steps: int = 0
    counts: dict = field(default_factory=dict)

    def column(self, name: str, phase: str = "insert") -> np.ndarray:
        """One field of every record of a phase as an array.

        Args:
            name: a :class:`StepResult` field (``"force"``, ``"energy"``, ...).
            phase: "insert" or "remove".

        Returns:
            A float array, one value per record.
        """
        records = self.removal if phase == "remove" else self.steps
        return np.array([getattr(r, name) for r in records], dtype=float)


def simulate_insertion(cm: CouplingModel, *, quiet: bool = True, callback=None, refined=(), recorder=None,
             guide: CoarseGuide | None = None) -> InsertionResult:
    """Run the insertion along all steps of ``cm``; see the module docstring for the method.

    callback : optional ``callback(k, StepResult)`` after every step (it may raise to stop the run)
    refined : boundary facet ids (rows of ``cm.contact_facets``) to carry refinement points from the
        start, e.g. a similar run's ``refined_facets``. Facets are otherwise refined when a converged
        step finds them crossing into O, and that step is solved again: seeding a design candidate's
        run with the facets its initial shape's run refined saves those second solves. The figures
        differ by the contact discretization only (facets dipping into O by less than the penetration
        tolerance are held out of it too).
    recorder : optional ``recorder(StepResult, StepState)`` with every kept record and its converged
        state (:class:`simfab.coupling.stepper.Stepper`), e.g. the adjoint sensitivities
        (:class:`simfab.coupling.adjoint.SensitivityRecorder`); it does not change the run.
    guide : optional :class:`simfab.coupling.guide.CoarseGuide`, a coarser run of the same insertion
        whose states, prolonged to this mesh, are offered as warm starts (a two-grid start: fewer
        Newton iterations on big moves; the records are this run's equilibria to Newton's tolerance).

    Returns :class:`InsertionResult` (one :class:`StepResult` per step including the start pose).
    Raises ConvergenceError when a step cannot be solved to tolerance, InputError when O starts
    inside A.
    """
    with single_threaded_blas():  # small dense products in the loop (see simfab._threads)
        t_start = time.perf_counter()
        stepper = Stepper(cm, refined=refined, callback=callback, recorder=recorder, guide=guide)
        check_start(cm)
        jam = None
        for s in progress(cm.s_steps, total=len(cm.s_steps), desc=f"insertion {cm.name}", quiet=quiet):
            stepper.keep(stepper.step(float(s)).record)
            if jammed(stepper.steps):
                jam = stepper.steps[-1].s
                break
        rest = settle.to_rest(cm, stepper) if jam is None else "jammed"
        if stepper.history_dependent and jam is None:
            remove(stepper, quiet=quiet)
        return _result(stepper, rest, jam, time.perf_counter() - t_start)


#: A frictional insertion jams when, on this many consecutive steps, more than JAM_LOCKED_REL of the
#: normal contact force sits at self-locked points (:class:`simfab.coupling.friction.FrictionRecord`).
JAM_STEPS = 2
JAM_LOCKED_REL = 0.5


def jammed(steps: list) -> bool:
    """The last JAM_STEPS insertion records are self-locked: O is pushed inside the friction cone of
    the contact carrying most of the normal force, which sticks, so A cannot slide out of its way
    and is dragged along (a snap-fit whose face angle alpha has mu tan alpha >= 1)."""
    last = steps[-JAM_STEPS:]
    return len(last) == JAM_STEPS and all(r.normal_force > 0 and r.locked > JAM_LOCKED_REL for r in last)


#: The removal turns O around in steps of h / 2^k (k = TURN_STEPS ... 1, h the planned step) before it
#: follows the insertion's positions: where O turns, the contact first sticks while the part's
#: tangential strain (left by friction dragging it) relaxes, and the friction force swings from one
#: side of the cone to the other over that travel; steps much longer than it would not resolve the
#: swing (the energy balance), nor the onset of sliding F_hold is read at.
TURN_STEPS = 6


def remove(stepper: Stepper, *, quiet: bool = True) -> None:
    """The removal as its own quasi-static traversal: O moved back from where the insertion left it,
    first by TURN_STEPS graded steps, then over the insertion's step positions to the start (records
    of phase "remove")."""
    s_end = stepper.steps[-1].s
    h = float(np.diff(stepper.cm.s_steps).mean())
    turn = [s_end - h / 2**k for k in range(TURN_STEPS, 0, -1) if s_end - h / 2**k > 0]
    last = turn[-1] if turn else s_end
    s_back = turn + [float(s) for s in stepper.cm.s_steps[::-1] if s < last * (1 - 1e-12)]
    stepper.reverse()
    for s in progress(s_back, total=len(s_back), desc=f"removal {stepper.cm.name}", quiet=quiet):
        stepper.keep(stepper.step(s).record)


def _result(stepper: Stepper, rest: str, jam: float | None, seconds: float) -> InsertionResult:
    """The run's result, its warnings (:func:`simfab.coupling.settle.warnings`) and notes."""
    cm, state, ctx = stepper.cm, stepper.state, stepper.ctx
    ctx.timer.add("total", seconds)
    warnings = settle.warnings(cm, stepper.steps, rest, removal=stepper.removal)
    if jam is not None:
        warnings.append(f"{cm.name}: the insertion jams at s={jam * 1e3:.4g} mm (friction mu={cm.contact.friction:g}): "
                        "the object pushes inside the friction cone of the contact, which sticks, and drags the part "
                        "along; the run stops there (no removal)")
    notes = []
    w = stepper.weakest
    if w is not None and w.ratio < rigid.UNRESISTED_REL:
        notes.append(
            f"{cm.name}: nothing resists the part's rigid {rigid.describe(w.motion, cm.dim, w.radius)} at "
            f"s={w.s:.4g} m (the supports leave it free and the contact normals are perpendicular to "
            "it): the solver pins it where each step starts (no force acts along it)")
    if state.grad_peak > C.PSI_LIPSCHITZ:
        warnings.append(
            f"{cm.name}: the contact field's gradient reached {state.grad_peak:.3g} near the part (sharp features of "
            f"the object, e.g. rims, at the IMLS width sigma={cm.field.sigma:.3g} m), above the Lipschitz bound "
            f"{C.PSI_LIPSCHITZ:g} that certifies points outside the object between samples: penetrations between "
            "constraint points may go undetected there; sample the object more finely (smaller sigma)")
    phases = dict(ctx.phases.t)
    phases["other"] = seconds - sum(phases.values())
    return InsertionResult(model=cm, steps=stepper.steps, seconds=seconds, timings=dict(ctx.timer.t), phases=phases,
                           warnings=warnings, notes=notes, refined_facets=tuple(sorted(state.refined)),
                           removal=stepper.removal, jammed_at=jam, guided_steps=ctx.guided,
                           counts=dict(ctx.timer.n))


def check_start(cm: CouplingModel) -> None:
    """InputError unless O starts outside A (every boundary vertex of A outside O at s = 0)."""
    R, p = cm.pose(0.0)
    y = cm.fem.rest[np.asarray(cm.fem.boundary_vertices)]
    ev = cm.field.evaluate(y, (R, p), hessian=False)
    if np.any(ev.psi >= 0):
        raise InputError(f"the object starts inside the compliant part ({int((ev.psi >= 0).sum())} vertices inside "
                         "it at the first keyframe); move the first keyframe away", where="keyframes")
