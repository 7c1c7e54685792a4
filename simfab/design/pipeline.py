"""``simfab couple optimize`` as a function: :func:`run` loads the design scene, places handles
(from one insertion of the initial shape), descends by gradients (:mod:`simfab.design.gradient`,
the default) or anneals (:mod:`simfab.design.optimize`, on worker processes:
:mod:`simfab.design.parallel`), checks the design on refined meshes and re-optimizes with
mesh-corrected figures while it misses the brief there (:mod:`simfab.design.verify`), and returns
a typed :class:`DesignResult`; with ``out`` it writes the outputs
(:func:`simfab.design.outputs.write_all`)."""

from __future__ import annotations

import contextlib
import dataclasses
import time
from pathlib import Path

import numpy as np

from simfab.coupling.scene import load_coupling_scene
from simfab.coupling.simulate import simulate_insertion
from simfab.design import brief as B
from simfab.design import outputs
from simfab.design.gradient import GRADIENT_LAG_TOL, MAX_ITERATIONS, NonsmoothEvents, design_recorder, optimize_gradient
from simfab.design.optimize import HistoryRow, history_rows, optimize_anneal
from simfab.design.parallel import Workers
from simfab.design.problem import EvaluationConfig, ProblemSource, evaluate, make_problem, rebuild
from simfab.design.scene import load_design_scene
from simfab.design.synthesis import boundary_loops, revolve_outline, revolved_scene
from simfab.design.verify import (
    MeshCheck,
    check_warnings,
    checked_objective,
    correction_factors,
    level_figures,
    needs_correction,
)
from simfab.design.verify import mesh_check as check_mesh  # (run's mesh_check is its switch)
from simfab.errors import ConvergenceError, InputError
from simfab.io.atomic import write_json
from simfab.io.mesh import save_mesh
from simfab.io.outpaths import make_out_dir
from simfab.progress import log
from simfab.results import Result, field
from simfab.sweep import run_tasks


@dataclasses.dataclass(frozen=True, kw_only=True)
class DesignFigures:
    """A design's profile figures (``None`` where the brief's evaluation did not read one).

    Args:
        category: "tight", "loose", "ejects", ...
        coupling_ratio_pct: E_ss / E_max [%].
        E_max_J, E_ss_J: peak and steady-state elastic energy [J].
        F_in_N, F_rm_N, F_hold_N, F_grip_N: insertion, removal, hold and grip force [N].
        von_mises_avg_Pa: von Mises stress averaged over the brief's stress_radius (what the yield
            constraint reads) [Pa]; max_von_mises_Pa: the largest element stress [Pa].
        seat_clearance_m: the seat's clearance [m]; friction: the Coulomb coefficient [-].
    """

    category: str | None = None
    coupling_ratio_pct: float | None = None
    E_max_J: float | None = None
    E_ss_J: float | None = None
    F_in_N: float | None = None
    F_rm_N: float | None = None
    F_hold_N: float | None = None
    F_grip_N: float | None = None
    von_mises_avg_Pa: float | None = None
    max_von_mises_Pa: float | None = None
    seat_clearance_m: float | None = None
    friction: float | None = None

    #: figure name of :func:`simfab.design.problem.profile_figures` -> field
    NAMES = {"category": "category", "coupling_ratio": "coupling_ratio_pct", "E_max": "E_max_J", "E_ss": "E_ss_J",
             "insertion_force": "F_in_N", "removal_force": "F_rm_N", "hold_force": "F_hold_N",
             "grip_force": "F_grip_N", "von_mises": "von_mises_avg_Pa", "von_mises_peak": "max_von_mises_Pa",
             "seat_clearance": "seat_clearance_m", "friction": "friction"}

    @classmethod
    def from_figures(cls, figures: dict) -> DesignFigures:
        """The figures of a design's evaluation, by their unit-bearing names.

        Args:
            figures: :func:`simfab.design.problem.profile_figures` of its insertion.

        Returns:
            The :class:`DesignFigures`.
        """
        return cls(**{v: figures.get(k) for k, v in cls.NAMES.items()})


@dataclasses.dataclass(frozen=True, kw_only=True)
class HandleCounts:
    """The design's handles.

    Args:
        active: handles the optimizer moves; inactive: the others.
        placement: "displacement", "spatial" or "random".
    """

    active: int
    inactive: int
    placement: str


@dataclasses.dataclass(frozen=True, kw_only=True)
class AcceptanceBranches:
    """The annealer's speculative acceptance branches.

    Args:
        drawn: branches drawn; adopted: branches whose head was accepted.
    """

    drawn: int
    adopted: int


@dataclasses.dataclass(frozen=True, kw_only=True)
class DesignUnits:
    """The units of a :class:`DesignResult`'s figures.

    Args:
        objective, E_L, seconds: of those fields.
        constraints: constraint name -> unit.
        rms_error: of the RMS force error (None without a target profile).
    """

    objective: str = "-"
    E_L: str = "-"
    seconds: str = "s"
    constraints: dict[str, str]
    rms_error: str | None = field(optional=True)


@dataclasses.dataclass(frozen=True, kw_only=True)
class RestartRun:
    """One annealing restart (``restarts`` > 1); the figures are None where it failed.

    Args:
        seed: its seed; status: "ok" or the failure; message: the failure's message.
        seconds: its wall time [s].
        feasible, objective, E_L, iterations: its best design's (None if it failed).
    """

    seed: int
    status: str
    message: str
    seconds: float = field(unit="s")
    feasible: bool | None = field(optional=True)
    objective: float | None = field(optional=True, unit="-")
    E_L: float | None = field(optional=True, unit="-")
    iterations: int | None = field(optional=True)


@dataclasses.dataclass(frozen=True, kw_only=True)
class CorrectionRound:
    """One mesh-corrected re-optimization (:func:`mesh_corrected`).

    Args:
        round: 1, 2, ...
        factors: per figure, the factor applied to the coarse figure.
        feasible_fine: its design meets the brief on the refined meshes.
        objective_fine: its design's objective with mesh-converged figures [-].
        iterations, seconds, insertions: its optimizer run's.
        kept: its design replaced the best one.
    """

    round: int
    factors: dict[str, float]
    feasible_fine: bool
    objective_fine: float = field(unit="-")
    iterations: int
    seconds: float = field(unit="s")
    insertions: int
    kept: bool


@dataclasses.dataclass(frozen=True, kw_only=True)
class RevolvedPart:
    """The simulation of the optimized section revolved with replicated arms (:func:`write_revolved`).

    Args:
        elements: its 10-node tets.
        seconds: the simulation's wall time [s].
        category: its coupling category.
        figures: its profile figures (:func:`simfab.design.verify.level_figures`, without the category).
        constraints: the 2D brief's constraints on them.
        warnings: one line each.
    """

    elements: int
    seconds: float = field(unit="s")
    category: str | None
    figures: dict[str, float]
    constraints: tuple[B.ConstraintReport, ...]
    warnings: tuple[str, ...]


@dataclasses.dataclass(frozen=True, kw_only=True)
class DesignResult(Result):
    """A rest-shape optimization: the ``--json`` summary of ``simfab couple optimize``, typed.

    Args:
        scene: the scene's name.
        feasible: the best design meets every constraint (on the optimizer's figures).
        objective, objective_initial: the objective of the best and the initial design [-].
        E_L: the best design's Laplacian editing energy [-].
        constraints: per constraint, its :class:`~simfab.design.brief.ConstraintReport` with the initial
            design's value (values mesh-corrected).
        corrections: per figure, the factor applied to the coarse figure (mesh check); {} without.
        category, category_initial: the best and the initial design's coupling category.
        profile, profile_initial: their :class:`DesignFigures`.
        handles: the :class:`HandleCounts`.
        method: "gradient" or "anneal".
        iterations: the first run's iterations; stopped_early: it stopped on patience or convergence.
        optimizer_message: the optimizer's closing message.
        insertions: every insertion simulation of the optimization: complete, stopped early or speculative
            (the mesh check's excluded).
        gradient_evaluations: insertions that also gave gradients.
        nonsmooth_events: the gradient method's :class:`~simfab.design.gradient.NonsmoothEvents` (None: anneal).
        simulations, simulations_stopped_early, speculative_simulations: insertion counts by kind.
        acceptance_branches: the annealer's speculative :class:`AcceptanceBranches`.
        workers: processes that evaluated candidates; accepted: accepted designs; rejected: count per reason.
        seconds, simulation_seconds: wall time and time inside the simulator [s].
        fraction_outside_simulator: the share of the workers' time outside the simulator [-].
        units: the :class:`DesignUnits`.
        rms_error, rms_error_initial: target profile matching's RMS force error [N] (None without a target).
        warnings: one line each.
        restarts: a :class:`RestartRun` per annealing restart (with ``restarts`` > 1).
        mesh_check: the :class:`~simfab.design.verify.MeshCheck` on refined meshes.
        correction_rounds: a :class:`CorrectionRound` each.
        iterations_total, insertions_total: every round's.
        objective_fine: the kept design's objective with mesh-converged figures [-].
        revolved: the revolved 3D part's simulation, a :class:`RevolvedPart` (with revolve arms).
        history: one typed row per iteration (:class:`simfab.design.optimize.HistoryRow`,
            :class:`~simfab.design.optimize.AnnealRow` under annealing).
        optimization: the optimizer's :class:`simfab.design.optimize.OptimizationResult` (problem,
            designs, their insertions).
        scene_xml, scene_toml: the scene's files (the optimized scene is written from them).
        outputs: label -> path of every file written: part_stl, outline_csv (2D), scene_xml, scene_toml,
            scene_mesh, profile_png, shape_png, history_csv, usd, summary_json; revolved_stl with a revolve
            axis; with revolve arms also revolved_scene_xml, revolved_scene_toml, revolved_mesh.
    """

    scene: str
    feasible: bool
    objective: float = field(unit="-")
    objective_initial: float = field(unit="-")
    E_L: float = field(unit="-")
    constraints: dict[str, B.ConstraintReport]
    corrections: dict[str, float]
    category: str | None
    category_initial: str | None
    profile: DesignFigures
    profile_initial: DesignFigures
    handles: HandleCounts
    method: str
    iterations: int
    stopped_early: bool
    optimizer_message: str
    insertions: int
    gradient_evaluations: int
    nonsmooth_events: NonsmoothEvents | None
    simulations: int
    simulations_stopped_early: int
    speculative_simulations: int
    acceptance_branches: AcceptanceBranches
    workers: int
    accepted: int
    rejected: dict[str, int]
    seconds: float = field(unit="s")
    simulation_seconds: float = field(unit="s")
    fraction_outside_simulator: float = field(unit="-")
    units: DesignUnits
    rms_error: float | None = field(unit="N", optional=True)
    rms_error_initial: float | None = field(unit="N", optional=True)
    warnings: tuple[str, ...]
    restarts: tuple[RestartRun, ...] | None = field(optional=True)
    mesh_check: MeshCheck | None = field(optional=True)
    correction_rounds: tuple[CorrectionRound, ...] | None = field(optional=True)
    iterations_total: int | None = field(optional=True)
    insertions_total: int | None = field(optional=True)
    objective_fine: float | None = field(unit="-", optional=True)
    revolved: RevolvedPart | None = field(optional=True)
    history: tuple[HistoryRow, ...] = field(json=False, default=())
    optimization: object = field(json=False, default=None)
    scene_xml: Path | None = field(json=False, default=None)
    scene_toml: Path | None = field(json=False, default=None)

    def to_json(self) -> dict:
        """The ``--json`` summary (optional fields only when set; ``outputs`` after the figures).

        Returns:
            A dict of JSON values.
        """
        d = super().to_json()
        paths = d.pop("outputs")
        if paths:
            revolved = d.pop("revolved", None)
            d["outputs"] = paths
            if revolved is not None:
                d["revolved"] = revolved
        return d


def design_result(res, *, scene_xml: Path, scene_toml: Path, extra: dict | None = None) -> DesignResult:
    """The typed :class:`DesignResult` of an optimizer run (nothing written).

    Args:
        res: an :class:`simfab.design.optimize.OptimizationResult`.
        scene_xml, scene_toml: the design scene's files.
        extra: the mesh check's and restarts' fields (:func:`optimize_checked`).

    Returns:
        The result; its warnings include the mesh check's.
    """
    extra = dict(extra or {})
    best, init, problem = res.best, res.initial, res.problem
    initial = {c.name: c.value for c in init.constraints}
    cons = {c.name: c.report(named=False, initial=initial.get(c.name)) for c in best.constraints}
    target = best.rms_error is not None
    warnings = design_warnings(res)
    if extra.get("mesh_check") is not None:
        warnings += check_warnings(extra["mesh_check"])
    return DesignResult(
        scene=problem.base.name, feasible=best.feasible, objective=best.objective, objective_initial=init.objective,
        E_L=best.E_L, constraints=cons,
        # the constraints read the coarse figures times these (mesh correction rounds; {} without)
        corrections=dict(problem.settings.corrections),
        category=best.figures.get("category"), category_initial=init.figures.get("category"),
        profile=DesignFigures.from_figures(best.figures), profile_initial=DesignFigures.from_figures(init.figures),
        handles=HandleCounts(active=int(problem.handles.n_active), inactive=int((~problem.handles.active).sum()),
                             placement=problem.brief.placement),
        method=res.method, iterations=res.iterations, stopped_early=res.stopped_early, optimizer_message=res.message,
        insertions=outputs.insertions(res), gradient_evaluations=res.gradient_evaluations,
        nonsmooth_events=res.events, simulations=res.simulations, simulations_stopped_early=res.stopped_simulations,
        speculative_simulations=res.speculative,
        acceptance_branches=AcceptanceBranches(drawn=int(res.branches[0]), adopted=int(res.branches[1])),
        workers=res.workers, accepted=len(res.accepted), rejected=dict(res.rejected), seconds=res.seconds,
        simulation_seconds=res.sim_seconds,
        # with several workers the simulations overlap: the share of the workers' time they took
        fraction_outside_simulator=(max(0.0, 1.0 - res.sim_seconds / (res.seconds * res.workers))
                                    if res.seconds > 0 else 0.0),
        units=DesignUnits(constraints=dict(B.UNITS), rms_error="N" if target else None),
        rms_error=best.rms_error if target else None, rms_error_initial=init.rms_error if target else None,
        warnings=tuple(warnings), **extra, history=history_rows(res), optimization=res, scene_xml=Path(scene_xml),
        scene_toml=Path(scene_toml))


def design_warnings(res) -> list[str]:
    """The warnings of an optimizer run: yielding, constraints missed, the best insertion's own.

    Args:
        res: an :class:`simfab.design.optimize.OptimizationResult`.

    Returns:
        One line each.
    """
    best = res.best
    warnings = []
    vm = best.figures.get("von_mises")
    ys = res.problem.limits.get("von_mises", (0, None))[1]
    if ys is not None and vm is not None and vm > ys:
        warnings.append(f"the optimized part exceeds its yield stress: von Mises averaged over "
                        f"{res.problem.brief.stress_radius * 1e3:.3g} mm {vm / 1e6:.4g} MPa > {ys / 1e6:.4g} MPa")
    if not best.feasible:
        bad = [c.name for c in best.constraints if not c.satisfied]
        warnings.append(f"not every constraint is met after {res.iterations} iterations: {', '.join(bad)}")
    radius = res.problem.brief.stress_radius
    for w in (best.result.warnings if best.result is not None else []):
        if "exceeds the yield stress" in w and vm is not None:  # the simulator reads the raw element peak
            w += (f"; that is the largest element stress, singular at sharp corners: the yield constraint reads "
                  f"the stress averaged over {radius * 1e3:.3g} mm, {vm / 1e6:.4g} MPa")
        warnings.append(w)
    return warnings


#: Options of :func:`run` that are neither brief entries nor scene options.
RUN_OPTIONS = ("method", "restarts", "scheduler", "workers", "mesh_check", "revolve")


def split_overrides(overrides: dict) -> tuple[dict, dict, dict]:
    """Split :func:`run`'s keyword overrides into the scene tables they override.

    Args:
        overrides: brief entries (``iterations=40``; :class:`simfab.design.brief.DesignConfig` fields),
            [simulation]/[contact] options (``steps=8``, ``friction=0.3``), or whole tables as dicts
            (``design={...}``, ``simulation={...}``, ``contact={...}``).

    Returns:
        (design, simulation, contact) override dicts.

    Raises:
        InputError: a keyword that is none of these.
    """
    import dataclasses

    from simfab.coupling.insertion import scene_overrides

    brief_keys = {f.name for f in dataclasses.fields(B.DesignConfig)}
    design = dict(overrides.pop("design", None) or {})
    design.update({k: overrides.pop(k) for k in list(overrides) if k in brief_keys})
    tables = scene_overrides(overrides)
    extra = set(tables) - {"simulation", "contact"}
    if extra:
        k = sorted(extra)[0]
        raise InputError(f"unknown override {k!r} (a [design] entry, a [simulation] or [contact] option, or a run "
                         f"option: {', '.join(RUN_OPTIONS)})", where=k)
    return design, tables.get("simulation", {}), tables.get("contact", {})


def run(scene, *, out=None, seed: int = 0, device: str = "cpu", progress: bool | None = None,
        method: str | None = None, restarts: int = 1, scheduler: str | None = None, workers: int = 1,
        mesh_check: bool = True, revolve: tuple | None = None, **overrides) -> DesignResult:
    """Optimize a design scene's rest shape for its design brief (``simfab couple optimize``).

    Args:
        scene: a coupling scene with a [design] table (NAME.xml or a bundled name).
        out: folder for every output (:func:`simfab.design.outputs.write_all`); None writes nothing.
        seed: seed of the handle placement and the annealing.
        device: Warp device.
        progress: True shows log lines and progress bars.
        method: "gradient" (a trust-region SQP on the adjoint sensitivities, one insertion per iteration; with
            friction its lag solved to at most GRADIENT_LAG_TOL) or "anneal" (simulated annealing); None:
            "gradient", or "anneal" with ``restarts`` > 1.
        restarts: independent annealing runs (seeds seed, seed+1, ...) as Dask tasks on ``scheduler`` (or a
            local cluster); the best design is kept, every run reported.
        scheduler: Dask scheduler address for the restarts.
        workers: processes evaluating the annealer's proposals (the result does not depend on it).
        mesh_check: re-run the optimized shape with quadratic elements on refined meshes, report the
            figures' discretization error and re-optimize with mesh-corrected figures while the brief is
            missed there (:mod:`simfab.design.verify`).
        revolve: (axis "x"|"y", offset [m], arms) to also write the 2D section revolved (needs ``out``;
            :func:`write_revolved`).
        **overrides: brief entries, scene options or tables (:func:`split_overrides`).

    Returns:
        The :class:`DesignResult`.

    Raises:
        InputError: bad scene, brief or option (before anything is computed or written).
        ConvergenceError: the initial shape cannot be simulated.
    """
    from simfab._warp import device as check_device

    quiet = not progress
    device = check_device(device)
    design, simulation, contact = split_overrides(dict(overrides))
    if method is None:
        method = "anneal" if restarts > 1 else "gradient"
    if method not in METHODS:
        raise InputError(f"must be one of {', '.join(METHODS)}, got {method!r}", where="--method")
    if method == "gradient" and restarts > 1:
        raise InputError("the gradient method is deterministic: restarts would repeat it", where="--restarts")
    if revolve is not None and out is None:
        raise InputError("revolving writes the revolved part: give an output folder", where="revolve")
    ds = load_design_scene(scene, design=design, simulation=simulation, contact=contact, device=device, quiet=quiet)
    cm = ds.cm
    if method == "gradient" and cm.contact.friction > 0 and cm.contact.lag_tol > GRADIENT_LAG_TOL:
        # finite differences of whole frictional insertions jump with the number of lagging
        # iterations at a loose lag; the adjoint differentiates the step at its converged lag
        contact = dict(contact or {}, lag_tol=GRADIENT_LAG_TOL)
        log(f"couple optimize: {cm.name}: the gradient method with friction solves the lag to "
            f"lag_tol = {GRADIENT_LAG_TOL:g} (the scene's {cm.contact.lag_tol:g})", quiet=quiet)
        ds = load_design_scene(scene, design=design, simulation=simulation, contact=contact, device=device)
        cm = ds.cm
    if revolve is not None and cm.dim != 2:
        raise InputError("only a 2D section can be revolved", where="--revolve-axis")
    if revolve is not None and len(revolve) > 2 and revolve[2] and not ds.kept_regions:
        raise InputError("replicating arms needs the base marked by a keep site ([design] keep)",
                         where="--revolve-arms")
    if out is not None:
        out = make_out_dir(out)  # after every input check: bad input leaves no output directory
    cap = min(MAX_ITERATIONS, ds.brief.iterations) if method == "gradient" else ds.brief.iterations
    log(f"couple optimize: {cm.name}: {cm.fem.n_elements} elements, {len(cm.s_steps) - 1} steps, "
        f"{ds.brief.handles} handles ({ds.brief.placement}), up to {cap} {'SQP ' if method == 'gradient' else ''}"
        "iterations", quiet=quiet)
    with contextlib.ExitStack() as stack:
        # the worker processes start now: their start-up overlaps the initial insertion and the
        # handle placement, and they serve the correction rounds too
        procs = stack.enter_context(Workers(workers)) if workers > 1 and restarts <= 1 else 1
        source = ProblemSource(scene=str(ds.xml), design=dict(design or {}), simulation=dict(simulation or {}),
                               contact=dict(contact or {}), device=device)
        res, extra = optimize_checked(ds, source, seed, restarts, scheduler, procs, mesh_check, quiet, method)
    result = design_result(res, scene_xml=ds.xml, scene_toml=ds.toml, extra=extra)
    if out is None:
        return result
    result = outputs.write_all(result, out)
    if revolve is not None:
        rev_paths, rev = write_revolved(res, out, cm.name, *revolve, scene=ds, optimized=result.outputs,
                                        quiet=quiet)
        paths = {**result.outputs, **{k: str(v) for k, v in rev_paths.items()}}
        result = dataclasses.replace(result, outputs=paths, revolved=rev,
                                     warnings=result.warnings + (rev.warnings if rev is not None else ()))
        write_json(result.outputs["summary_json"], result.to_json())  # with the revolved part's entries
    return result


#: The optimizers ``couple optimize --method`` offers.
METHODS = ("anneal", "gradient")


def optimize_checked(ds, source: ProblemSource, seed, restarts, scheduler, workers, mesh_check, quiet,
                     method: str = "anneal"):
    """Place the handles, optimize by ``method`` (the gradient method, or annealing: ``restarts`` runs,
    or one on ``workers``: a count or running :class:`simfab.design.parallel.Workers`), check the
    design on refined meshes and correct; returns (OptimizationResult, the :class:`DesignResult` fields
    of the restarts and the mesh check)."""
    cm = ds.cm
    # (the gradient method reuses the placement's insertion of the initial shape, recorded)
    rec = design_recorder(cm, ds.brief) if method == "gradient" else None
    initial = simulate_insertion(cm, recorder=rec) if ds.brief.placement == "displacement" else None
    problem = make_problem(cm, ds.brief, kept_regions=ds.kept_regions, target=ds.target, initial=initial, seed=seed,
                           source=source, initial_recorder=rec)
    if mesh_check and problem.target is not None:
        # target matching: the coarse mesh's bias on the whole profile is known before any iteration
        # from the initial shape's check; without it the first run matches the target with a
        # too-stiff model and a correction round of half the budget must undo it
        problem = problem.with_settings(corrections=correction_factors(check_mesh(problem, problem.handles.rest,
                                                                                  quiet=quiet)))
    if method == "gradient":
        res, runs = optimize_gradient(problem, quiet=quiet, seed=seed), None
    elif restarts <= 1:
        res, runs = optimize_anneal(problem, quiet=quiet, seed=seed, workers=workers), None
    else:
        res, runs = _restarts(problem, seed, restarts, quiet, scheduler)
        runs = tuple(runs)
    extra = {} if runs is None else {"restarts": runs}
    if mesh_check and res.best.status == "ok":
        first, insertions = res.iterations, outputs.insertions(res)
        res, extra["mesh_check"], extra["correction_rounds"] = mesh_corrected(res, seed, workers, quiet)
        extra["iterations_total"] = first + sum(r.iterations for r in extra["correction_rounds"])
        extra["insertions_total"] = insertions + sum(r.insertions for r in extra["correction_rounds"])
        extra["objective_fine"] = checked_objective(res.problem, res.best, extra["mesh_check"])
    return res, extra


def mesh_corrected(res, seed: int, workers, quiet: bool):
    """Mesh check of the optimized shape (:mod:`simfab.design.verify`); while the mesh-converged
    figures miss the brief, or a target profile is matched only on the coarse mesh
    (:func:`simfab.design.verify.needs_correction`; at most ``[design] correction_rounds``
    times), optimize again from the best checked design with the coarse figures multiplied by
    its check's correction factors (output space mapping: the coarse model stays the fast one,
    its bias is measured on the design it produced; its penalties aim CORRECTION_MARGIN inside the
    force and stress bounds, since the next design's factors differ) and check again. A round can
    make things worse (the factors change along the way, e.g. when a contact event moves with the mesh), so
    the best checked design is kept: feasible on the refined meshes first, then the lowest
    objective there (:func:`simfab.design.verify.checked_objective`).

    Returns (result, its :class:`~simfab.design.verify.MeshCheck`, a :class:`CorrectionRound` per round).
    """
    name = res.problem.base.name
    log(f"couple optimize: {name}: mesh check of the optimized shape (quadratic elements)", quiet=quiet)
    check = check_mesh(res.problem, res.best.rest, figures0=res.best.figures, result0=res.best.result, quiet=quiet)

    def key(r, c):
        return (not c.feasible_fine, checked_objective(r.problem, r.best, c))

    best, rounds = (res, check), []
    for k in range(res.problem.brief.correction_rounds):
        res_b, check_b = best
        if not needs_correction(check_b, res_b.problem.settings.corrections):
            break
        factors = correction_factors(check_b)
        # the next design's factors differ from these: aim inside the bounds
        problem = res_b.problem.with_settings(corrections=factors, margin=B.CORRECTION_MARGIN)
        log(f"couple optimize: {name}: correction round {k + 1}: the coarse figures times "
            + ", ".join(f"{n} {v:.3g}" for n, v in factors.items()), quiet=quiet)
        if res_b.method == "gradient":
            nxt = optimize_gradient(problem, quiet=quiet, start=res_b.best.h, seed=seed + 1 + k, resume=res_b.resume)
        else:
            nxt = optimize_anneal(problem, seed=seed + 1 + k, quiet=quiet,
                           workers=workers if problem.source is not None else 1, start=res_b.best.h,
                           iterations=max(problem.brief.iterations // 2, 1))
        c = check_mesh(problem, nxt.best.rest, figures0=nxt.best.figures, result0=nxt.best.result, quiet=quiet)
        better = key(nxt, c) < key(*best)
        rounds.append(CorrectionRound(round=k + 1, factors=factors, feasible_fine=c.feasible_fine,
                                      objective_fine=key(nxt, c)[1], iterations=nxt.iterations, seconds=nxt.seconds,
                                      insertions=outputs.insertions(nxt), kept=better))
        if better:
            best = (nxt, c)
        elif res_b.method == "gradient":  # the same start and factors: the next round would repeat this one
            break
    return best[0], best[1], tuple(rounds)


def write_revolved(res, out: Path, stem: str, axis: str, offset: float, arms: int = 0, *, scene=None,
                   optimized: dict | None = None, quiet: bool = True) -> tuple[dict, RevolvedPart | None]:
    """The optimized 2D section revolved about ``axis`` (mm STL): a full turn of its outer outline
    (``arms`` 0), else the base revolved with ``arms`` replicated arms as a 3D scene next to the
    optimized 2D one (``optimized``: its output paths; ``scene``: the DesignScene, for its keep
    sites), simulated: (label -> path of the files written, the :class:`RevolvedPart` with arms, else None)."""
    fem = res.problem.mesh  # (the design's linear mesh)
    if not arms:
        loop = boundary_loops(fem.boundary_facets)[0]
        mesh = revolve_outline(res.best.rest[loop], axis=axis, offset=offset)
        mesh.apply_scale(1e3)
        return {"revolved_stl": save_mesh(mesh, Path(out) / f"{stem}_optimized_revolved.stl")}, None
    cm = res.problem.base
    kept = np.concatenate(scene.kept_regions) if scene is not None and scene.kept_regions else np.zeros(0, int)
    paths = revolved_scene(res.best.rest, fem, kept=kept, object_start=cm.pose(0.0)[1],
                           scene_xml=optimized["scene_xml"], scene_toml=optimized["scene_toml"], out=out, stem=stem,
                           axis=axis, offset=offset, arms=arms)
    cm3 = load_coupling_scene(paths["scene_xml"], device=fem.device)
    log(f"couple optimize: simulating the revolved part ({arms} arms, {cm3.fem.n_elements} 10-node tets)", quiet=quiet)
    t0 = time.perf_counter()
    r3 = simulate_insertion(cm3)
    fig = level_figures(r3, res.problem.brief.stress_radius)  # P2: stress averaged at quadrature points
    cons = B.constraints(fig, res.problem.limits)
    missed = [c.name for c in cons if not c.satisfied]
    warnings = list(r3.warnings)
    if missed:
        warnings.append(f"{stem}: the revolved 3D part ({arms} arms) misses the 2D brief on {', '.join(missed)} "
                        "(a plane-strain section and a 3D part with discrete arms on a ball are different mechanics: "
                        "see summary 'revolved')")
    part = RevolvedPart(elements=int(cm3.fem.n_elements), seconds=time.perf_counter() - t0, category=fig["category"],
                        figures={k: v for k, v in fig.items() if k != "category"},
                        constraints=tuple(c.report() for c in cons), warnings=tuple(warnings))
    return {"revolved_" + k: v for k, v in paths.items()} | {"revolved_stl": paths["stl"]}, part


def anneal_task(*, source: ProblemSource, settings: EvaluationConfig, seed: int):
    """One restart (a Dask task): the annealing of the problem ``source`` rebuilds
    (:class:`simfab.design.problem.ProblemSource`, handles already placed), scored with
    ``settings``, with ``seed``; returns the :class:`simfab.design.optimize.OptimizationResult` without
    its unpicklable parts (the problem and the insertion results, which the client rebuilds)."""
    res = optimize_anneal(rebuild(source, settings), seed=seed)
    res.problem = None
    res.initial.result = res.best.result = None
    return res


def _restarts(problem, seed, restarts, quiet, scheduler):
    tasks = [dict(source=problem.source, settings=problem.settings, seed=seed + i) for i in range(restarts)]
    results = run_tasks(anneal_task, tasks, scheduler=scheduler, quiet=quiet,
                        desc=f"optimize {problem.base.name} restarts")
    runs = []
    for t, r in zip(tasks, results):
        best = r.value.best if r.ok else None
        runs.append(RestartRun(seed=t["seed"], status=r.status, message=r.message, seconds=r.seconds,
                               **({} if best is None else dict(feasible=best.feasible, objective=best.objective,
                                                               E_L=best.E_L, iterations=r.value.iterations))))
    ok = [r.value for r in results if r.ok]
    if not ok:
        raise ConvergenceError(f"every restart failed; first: {results[0].message}")
    # feasible designs first, then the lowest objective
    res = min(ok, key=lambda v: (not v.best.feasible, v.best.objective))
    res.problem = problem
    res.initial = evaluate(problem, res.initial.h, keep_result=True)  # deterministic: the same figures
    res.best = evaluate(problem, res.best.h, keep_result=True)
    return res, runs
