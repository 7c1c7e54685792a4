"""Rest-shape design by gradients: a trust-region SQP (:mod:`simfab.design.sqp`) over the handle parameters.

:func:`optimize_gradient` descends on z = (h - lower) / (upper - lower) in [0, 1] from the initial
shape, one insertion per iteration, with the figure gradients of :mod:`simfab.design.figure_gradients`.
The objective's model needs no simulation (E_L is quadratic in h, :func:`modification_hessian`;
profile matching's rms^2 a Gauss-Newton model of the force samples,
:func:`~simfab.design.figure_gradients.target_model`);
only the brief's constraints are linearized from the insertion, scaled to their SCALES units,
(value - lo) / scale >= 0 and (hi - value) / scale >= 0 (:class:`ConstraintRow`; a loose grip's
coupling-ratio bound in sqrt(CR)), aimed AIM_REL inside the bound. The element-quality bound
q_e / q0_e >= QUALITY_REL holds exactly in every subproblem, so no trial is an inverted mesh.

Starts without a direction: a part that touches nothing linearizes the seat clearance through the
undeformed part's gap (:func:`~simfab.design.figure_gradients.gap_gradient`); a start that ejects at
an end pose continues its coupling ratio above 100 % (:func:`~simfab.design.figure_gradients.ejecting_ratio`);
only when neither helps (:func:`flat_start`) a seeded annealing pre-phase runs until a design is in
the brief's category (:func:`in_category`). Target matching restarts the SQP from its best design at
the initial radius when the trust region collapsed (at most RESTARTS times). The best design is the
feasible one with the lowest objective among all simulated (else the lowest penalized objective).
Every candidate runs at the initial shape's planned step positions (``EvaluationConfig.hold_steps``).
The full derivation: docs/design-gradients.md.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np

from simfab.coupling.adjoint import SensitivityRecorder
from simfab.coupling.profile import analyze_run
from simfab.design import brief as B
from simfab.design.figure_gradients import (  # the figure gradients, re-exported for their callers
    TEMPERATURE_REL,
    WEIGHT_FLOOR,
    DeferredRecorder,
    FigureGradients,
    TargetModel,
    design_recorder,
    ejecting_ratio,
    figure_gradients,
    gap_gradient,
    handle_jacobian,
    modification_gradient,
    needed_records,
    quality_jacobian,
    removal_gradients,
    rest_grip_gradient,
    stress_measure,
    target_model,
)
from simfab.design.optimize import OptimizationResult, optimize_anneal
from simfab.design.problem import (
    QUALITY_REL,
    DesignEvaluation,
    DesignProblem,
    element_quality,
    evaluate,
    initial_evaluation,
    score_figures,
)
from simfab.design.sqp import CheapConstraints, Sample, SQPConfig, trust_region_sqp
from simfab.errors import ConvergenceError
from simfab.progress import log

#: [contact] lag_tol the gradient method runs frictional insertions with (at most): the adjoint
#: differentiates each step at its converged lag, and at a looser lag the figures jump with the
#: number of lagging iterations (docs/decisions.md, "Design by gradients").
GRADIENT_LAG_TOL = 1e-2
@dataclass(kw_only=True)
class _Run:
    """The optimizer's bookkeeping: every design simulated, in order."""

    problem: DesignProblem
    Jh: np.ndarray
    evaluations: list = field(default_factory=list)
    memo: dict = field(default_factory=dict)
    insertions: int = 0
    gradient_evaluations: int = 0
    signatures: list = field(default_factory=list)  # per complete insertion: its discrete features (events)


@dataclass(frozen=True, kw_only=True, eq=False)
class _Evaluated:
    """One simulated design: the evaluation, its :class:`FigureGradients` (None unless complete) and
    (target matching) the records' force derivatives dF_k/dh (k, n_vars) at fixed positions."""

    ev: DesignEvaluation
    fg: FigureGradients | None
    force_jacobian: np.ndarray | None = None


def _key(h: np.ndarray) -> np.ndarray:
    """A design's memo key (z -> h round trips differ in the last bits)."""
    return np.round(np.asarray(h, float), 12)


def _evaluate(run: _Run, h: np.ndarray) -> _Evaluated:
    """Design h simulated with its sensitivities, memoized (a design is never simulated twice)."""
    key = _key(h).tobytes()
    out = run.memo.get(key)
    if out is not None:
        return out
    problem = run.problem
    if (problem.initial_recorder is not None and problem.initial is not None and not problem.settings.refined
            and np.array_equal(h, problem.handles.identity())):
        # the initial shape's insertion, run before the optimization with its recorder (the same run:
        # hold_steps is the initial shape's own steps); scored with this problem's settings
        ev = initial_evaluation(problem)
        ev.recorder = problem.initial_recorder
    else:
        ev = evaluate(problem, h, keep_result=True,
                      recorder=lambda cm: DeferredRecorder(cm, stress_measure(problem, cm)))
    if ev.sim_seconds > 0:
        run.insertions += 1
    fg, dF = None, None
    if ev.status == "ok":
        fg = figure_gradients(problem, ev, run.Jh)
        run.gradient_evaluations += 1
        if problem.target is not None:
            dF = fg.gradients["force_samples"]
    ev.recorder = None  # (memory: the recorder's states; the sensitivities are read into fg)
    if ev.status == "ok":
        r = ev.result
        planned = len(r.model.s_steps)
        run.signatures.append({"steady_state_index": fg.steady_index, "category": ev.figures.get("category"),
                               "refinement": tuple(r.refined_facets), "kappa": max(st.kappa for st in r.steps),
                               "steps": len(r.steps), "rest_positions": tuple(st.s for st in r.steps[planned:])})
    run.evaluations.append(ev)
    out = run.memo[key] = _Evaluated(ev=ev, fg=fg, force_jacobian=dF)
    return out


@dataclass(frozen=True, kw_only=True)
class NonsmoothEvents:
    """How often consecutive simulated designs differ in a discrete feature the gradient does not see.

    Args:
        steady_state_index: in the record read as the steady state.
        category: in the coupling category.
        refinement: in the set of refined facets.
        kappa: in the final barrier stiffness.
        steps: in the number of records.
        rest_positions: in the positions of the records past the planned steps (the rest search's).
        pairs: the consecutive pairs compared.
    """

    steady_state_index: int = 0
    category: int = 0
    refinement: int = 0
    kappa: int = 0
    steps: int = 0
    rest_positions: int = 0
    pairs: int = 0


def nonsmooth_events(signatures: list) -> NonsmoothEvents:
    """Count how often consecutive simulated designs differ in a discrete feature the gradient does not see.

    Args:
        signatures: per complete insertion, its discrete features (steady-state index, category, the
            set of refined facets, the final barrier stiffness kappa, the number of records and the
            positions of those past the planned steps: the rest search's).

    Returns:
        The :class:`NonsmoothEvents` over the consecutive pairs.
    """
    keys = ("steady_state_index", "category", "refinement", "kappa", "steps", "rest_positions")
    counts = {k: sum(int(a[k] != b[k]) for a, b in zip(signatures, signatures[1:])) for k in keys}
    return NonsmoothEvents(**counts, pairs=max(len(signatures) - 1, 0))


#: Constraints without a gradient: the SQP would see them as flat (the seat clearance turns positive as
#: a grip is relaxed: a flat constraint stalls a line search); every simulated design is still checked
#: against them (the best design is a feasible one). A start that touches nothing linearizes the
#: clearance through :func:`gap_gradient` instead.
NOT_DIFFERENTIATED = ("seat_clearance",)


#: A coupling-ratio upper bound below this [%] (the loose brief's KAPPA_LOOSE) is linearized in
#: sqrt(CR) (:class:`ConstraintRow`).
ROOT_BELOW = 1.0


@dataclass(frozen=True, kw_only=True)
class ConstraintRow:
    """One finite bound the SQP linearizes.

    c = sign (v - bound) / scale >= 0 with v = value * correction, or with ``root``
    c = sign (sqrt(v) - sqrt(bound)) / sqrt(scale): the smooth surrogate of a category bound (a loose
    grip's CR <= 1e-3 %: E_ss vanishes quadratically as the seat's overlap closes, so dCR/dh -> 0 on
    the way; sqrt(CR) is about linear in the overlap).

    Args:
        name: the figure.
        sign: +1 for a lower bound, -1 for an upper one.
        bound: the bound [unit].
        scale: the violation that counts one [unit].
        root: linearize in sqrt(v).
    """

    name: str
    sign: float
    bound: float
    scale: float
    root: bool = False

    def value(self, v: float) -> float:
        """The row's value at a figure value.

        Args:
            v: the figure's (corrected) value [unit].

        Returns:
            c (>= 0 where the bound holds).
        """
        if self.root:
            return self.sign * (math.sqrt(max(v, 0.0)) - math.sqrt(self.bound)) / math.sqrt(self.scale)
        return self.sign * (v - self.bound) / self.scale

    def gradient(self, v: float, g: np.ndarray) -> np.ndarray:
        """The row's gradient.

        Args:
            v: the figure's value [unit].
            g: dv/dh (n_vars,).

        Returns:
            dc/dh (n_vars,).
        """
        if self.root:
            return self.sign * g / (2.0 * math.sqrt(v * self.scale)) if v > 0 else np.zeros_like(g)
        return self.sign * g / self.scale


def constraint_rows(problem: DesignProblem) -> list:
    """The rows of a problem's brief: one per finite bound (a force's lower bound 0 always holds).

    Args:
        problem: the design problem.

    Returns:
        [:class:`ConstraintRow`].
    """
    rows = []
    for name, (lo, hi) in problem.limits.items():
        if name in NOT_DIFFERENTIATED:  # checked on every design (the best is a feasible one), not linearized
            continue
        lo, hi = B.aimed_bounds(name, lo, hi, problem.settings.margin)
        scale = B.SCALES[name]
        if math.isfinite(lo) and not (name != "coupling_ratio" and lo <= 0):  # a force >= 0 always holds
            rows.append(ConstraintRow(name=name, sign=1.0, bound=lo, scale=scale))
        if math.isfinite(hi):
            rows.append(ConstraintRow(name=name, sign=-1.0, bound=hi, scale=scale,
                                      root=name == "coupling_ratio" and hi < ROOT_BELOW))
    return rows


#: Annealing iterations at most of the pre-phase that runs when the start gives the SQP no direction.
PRE_PHASE_ITERATIONS = 60


def flat_start(rows: list, fg: FigureGradients, corrections: dict) -> bool:
    """Whether the start gives the SQP no direction.

    Some constraint row is violated and every violated row's gradient is zero or missing (a part that
    does not touch the object), or a coupling-ratio row is violated while the profile ejects (CR = 100 %
    for every shape nearby) and the ratio could not be continued past the category
    (:func:`~simfab.design.figure_gradients.ejecting_ratio`).

    Args:
        rows: the constraint rows.
        fg: the start's figure gradients.
        corrections: {figure: mesh-correction factor}.

    Returns:
        True when the annealing pre-phase must find a start.
    """
    violated = [r for r in rows if r.value(fg.values[r.name] * corrections.get(r.name, 1.0)) < 0]
    flat = all(fg.gradients.get(r.name) is None or not np.any(fg.gradients[r.name]) for r in violated)
    ejects = (fg.values.get("category") == "ejects" and not fg.ratio_continued
              and any(r.name == "coupling_ratio" for r in violated))
    return bool(violated) and (flat or ejects)


def lost_grip(category: str, tight: bool, reached: dict) -> bool:
    """Whether the SQP counts a design as failed.

    One that touches nothing once a design touched, or, for a tight brief, one whose category is not
    tight once a tight one was reached: its figures have no gradient towards the brief, so a step there
    ends the descent.

    Args:
        category: the design's category.
        tight: the brief asks a tight grip.
        reached: {"contact": bool, "tight": bool} reached so far.

    Returns:
        True for a failed design.
    """
    if category == "none" and reached["contact"]:
        return True
    return tight and category != "tight" and reached["tight"]


def in_contact(ev: DesignEvaluation) -> bool:
    """Whether a complete evaluation's part touched the object (category other than "none").

    Args:
        ev: the evaluation.

    Returns:
        True in contact.
    """
    return ev.status == "ok" and ev.figures.get("category") not in (None, "none")


def in_category(ev: DesignEvaluation) -> bool:
    """Whether an evaluation is in contact and within the brief's coupling-ratio bounds (the pre-phase's goal).

    A design that merely grazes the object has gradients too small for a linearization of a
    newton-sized bound.

    Args:
        ev: the evaluation.

    Returns:
        True in the brief's category.
    """
    return in_contact(ev) and all(c.satisfied for c in ev.constraints if c.name == "coupling_ratio")


#: Trust-region SQP iterations at most (one insertion each), when the brief's iterations are more.
MAX_ITERATIONS = 30
#: The SQP's initial trust-region radius, in z (a fraction of each design variable's range).
RADIUS = 0.05
#: ... when it starts from a given design (a correction round's: an optimized design, near the kinks of
#: its active constraints, where a step of RADIUS loses the grip).
RADIUS_FROM_DESIGN = 0.01
#: The constraints are aimed this far inside their bounds, relative to the bound (at least AIM_ABS in
#: their SCALES units: 1 mN, 1 kPa, 0.001 %), a design the SQP counts as feasible (each aimed row violated by
#: at most its aim) meets the brief, and a step whose linearization lands on
#: the bound does not end a hair outside it (the figures are piecewise smooth: a correction step of a few
#: micrometres then meets their kinks).
AIM_REL = 1e-2
AIM_ABS = 1e-3
#: The element-quality bound the subproblems impose: this factor above QUALITY_REL (round-off off the
#: rejection threshold).
QUALITY_AIM = 1.001
#: The SQP stops when its trust-region radius falls below this (in z: 1e-4 of a translation's range
#: is ~ 1e-5 of the part's size).
MIN_RADIUS = 1e-4
#: Stop when no step predicts a reduction of the objective above this fraction of it.
RTOL = 1e-2
#: Target matching: restarts of the SQP from its best design at its initial radius after its trust region
#: collapsed or its trials kept failing (the next one only while a restart lowers the objective by more than RTOL).
RESTARTS = 2


def modification_hessian(problem: DesignProblem, Jh: np.ndarray) -> np.ndarray:
    """d2E_L/dh2, constant: E_L = sum_axes v_a^T M_L v_a over the boundary vertices' displacements v_a
    (linear in h), so the Hessian is 2 sum_a J_a^T M_L J_a with J_a the rows of dX/dh of axis a.

    Args:
        problem: the design problem.
        Jh: dX/dh (n*dim, n_vars).

    Returns:
        (n_vars, n_vars).
    """
    en = problem.energy
    d = problem.handles.dim
    out = np.zeros((Jh.shape[1], Jh.shape[1]))
    for a in range(d):
        Ja = Jh[en.vertices * d + a]
        out += 2.0 * Ja.T @ (en.M @ Ja)
    return out


def optimize_gradient(problem: DesignProblem, *, iterations: int | None = None, seed: int = 0, quiet: bool = True,
                      callback=None, start=None, resume=None) -> OptimizationResult:
    """A trust-region SQP on the brief (:func:`simfab.design.sqp.trust_region_sqp`; see the module docstring).

    One insertion per iteration. The annealing pre-phase runs only when the start gives no direction
    (:func:`flat_start`: at most PRE_PHASE_ITERATIONS iterations, until a design is in the brief's
    category; the SQP starts from the best one); otherwise the method is deterministic.

    Args:
        problem: the design problem.
        iterations: cap of the SQP's iterations (default: the brief's, at most MAX_ITERATIONS).
        seed: seeds the annealing pre-phase.
        quiet: no progress log.
        callback: called with each simulated design's evaluation.
        start: the design to start from (a correction round's: the trust region then starts at
            RADIUS_FROM_DESIGN, and a brief's round stops at its first design that meets the corrected
            brief, ``SQPConfig.stop_when_feasible``); default the initial shape.
        resume: a previous result's ``resume`` (its best design's simulation with gradients); when
            ``start`` is that design and the problem a brief, the run starts from it re-scored instead
            of simulating it again.

    Returns:
        A :class:`~simfab.design.optimize.OptimizationResult` whose ``simulations`` counts every insertion
        (the pre-phase's and the final run included) and ``gradient_evaluations`` those that gave
        gradients. Raises ConvergenceError when the initial shape cannot be simulated.
    """
    t0 = time.perf_counter()
    problem = problem.with_settings(hold_steps=True)  # derivatives are at fixed step positions
    H = problem.handles
    Jh = handle_jacobian(H)
    run = _Run(problem=problem, Jh=Jh)
    if problem.initial is not None:  # the placement's run of the initial shape: scored, not simulated again
        initial = initial_evaluation(problem)
    else:
        initial = _evaluate(run, H.identity()).ev  # (with its sensitivities: the SQP starts there)
    if initial.status != "ok":
        raise ConvergenceError(f"the initial shape cannot be simulated ({initial.reason}); nothing to optimize from")
    if not problem.settings.refined and initial.result.refined_facets:
        run.problem = problem = problem.with_settings(refined=tuple(int(i) for i in initial.result.refined_facets))
    lo, hi = problem.lower, problem.upper
    span = hi - lo
    rows = constraint_rows(problem)
    corr = problem.settings.corrections
    if (resume is not None and start is not None and problem.target is None and resume.fg is not None
            and np.array_equal(_key(resume.ev.h), _key(start)) and resume.ev.figures.get("category") != "none"):
        # a round from the previous run's best: its simulation, scored with this round's factors
        ev = dataclasses.replace(resume.ev, sim_seconds=0.0)  # (simulated by that run)
        score_figures(problem, ev, ev.result)
        run.memo[_key(start).tobytes()] = dataclasses.replace(resume, ev=ev)
        run.evaluations.append(ev)
    pre = None
    e0 = _evaluate(run, H.identity() if start is None else np.asarray(start, float))
    if e0.fg is not None and flat_start(rows, e0.fg, corr):
        touches_nothing = e0.ev.figures.get("category") == "none"
        g_gap = (gap_gradient(e0.ev.result, e0.fg.steady_index, Jh)
                 if touches_nothing and "seat_clearance" in problem.limits else None)
        if g_gap is not None and np.any(g_gap):
            # no figure depends on the shape, but the gap to O does: close it first (the clearance bound, linearized)
            log(f"couple optimize: {problem.base.name}: the start touches nothing (gap "
                f"{e0.ev.figures['seat_clearance'] * 1e6:.3g} um); the SQP closes the gap first", quiet=quiet)
            rows.append(ConstraintRow(name="seat_clearance", sign=-1.0, bound=0.0, scale=B.SCALES["seat_clearance"]))
        else:
            # no direction at all: anneal (seeded) until a design is in the brief's category, then descend
            why = "no contact" if touches_nothing else "the profile ejects"
            log(f"couple optimize: {problem.base.name}: the start gives no gradient ({why}); annealing "
                f"pre-phase until a design is in the brief's category, at most {PRE_PHASE_ITERATIONS} iterations",
                quiet=quiet)
            pre = optimize_anneal(problem, iterations=PRE_PHASE_ITERATIONS, seed=seed, quiet=True,
                           start=None if start is None else np.asarray(start, float), until=in_category)
            run.insertions += pre.simulations + pre.stopped_simulations + pre.speculative
            if in_contact(pre.best):
                start = pre.best.h
    target = problem.target is not None
    el = problem.mesh.elements
    q0 = problem.q0
    B_EL = None if target else span[:, None] * modification_hessian(problem, Jh) * span[None, :]
    force_scale = corr.get("force_profile", 1.0)

    def h_of(z):
        return lo + np.clip(z, 0.0, 1.0) * span

    tight = problem.brief.grip == "tight"
    reached = {"contact": False, "tight": False}

    def sample(z) -> Sample:
        h = h_of(z)
        e = _evaluate(run, h)
        if e.fg is None or (target and e.ev.rms_error is None):
            return Sample(ok=False)
        category = e.ev.figures.get("category")
        if lost_grip(category, tight, reached):
            return Sample(ok=False)
        reached["contact"] |= category != "none"
        reached["tight"] |= category == "tight"
        fg = e.fg
        if target:
            tm = target_model(problem.target, e.ev.result.column("s"), force_scale * e.ev.result.column("force"),
                              force_scale * e.force_jacobian * span[None, :])
            f, g, Bz = tm.value, tm.gradient, tm.hessian  # (Gauss-Newton: the samples' own curvature left out)
        else:
            X = H.apply(h)
            f, g, Bz = problem.energy(X), modification_gradient(problem, X, Jh) * span, B_EL
        c = np.array([r.value(fg.values[r.name] * corr.get(r.name, 1.0)) for r in rows]) - aim
        A = np.zeros((len(rows), len(z)))
        for i, r in enumerate(rows):
            gr = fg.gradients.get(r.name)
            if r.name == "seat_clearance":  # (a flat start's gap; 0 once in contact, where it holds)
                gr = (gap_gradient(e.ev.result, fg.steady_index, Jh) if e.ev.figures.get("category") == "none"
                      else None)
            if gr is not None:
                k = corr.get(r.name, 1.0)
                A[i] = r.gradient(fg.values[r.name] * k, gr * k) * span
        return Sample(ok=True, f=f, g=g, B=Bz, c=c, A=A)

    aim = np.array([max(AIM_ABS, AIM_REL * abs(r.value(0.0))) for r in rows])
    quality = CheapConstraints(
        fun=lambda z: np.asarray(element_quality(H.apply(h_of(z)), el)) / q0 - QUALITY_AIM * QUALITY_REL,
        jac=lambda z: np.asarray(quality_jacobian(H.apply(h_of(z)), el) @ Jh) / q0[:, None] * span[None, :])
    z0 = np.clip((H.identity() if start is None else np.asarray(start, float)) - lo, 0, None) / span
    cap = min(MAX_ITERATIONS, problem.brief.iterations) if iterations is None else int(iterations)
    history: list = []

    def on_step(st):
        ev = _evaluate(run, h_of(st.z)).ev  # (memoized: the trial's evaluation)
        history.append((ev, st.accepted))
        if callback is not None:
            callback({"k": len(history), "info": ev})
        log(f"couple optimize: {problem.base.name}: SQP iteration {len(history)}: objective {ev.objective:.4g}, "
            f"ratio {st.rho:.3g} (predicted {st.predicted:.3g}), radius {st.radius:.3g}, "
            f"{'accepted' if st.accepted else 'rejected'}, insertions {run.insertions}", quiet=quiet)

    opts = SQPConfig(radius=RADIUS if start is None or pre is not None else RADIUS_FROM_DESIGN,
                      max_evaluations=cap + 1, rtol=RTOL, ctol=aim, min_radius=MIN_RADIUS,
                      stop_when_feasible=start is not None and not target)
    if not sample(z0).ok:  # (memoized: the SQP's first evaluation)
        why = _evaluate(run, h_of(z0)).ev.reason or "status " + _evaluate(run, h_of(z0)).ev.status
        raise ConvergenceError(f"couple optimize: {problem.base.name}: the gradient method's start cannot be "
                               f"simulated with its sensitivities ({why}); --method anneal does not need them")
    res = trust_region_sqp(sample, z0, options=opts, cheap=quality, callback=on_step)
    iterations = len(res.steps)
    for _ in range(RESTARTS if target else 0):
        # target matching: a trust region that collapsed at a kink of the rest point starts again from the
        # best design at the initial radius (its start memoized: no insertion); again while that gains
        if res.converged or iterations >= cap:
            break
        log(f"couple optimize: {problem.base.name}: SQP: {res.message}; restart from the best design at radius "
            f"{opts.radius:g}", quiet=quiet)
        before = res.sample.f
        res = trust_region_sqp(sample, res.z, options=dataclasses.replace(opts, max_evaluations=cap + 1 - iterations),
                               cheap=quality, callback=on_step)
        iterations += len(res.steps)
        if res.sample.f > (1.0 - RTOL) * before:
            break
    if not res.converged and iterations >= cap:
        res.message = f"iteration cap ({cap}) reached"
    log(f"couple optimize: {problem.base.name}: SQP: {res.message} ({iterations} iterations, "
        f"{run.insertions} insertions)", quiet=quiet)
    ok = [ev for ev in run.evaluations if ev.status == "ok"]
    best = min(ok, key=lambda e: (not e.feasible, e.objective))
    resume_next = run.memo.get(_key(best.h).tobytes())
    if best.status == "ok" and best is not initial:  # as `couple simulate` runs it (own steps, no seeded refinement)
        plain = evaluate(problem.with_settings(refined=(), hold_steps=False), best.h, keep_result=True)
        run.insertions += int(plain.sim_seconds > 0)
        if plain.status == "ok":
            best = plain
    for ev in run.evaluations:
        if ev is not best and ev is not initial:
            ev.result = None
    rejected: dict = {}
    for ev in run.evaluations:
        if ev.status == "rejected":
            key = ev.reason.split(":")[0]
            rejected[key] = rejected.get(key, 0) + 1
    hist, current, best_so_far = [], initial.objective, initial.objective
    for k, (ev, acc) in enumerate(history):
        current = ev.objective if acc else current
        best_so_far = min(best_so_far, ev.objective)
        hist.append({"k": k, "accepted": acc, "current": current, "best": best_so_far, "temperature": math.nan,
                     "sigma": math.nan, "value": ev.objective, "evaluation": ev})
    message = f"SQP: {res.message} ({iterations} iterations)"
    if pre is not None:
        message = (f"annealing pre-phase ({pre.iterations} iterations, "
                   f"{pre.simulations + pre.stopped_simulations + pre.speculative} insertions, "
                   f"{'a design in the category' if in_category(pre.best) else 'none in the category'}); "
                   f"{message}")
    if problem.initial is None:  # the initial shape's run, for correction rounds started from this result
        problem = dataclasses.replace(problem, initial=initial.result)
    return OptimizationResult(problem=problem, initial=initial, best=best, history=hist,
                        accepted=[(k, ev.rest, ev.objective) for k, (ev, acc) in enumerate(history) if acc],
                        simulations=run.insertions, stopped_simulations=0, rejected=rejected,
                        seconds=time.perf_counter() - t0, sim_seconds=sum(ev.sim_seconds for ev in run.evaluations),
                        iterations=iterations, stopped_early=bool(res.converged), method="gradient",
                        gradient_evaluations=run.gradient_evaluations, message=message,
                        events=nonsmooth_events(run.signatures), resume=resume_next)


__all__ = [  # the optimizer driver, and the figure gradients (simfab.design.figure_gradients) it is built on
    "GRADIENT_LAG_TOL", "MAX_ITERATIONS", "ConstraintRow", "constraint_rows", "flat_start", "in_category",
    "in_contact", "lost_grip", "modification_hessian", "NonsmoothEvents", "nonsmooth_events", "optimize_gradient",
    "DeferredRecorder", "FigureGradients", "TEMPERATURE_REL", "TargetModel", "WEIGHT_FLOOR", "design_recorder",
    "ejecting_ratio", "figure_gradients", "gap_gradient", "handle_jacobian", "modification_gradient",
    "needed_records", "quality_jacobian", "removal_gradients", "rest_grip_gradient", "stress_measure",
    "target_model", "SensitivityRecorder", "analyze_run",
]
