"""The design problem: what one optimization holds fixed, how it is rebuilt in another process, and
the evaluation of one design (thesis, "Rest Shape Optimization").

    E(h) = E_L(X'(h)) + W sum_c max(0, c(h) / scale_c)^2          (or a target-profile error)
    X'(h) = M_LBS T(h)                                              (:mod:`simfab.design.handles`)

Each evaluation of a design h (:func:`evaluate`):

1. X' = M_LBS T(h); **validity**: every element keeps its orientation and at least QUALITY_REL of
   its initial mean-ratio quality q (4 sqrt(3) A / sum l^2 for a triangle, 12 (3 V)^(2/3) / sum l^2
   for a tetrahedron); a candidate that fails is rejected without simulating.
2. The initial scene's insertion is re-run on X' (:func:`simfab.coupling.simulate.simulate_insertion`,
   starting with the facets the initial insertion refined); a simulation that raises makes a
   rejected candidate with its reason, never a crash of the optimization.
3. The profile gives E_ss, E_max, F_grip, F_in, F_rm and max von Mises (:func:`profile_figures`);
   the objective adds their penalties (:mod:`simfab.design.brief`).

**Early rejection.** E_L plus the penalties of the bounds the run has already violated (yield,
insertion and removal forces read up to the energy's running maximum) is a lower bound of E at
every step; once it exceeds the annealer's threshold the simulation stops (status "stopped").

**One problem, two processes.** A worker (:mod:`simfab.design.parallel`) rebuilds the
:class:`DesignProblem` from its :class:`ProblemSource` (:func:`rebuild`; deterministic) and receives
the :class:`EvaluationConfig` with each task. Full notes: docs/methods.md, "simfab.design.problem".
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np

from simfab._warp import device as check_device
from simfab.coupling import settle
from simfab.coupling.model import CouplingModel, with_rest_shape
from simfab.coupling.profile import analyze_run
from simfab.coupling.simulate import InsertionResult, check_start, simulate_insertion
from simfab.design import brief as B
from simfab.design.handles import Handles, make_handles
from simfab.design.modification import ModificationEnergy
from simfab.design.placement import place_handles
from simfab.design.scene import load_design_scene
from simfab.design.stress import STRESS_RADIUS, record_averaged_von_mises
from simfab.errors import ConvergenceError, InputError

#: A candidate element must keep this fraction of its initial mean-ratio quality.
QUALITY_REL = 0.25

#: Initial proposal standard deviation: translations as a fraction of the bounding-box diagonal,
#: scales (dimensionless).
SIGMA_TRANSLATION_REL = 0.01
SIGMA_SCALE = 0.03


def element_quality(X: np.ndarray, elements: np.ndarray) -> np.ndarray:
    """(m,) signed mean-ratio quality of simplices (see module docstring); < 0 means inverted."""
    p = np.asarray(X, float)[np.asarray(elements)]
    d = p.shape[-1]
    D = np.swapaxes(p[:, 1:, :] - p[:, :1, :], 1, 2)
    det = np.linalg.det(D)
    k = d + 1
    i, j = np.triu_indices(k, 1)
    l2 = np.sum((p[:, i, :] - p[:, j, :]) ** 2, axis=(1, 2))
    if d == 2:
        return 4.0 * math.sqrt(3.0) * (det / 2.0) / l2
    vol = det / 6.0
    return np.sign(vol) * 12.0 * np.cbrt(3.0 * np.abs(vol)) ** 2 / l2


def seat_clearance(res, index: int) -> float:
    """Gap [m] between the part and the object at step ``index`` beyond the contact range: the
    smallest distance from A's boundary vertices to O (-psi near O, the field's far lower bound
    beyond its kernel) minus the barrier's activation distance d_hat (<= 0: in contact)."""
    cm = res.model
    r = res.steps[index]
    y = np.asarray(r.x)[np.asarray(cm.fem.boundary_vertices)]
    pose = cm.pose(r.s)
    ev = cm.field.evaluate(y, pose, hessian=False)
    d = -np.asarray(ev.psi, float)
    far = ~np.asarray(ev.near, bool)
    if far.any():
        d[far] = cm.field.far_lower_bound(y[far], pose)
    return float(d.min() - np.max(cm.dhat))


def linear_mesh(fem):
    """The linear mesh the design acts on: ``fem`` itself, or for a quadratic (P2) model the linear
    :class:`simfab.fem.model.FemModel` it was lifted from (its corners; the edge nodes follow at the
    edges' midpoints, :func:`simfab.coupling.model.with_rest_shape`). Handles, E_L, the element
    quality bound and the outputs act on it."""
    return fem.linear if getattr(fem, "element_order", 1) == 2 else fem


def lift_rest(fem, X: np.ndarray) -> np.ndarray:
    """Node rest positions (fem.n_vertices, dim) [m] of a design X on :func:`linear_mesh` (fem):
    X itself, or for P2 the corners X followed by the edge nodes at the edges' midpoints
    (as :func:`simfab.fem.p2.to_p2` places them)."""
    X = np.asarray(X, float)
    if getattr(fem, "element_order", 1) != 2:
        return X
    e = np.asarray(fem.edges, np.int64)
    return np.r_[X, 0.5 * (X[e[:, 0]] + X[e[:, 1]])]


def profile_figures(res, stress_radius: float = STRESS_RADIUS) -> dict:
    """Figures of an insertion the constraints read: coupling_ratio [%], grip_force,
    insertion_force, removal_force, hold_force [N] (frictional with friction: removal and hold from
    the removal traversal), von_mises [Pa] (max over the insertion and removal of the von Mises
    stress averaged over ``stress_radius`` [m], :mod:`simfab.design.stress`; on P2 elements at the
    quadrature points, :func:`simfab.design.stress.record_averaged_von_mises`), seat_clearance [m]
    (gap between part and object at the steady state, which is the path's end when O never touched
    the part: category "none", :func:`simfab.coupling.profile.analyze_run`; <= 0 in contact), and
    category, E_max, E_ss [J], von_mises_peak [Pa] (the largest element stress, mesh-dependent at
    sharp corners)."""
    prof = analyze_run(res)
    fem = res.model.fem
    return {"coupling_ratio": prof.coupling_ratio, "grip_force": prof.F_grip,
            "insertion_force": prof.F_in, "removal_force": prof.F_rm, "hold_force": prof.F_hold,
            "von_mises": max(record_averaged_von_mises(fem, r, stress_radius) for r in [*res.steps, *res.removal]),
            "von_mises_peak": float(max(r.max_von_mises for r in [*res.steps, *res.removal])),
            "seat_clearance": seat_clearance(res, prof.index_ss),
            "category": prof.category, "E_max": prof.E_max, "E_ss": prof.E_ss,
            "friction": prof.friction}



@dataclass(frozen=True, kw_only=True)
class ProblemSource:
    """What rebuilds a design problem in another process (:func:`rebuild`): the scene (MJCF path),
    the overrides of its ``[design]``, ``[simulation]`` and ``[contact]`` tables, the Warp device, the active
    handle vertices (placed once, by the caller: :func:`make_problem` fills them in) and the
    placement seed."""

    scene: str
    design: dict = field(default_factory=dict)
    simulation: dict = field(default_factory=dict)
    contact: dict = field(default_factory=dict)
    device: str = "cpu"
    handle_vertices: tuple = ()
    seed: int = 0


@dataclass(frozen=True, kw_only=True)
class EvaluationConfig:
    """How a problem's designs are scored, beyond the scene: what changes between the rounds of one
    optimization, and travels with every task to a worker (one value; the problem itself does not).

    corrections : {figure: factor} applied to the simulated figures before the constraints read
        them (mesh correction of a coarse model, :func:`simfab.design.verify.correction_factors`);
        empty: none
    margin : relative margin inside the force and stress bounds that the penalties aim at
        (:data:`simfab.design.brief.CORRECTION_MARGIN` in correction rounds, else 0); the
        constraints report the brief's own bounds
    refined : boundary facet ids every candidate's insertion starts refined with (``simulate_insertion``'s
        ``refined``): those the initial shape's insertion refined, set by
        :func:`simfab.design.optimize.optimize_anneal`
    hold_steps : every candidate's insertion runs at the initial shape's planned path positions
        (``base.s_steps``) instead of its own (whose insertion length follows A's farthest point
        along the path in jumps of 1/2000 of the path): the gradient method
        (:mod:`simfab.design.gradient`) differentiates at fixed step positions
    """

    corrections: dict = field(default_factory=dict)
    margin: float = 0.0
    refined: tuple = ()
    hold_steps: bool = False


@dataclass(frozen=True, kw_only=True, eq=False)
class DesignProblem:
    """Everything fixed during one optimization (the model of the loop).

    Args:
        base: the initial :class:`simfab.coupling.model.CouplingModel`.
        brief: :class:`simfab.design.brief.DesignConfig`.
        limits: {constraint: (lo, hi)} in UNITS.
        handles: :class:`Handles`.
        energy: :class:`ModificationEnergy`.
        target: :class:`simfab.design.brief.TargetProfile` or None.
        kept: (k,) vertices held unchanged.
        q0: (m,) initial element qualities [-].
        lower, upper, sigma0: (n_vars,) design bounds and initial proposal deviations.
        source: the :class:`ProblemSource` that rebuilds this problem in another process (parallel
            evaluation, restarts), or None (a problem not loaded from a scene file).
        settings: :class:`EvaluationConfig` (mesh corrections, margin, seeded refinement).
        initial: the unmodified shape's insertion (``simulate_insertion(base)``, e.g. run for the displacement
            placement), which :func:`initial_evaluation` scores instead of running it again; None:
            it is simulated there.
        initial_recorder: the recorder ``initial`` was run with (``simulate_insertion``'s ``recorder``, e.g. the
            gradient method's :class:`simfab.design.gradient.DeferredRecorder`), or None.
    """

    base: CouplingModel
    brief: B.DesignConfig
    limits: dict
    handles: Handles
    energy: ModificationEnergy
    target: B.TargetProfile | None
    kept: np.ndarray
    q0: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    sigma0: np.ndarray
    source: ProblemSource | None = None
    settings: EvaluationConfig = field(default_factory=EvaluationConfig)
    initial: InsertionResult | None = None
    initial_recorder: object = None

    @property
    def mesh(self):
        """The linear mesh the design acts on (:func:`linear_mesh` of ``base.fem``): ``handles``,
        ``energy``, ``q0`` and every design's ``rest`` are on its vertices."""
        return linear_mesh(self.base.fem)

    def with_settings(self, **changes) -> "DesignProblem":
        """This problem with some :class:`EvaluationConfig` fields replaced.

        Args:
            **changes: :class:`EvaluationConfig` field -> new value.

        Returns:
            A new :class:`DesignProblem`.
        """
        return dataclasses.replace(self, settings=dataclasses.replace(self.settings, **changes))

    def constraints(self, figures: dict) -> list:
        """The brief's constraints on simulated figures, mesh-corrected (``settings.corrections``).

        Args:
            figures: :func:`profile_figures` of a design.

        Returns:
            A list of :class:`simfab.design.brief.Constraint`.
        """
        c = self.settings.corrections
        return B.constraints({k: v * c.get(k, 1.0) if isinstance(v, float) else v for k, v in figures.items()},
                             self.limits)


def make_problem(cm: CouplingModel, brief: B.DesignConfig, *, kept_regions=(), target: B.TargetProfile | None = None,
                 initial: InsertionResult | None = None, handle_vertices=None, seed: int = 0,
                 source: ProblemSource | None = None, settings: EvaluationConfig | None = None,
                 initial_recorder=None) -> DesignProblem:
    """Set up the optimization of scene ``cm``'s part.

    kept_regions : vertex index arrays kept unchanged besides the fixed support (keep sites)
    initial : the initial shape's InsertionResult, ``simulate_insertion(cm)`` (displacement placement needs it;
        simulated here when missing); kept as the problem's ``initial``
    handle_vertices : explicit active handle vertices (overrides the brief's placement)
    seed : placement seed (random placement; affinity propagation's tie-breaking)
    source : a :class:`ProblemSource` naming the scene this problem was loaded from (its handle
        vertices and seed are filled in here); needed by parallel evaluation
    settings : :class:`EvaluationConfig` (default: none)
    initial_recorder : the recorder ``initial`` was simulated with (kept with it), or None
    """
    # handles, E_L and the quality bound act on the linear mesh; a P2 model's candidates are lifted
    # from it (edge nodes at the midpoints), so only its corners (the first n_corners nodes) are design vertices
    fem = linear_mesh(cm.fem)
    X = np.asarray(fem.rest, float)
    n = len(X)

    def corners(v):
        v = np.asarray(v, np.int64)
        return v[v < n]

    regions = [corners(cm.fixed_vertices)] + [corners(r) for r in kept_regions if len(corners(r))]
    kept = np.unique(np.concatenate(regions))
    if handle_vertices is None:
        disp = None
        if brief.placement == "displacement":
            if initial is None:
                initial = simulate_insertion(cm)
            disp = max_displacement(initial)[:n]
        handle_vertices = place_handles(X, fem.elements, brief.handles, kept, method=brief.placement,
                                        displacement=disp, seed=seed)
    H = make_handles(X, fem.elements, handle_vertices, regions)
    diag = float(np.linalg.norm(X.max(axis=0) - X.min(axis=0)))
    d, m = H.dim, H.n_active
    t_max = brief.max_translation * diag
    lo_s, hi_s = brief.scale_range
    lower = np.tile(np.r_[np.full(d, -t_max), np.full(d, lo_s)], m)
    upper = np.tile(np.r_[np.full(d, t_max), np.full(d, hi_s)], m)
    sigma0 = np.tile(np.r_[np.full(d, SIGMA_TRANSLATION_REL * diag), np.full(d, SIGMA_SCALE)], m)
    mat = cm.fem.material
    ys = mat.yield_stress if mat is not None else None
    return DesignProblem(base=cm, brief=brief, limits=B.constraint_bounds(brief, ys), handles=H,
                         energy=ModificationEnergy(X, fem.boundary_facets), target=target, kept=kept,
                         q0=element_quality(X, fem.elements), lower=lower, upper=upper, sigma0=sigma0,
                         source=None if source is None else dataclasses.replace(
                             source, handle_vertices=tuple(int(v) for v in H.vertex[H.active]), seed=seed),
                         settings=EvaluationConfig() if settings is None else settings,
                         initial=initial if initial is not None and initial.model is cm else None,
                         initial_recorder=initial_recorder if initial is not None and initial.model is cm else None)


def rebuild(source: ProblemSource, settings: EvaluationConfig | None = None) -> DesignProblem:
    """The :class:`DesignProblem` that ``source`` describes, scored with ``settings``."""
    ds = load_design_scene(source.scene, design=source.design, simulation=source.simulation, contact=source.contact,
                           device=check_device(source.device))
    return make_problem(ds.cm, ds.brief, kept_regions=ds.kept_regions, target=ds.target,
                        handle_vertices=list(source.handle_vertices), seed=source.seed, source=source,
                        settings=settings)


def max_displacement(res) -> np.ndarray:
    """(n,) largest displacement of every vertex over an insertion [m]."""
    X = np.asarray(res.model.fem.rest)
    return np.max([np.linalg.norm(np.asarray(r.x) - X, axis=1) for r in res.steps], axis=0)


@dataclass(kw_only=True)
class DesignEvaluation:
    """One design's evaluation.

    Args:
        h: (n_vars,) the design.
        rest: (n, d) its rest shape [m].
        status: "ok" | "rejected" (invalid) | "stopped" (provably above the acceptance threshold) |
            "aborted" (a speculative run no longer needed, never decided on).
        objective: the objective [-]: +inf when rejected, a lower bound when stopped.
        reason: why not ok.
        E_L: the Laplacian editing energy [-].
        rms_error: the RMS force error of target matching [N] (None without a target).
        constraints: list of :class:`simfab.design.brief.Constraint`.
        figures: :func:`profile_figures`.
        result: the InsertionResult (kept only while needed).
        sim_seconds, seconds: wall time in the simulation and in total [s].
        bounds: the objective's lower bound after each insertion step [-].
        newton_iterations: of a complete insertion (status "ok").
        recorder: the insertion's per-step recorder (``evaluate``'s ``recorder``), None without one.
    """

    h: np.ndarray
    rest: np.ndarray
    status: str
    objective: float = math.inf
    reason: str = ""
    E_L: float = math.nan
    rms_error: float | None = None
    constraints: list = field(default_factory=list)
    figures: dict = field(default_factory=dict)
    result: InsertionResult | None = None
    sim_seconds: float = 0.0
    seconds: float = 0.0
    bounds: list = field(default_factory=list)
    newton_iterations: int = 0
    recorder: object = None

    @property
    def feasible(self) -> bool:
        return self.status == "ok" and all(c.satisfied for c in self.constraints)


def restricted(problem: DesignProblem, ev: DesignEvaluation, threshold: float) -> DesignEvaluation:
    """``ev``, evaluated with a threshold at least ``threshold``, as :func:`evaluate` with
    ``threshold`` returns it: screened out when E_L alone exceeds it, stopped at the first step
    whose objective bound exceeds it, else ``ev`` itself."""
    if ev.status not in ("ok", "stopped"):
        return ev
    lead = 0.0 if problem.target is not None else ev.E_L
    if lead > threshold:
        return dataclasses.replace(ev, status="stopped", reason="modification energy above the acceptance threshold",
                                   objective=lead, figures={}, constraints=[], rms_error=None, result=None,
                                   sim_seconds=0.0, bounds=[])
    for i, b in enumerate(ev.bounds):
        if b > threshold:
            return dataclasses.replace(ev, status="stopped",
                                       reason=f"objective above the acceptance threshold at step {i}",
                                       objective=b, figures={}, constraints=[], rms_error=None, result=None,
                                       bounds=ev.bounds[: i + 1])
    return ev


def shape_defect(problem: DesignProblem, X: np.ndarray) -> str:
    """Why X is not a valid rest shape ("inverted element", "degenerate element"), or ""."""
    q = element_quality(X, problem.mesh.elements)
    if np.any(q <= 0):
        return "inverted element"
    if np.any(q < QUALITY_REL * problem.q0):
        return "degenerate element"
    return ""


def candidate_model(problem: DesignProblem, X: np.ndarray):
    """(CouplingModel on rest shape X, "") or (None, reason) when X is not a valid rest shape."""
    cm = problem.base
    why = shape_defect(problem, X)
    if why:
        return None, why
    try:  # the scene's own options: the insertion runs as 'couple simulate' would run the candidate
        out = with_rest_shape(cm, X)
    except InputError as e:
        return None, f"invalid mesh: {e}"
    if problem.settings.hold_steps and not settle.can_continue(cm):
        # the initial shape's step positions (the default insertion length follows A's farthest
        # point along the path, in jumps); a run continued to rest past the path's end already
        # plans the whole path, whatever the shape
        out = dataclasses.replace(out, s_steps=np.array(cm.s_steps, dtype=float))
    return out, ""


class _Exceeded(Exception):
    """Raised from the insertion's step callback once the objective's lower bound exceeds the
    acceptance threshold."""

    def __init__(self, bound: float, step: int):
        self.bound, self.step = bound, step


def _bound_watch(problem: DesignProblem, cm, base: float, threshold: float, trace: list):
    """Step callback raising :class:`_Exceeded` once ``base`` + W * (sum of the squared violations
    that the steps so far already prove) exceeds ``threshold`` (None if nothing can be bounded);
    appends each step's bound to ``trace``. Bounded, on ``cm``'s mesh, mesh-corrected like the
    figures (``problem.settings.corrections``):

    - the yield bound, by the running max of the averaged von Mises stress (the figure is its
      maximum over the whole run);
    - the upper bounds of the insertion and removal forces, by max(0, -min F) and max(0, max F)
      over the records up to the first maximum of the energy so far: the profile reads the forces
      up to its steady state, which lies after the energy's maximum over the whole run
      (:func:`simfab.coupling.profile.analyze`), itself at or after the running one, so those
      records are always part of it. With friction the removal force is read from the removal's
      own records (phase "remove"), by the running max(0, max F) over them; the hold force is not
      bounded early (it is read at the removal's turn, after the whole insertion).
    """
    terms = {k: B.aimed_bounds(k, *problem.limits[k], problem.settings.margin)[1]  # the bounds the penalties aim at
             for k in ("von_mises", "insertion_force", "removal_force")
             if k in problem.limits and math.isfinite(problem.limits[k][1])}
    if not terms or not math.isfinite(threshold):
        return None
    corr = {k: problem.settings.corrections.get(k, 1.0) for k in terms}
    radius = problem.brief.stress_radius
    run = dict(sigma=0.0, E=-math.inf, F_lo=math.inf, F_hi=-math.inf, F_min=math.inf, F_max=-math.inf)

    frictional = cm.contact.friction > 0
    run["F_rm"] = -math.inf

    def watch(k, rec):
        if rec.phase == "remove":
            run["F_rm"] = max(run["F_rm"], rec.force)
        else:
            run["F_min"], run["F_max"] = min(run["F_min"], rec.force), max(run["F_max"], rec.force)
            if rec.energy > run["E"]:  # a new maximum of the energy: every force so far is read
                run["E"], run["F_lo"], run["F_hi"] = rec.energy, run["F_min"], run["F_max"]
        value = {"insertion_force": max(0.0, -run["F_lo"]),
                 "removal_force": max(0.0, run["F_rm"] if frictional else run["F_hi"])}
        if "von_mises" in terms:
            run["sigma"] = max(run["sigma"], record_averaged_von_mises(cm.fem, rec, radius))
            value["von_mises"] = run["sigma"]
        bound = base + B.PENALTY_WEIGHT * sum(max(0.0, corr[c] * value[c] - hi) ** 2 / B.SCALES[c] ** 2
                                              for c, hi in terms.items())
        trace.append(bound)
        if bound > threshold:
            raise _Exceeded(bound, k)

    return watch


class _Aborted(Exception):
    """Raised from the insertion's step callback when the evaluation is no longer needed."""

    def __init__(self, step: int):
        self.step = step


def _step_watch(bound, abort):
    """The insertion's step callback: the objective bound's watch (or None), then ``abort``."""
    if abort is None:
        return bound

    def watch(k, rec):
        if bound is not None:
            bound(k, rec)
        if abort():
            raise _Aborted(k)

    return watch


def screen(problem: DesignProblem, h: np.ndarray, threshold: float = math.inf) -> DesignEvaluation:
    """The cheap part of :func:`evaluate`: the rest shape, its validity and E_L against the
    acceptance threshold. A returned evaluation with a ``reason`` is decided (rejected, or
    stopped with objective E_L > threshold); without one, the candidate needs its simulation."""
    t0 = time.perf_counter()
    X = problem.handles.apply(h)
    ev = DesignEvaluation(h=np.array(h, float), rest=X, status="rejected")
    ev.reason = shape_defect(problem, X)
    if not ev.reason:
        ev.E_L = problem.energy(X)
        base = 0.0 if problem.target is not None else ev.E_L
        if base > threshold:
            ev.status, ev.reason, ev.objective = "stopped", "modification energy above the acceptance threshold", base
    ev.seconds = time.perf_counter() - t0
    return ev


def evaluate(problem: DesignProblem, h: np.ndarray, *, keep_result: bool = False,
             threshold: float = math.inf, abort=None, recorder=None) -> DesignEvaluation:
    """Evaluate design vector h (see the module docstring); never raises for a bad candidate.

    threshold : acceptance threshold of the annealer; the simulation stops (status "stopped",
        objective = a lower bound > threshold) as soon as the objective provably exceeds it.
    abort : optional callable () -> bool polled after every insertion step; when it returns True
        the simulation stops (status "aborted": a speculative evaluation no longer needed).
    recorder : optional factory ``recorder(cm)`` of the insertion's per-step recorder (``simulate_insertion``'s
        ``recorder``, e.g. :class:`simfab.coupling.adjoint.SensitivityRecorder`), made for the
        candidate's model; the recorder is returned as ``DesignEvaluation.recorder``.
    """
    t0 = time.perf_counter()
    ev = screen(problem, h, threshold)
    if ev.reason:
        return ev
    cm, ev.reason = candidate_model(problem, ev.rest)
    if ev.reason:
        ev.seconds = time.perf_counter() - t0
        return ev
    base = 0.0 if problem.target is not None else ev.E_L
    t1 = time.perf_counter()
    try:
        check_start(cm)
        rec = ev.recorder = recorder(cm) if recorder is not None else None
        res = simulate_insertion(cm, callback=_step_watch(_bound_watch(problem, cm, base, threshold, ev.bounds), abort),
                       refined=problem.settings.refined, recorder=rec)
    except _Aborted as e:
        ev.status, ev.reason = "aborted", f"no longer needed at step {e.step}"
    except _Exceeded as e:
        ev.status, ev.objective = "stopped", e.bound
        ev.reason = f"objective above the acceptance threshold at step {e.step}"
    except ConvergenceError as e:
        ev.reason = f"simulation did not converge: {str(e).splitlines()[0][:160]}"
    except InputError as e:
        ev.reason = f"simulation refused the shape: {str(e).splitlines()[0][:160]}"
    except (ArithmeticError, ValueError, np.linalg.LinAlgError, RuntimeError) as e:
        ev.reason = f"simulation failed ({type(e).__name__}): {str(e).splitlines()[0][:160] if str(e) else ''}"
    else:
        ev.sim_seconds = time.perf_counter() - t1
        _score(problem, ev, res, keep_result)
    if ev.sim_seconds == 0.0:
        ev.sim_seconds = time.perf_counter() - t1
    ev.seconds = time.perf_counter() - t0
    return ev


def _score(problem: DesignProblem, ev: DesignEvaluation, res, keep_result: bool) -> None:
    """Fill ``ev`` (status "ok") from the complete insertion ``res`` of its rest shape: figures,
    constraints, objective (or "rejected" for non-finite figures)."""
    ev.status = "ok"
    ev.newton_iterations = int(sum(st.iterations for st in res.steps))
    ev.figures = profile_figures(res, problem.brief.stress_radius)
    score_figures(problem, ev, res)
    if keep_result:
        ev.result = res


def score_figures(problem: DesignProblem, ev: DesignEvaluation, res) -> None:
    """Set ``ev``'s constraints and objective from its figures (and, with a target profile, the
    complete insertion ``res``) under ``problem``'s corrections and margin: E_L + penalty, or the squared
    RMS force error + penalty; "rejected" for non-finite figures. A correction round re-scores the
    previous run's simulation of its start with it (the same simulation, other factors)."""
    ev.constraints = problem.constraints(ev.figures)
    pen = B.penalty(ev.constraints, problem.settings.margin)
    if problem.target is not None:
        scale = problem.settings.corrections.get("force_profile", 1.0)  # mesh correction of the whole profile
        ev.rms_error = problem.target.rms_error(res.column("s"), scale * res.column("force"))
        ev.objective = ev.rms_error ** 2 + pen
    else:
        ev.objective = ev.E_L + pen
    if not math.isfinite(ev.objective):
        ev.status, ev.reason, ev.objective = "rejected", "non-finite profile figures", math.inf


def initial_evaluation(problem: DesignProblem) -> DesignEvaluation:
    """The evaluation of the unmodified shape (identity handles: the mesh exactly), scored from
    ``problem.initial`` when the caller already ran it, else simulated."""
    h = problem.handles.identity()
    if problem.initial is None:
        return evaluate(problem, h, keep_result=True)
    t0 = time.perf_counter()
    ev = screen(problem, h)
    if not ev.reason:
        ev.sim_seconds = problem.initial.seconds
        _score(problem, ev, problem.initial, True)
    ev.seconds = time.perf_counter() - t0 + ev.sim_seconds
    return ev


