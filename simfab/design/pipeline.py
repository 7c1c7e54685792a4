"""``simfab couple optimize``'s pipeline: load the design scene, place handles (from one
insertion of the initial shape), anneal (:mod:`simfab.design.optimize`, on worker processes:
:mod:`simfab.design.parallel`) or descend by gradients (:mod:`simfab.design.gradient`), check the
design on refined meshes and re-optimize with
mesh-corrected figures while it misses the brief there (:mod:`simfab.design.verify`), write the
outputs (:mod:`simfab.design.outputs`)."""

from __future__ import annotations

import contextlib
import time
from pathlib import Path

import numpy as np

from simfab.coupling.scene import load_coupling_scene
from simfab.coupling.simulate import simulate
from simfab.design import brief as B
from simfab.design import outputs
from simfab.design.gradient import GRADIENT_LAG_TOL, MAX_ITERATIONS, design_recorder, optimize_gradient
from simfab.design.optimize import optimize
from simfab.design.parallel import Workers
from simfab.design.problem import EvaluationSettings, ProblemSource, evaluate, make_problem, rebuild
from simfab.design.scene import load_design_scene
from simfab.design.synthesis import boundary_loops, revolve_outline, revolved_scene
from simfab.design.verify import checked_objective, correction_factors, level_figures, needs_correction
from simfab.design.verify import mesh_check as check_mesh  # (optimize_scene's mesh_check is its switch)
from simfab.errors import ConvergenceError, InputError
from simfab.io.atomic import write_json
from simfab.io.mesh import save_mesh
from simfab.io.outpaths import make_out_dir
from simfab.progress import log
from simfab.sweep import run_tasks


def optimize_scene(scene, *, out, design: dict | None = None, simulation: dict | None = None,
                   contact: dict | None = None, device: str = "cpu",
                   quiet: bool = True, seed: int = 0, revolve: tuple[str, float] | None = None, restarts: int = 1,
                   scheduler: str | None = None, workers: int = 1, mesh_check: bool = True,
                   method: str | None = None) -> dict:
    """Optimize a design scene's part and write every output into ``out``; returns the summary.

    design : overrides of the ``[design]`` table (e.g. ``{"iterations": 60, "handles": 4}``)
    simulation : overrides of ``[simulation]``; contact : of ``[contact]`` (e.g. ``{"friction": 0.3}``)
    seed : random seed of the handle placement and the annealing
    restarts : independent annealing runs (seeds seed, seed+1, ...) on the same handles, run as
        Dask tasks (:func:`simfab.sweep.run_tasks`, on ``scheduler`` or a local cluster); the
        best final design is kept and every run is reported
    revolve : (axis "x"|"y", offset [m], arms) to also write the optimized 2D section revolved into a
        3D part (``NAME_optimized_revolved.stl``, mm): a full turn (arms 0), or the base revolved
        and the arms replicated ``arms`` times (:func:`simfab.design.synthesis.revolve_arms`), then
        written as a 3D scene and simulated (summary ``revolved``: its figures against the brief)
    workers : processes evaluating the annealer's proposals (:mod:`simfab.design.parallel`; the
        result does not depend on it); without restarts only
    mesh_check : re-run the optimized shape with quadratic elements, refined in 2D
        (:mod:`simfab.design.verify`) and report how far the optimization mesh's figures are from
        the mesh-converged ones, warning when a constraint holds only on the coarse mesh
    method : "gradient" (a trust-region SQP on the adjoint sensitivities, :mod:`simfab.design.gradient`: one
        run; with friction its lag solved to at most GRADIENT_LAG_TOL) or "anneal" (simulated annealing,
        :mod:`simfab.design.optimize`); None: "gradient", or "anneal" with ``restarts`` > 1 (restarts are
        independent annealing runs). The gradient method is the default: it needs one insertion per
        iteration where annealing needs one per proposal (measured: scenes/coupling/README.md).
    """
    if method is None:
        method = "anneal" if restarts > 1 else "gradient"
    if method not in METHODS:
        raise InputError(f"must be one of {', '.join(METHODS)}, got {method!r}", where="--method")
    if method == "gradient" and restarts > 1:
        raise InputError("the gradient method is deterministic: restarts would repeat it", where="--restarts")
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
        res, extra = _anneal_checked(ds, source, seed, restarts, scheduler, procs, mesh_check, quiet, method)
    summary = outputs.write_all(res, out, scene_xml=ds.xml, scene_toml=ds.toml, extra=extra)
    if revolve is not None:
        rev = write_revolved(res, out, cm.name, *revolve, scene=ds, optimized=summary["outputs"], quiet=quiet)
        summary["outputs"].update({k: str(v) for k, v in rev.pop("outputs").items()})
        if rev:
            summary["revolved"] = rev
            summary["warnings"] += rev["warnings"]
        write_json(summary["outputs"]["summary_json"], summary)  # with the revolved part's entries
    for w in summary["warnings"]:
        log(f"simfab: warning: {w}")
    return summary


#: The optimizers ``couple optimize --method`` offers.
METHODS = ("anneal", "gradient")


def _anneal_checked(ds, source: ProblemSource, seed, restarts, scheduler, workers, mesh_check, quiet,
                    method: str = "anneal"):
    """Place the handles, anneal (``restarts`` runs, or one on ``workers``: a count or running
    :class:`simfab.design.parallel.Workers`), check the design on refined meshes and correct;
    returns (DesignResult, summary extras)."""
    cm = ds.cm
    # (the gradient method reuses the placement's insertion of the initial shape, recorded)
    rec = design_recorder(cm, ds.brief) if method == "gradient" else None
    initial = simulate(cm, recorder=rec) if ds.brief.placement == "displacement" else None
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
        res, runs = optimize(problem, quiet=quiet, seed=seed, workers=workers), None
    else:
        res, runs = _restarts(problem, seed, restarts, quiet, scheduler)
    extra = {} if runs is None else {"restarts": runs}
    if mesh_check and res.best.status == "ok":
        first, insertions = res.iterations, outputs.insertions(res)
        res, extra["mesh_check"], extra["correction_rounds"] = mesh_corrected(res, seed, workers, quiet)
        extra["iterations_total"] = first + sum(r["iterations"] for r in extra["correction_rounds"])
        extra["insertions_total"] = insertions + sum(r["insertions"] for r in extra["correction_rounds"])
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

    Returns (result, its check, [per round: factors, feasible_fine, checked objective, iterations,
    seconds, kept]).
    """
    name = res.problem.base.name
    log(f"couple optimize: {name}: mesh check of the optimized shape (quadratic elements)", quiet=quiet)
    check = check_mesh(res.problem, res.best.rest, figures0=res.best.figures, result0=res.best.result, quiet=quiet)

    def key(r, c):
        return (not c["feasible_fine"], checked_objective(r.problem, r.best, c))

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
            nxt = optimize(problem, seed=seed + 1 + k, quiet=quiet,
                           workers=workers if problem.source is not None else 1, start=res_b.best.h,
                           iterations=max(problem.brief.iterations // 2, 1))
        c = check_mesh(problem, nxt.best.rest, figures0=nxt.best.figures, result0=nxt.best.result, quiet=quiet)
        better = key(nxt, c) < key(*best)
        rounds.append({"round": k + 1, "factors": factors, "feasible_fine": c["feasible_fine"],
                       "objective_fine": key(nxt, c)[1], "iterations": nxt.iterations, "seconds": nxt.seconds,
                       "insertions": outputs.insertions(nxt), "kept": better})
        if better:
            best = (nxt, c)
        elif res_b.method == "gradient":  # the same start and factors: the next round would repeat this one
            break
    return best[0], best[1], rounds


def write_revolved(res, out: Path, stem: str, axis: str, offset: float, arms: int = 0, *, scene=None,
                   optimized: dict | None = None, quiet: bool = True) -> dict:
    """The optimized 2D section revolved about ``axis`` (mm STL): a full turn of its outer outline
    (``arms`` 0), else the base revolved with ``arms`` replicated arms as a 3D scene next to the
    optimized 2D one (``optimized``: its output paths; ``scene``: the DesignScene, for its keep
    sites), simulated: {"outputs": paths, and with arms: "elements", "seconds", "category",
    "figures", "constraints", "warnings"}."""
    fem = res.problem.mesh  # (the design's linear mesh)
    if not arms:
        loop = boundary_loops(fem.boundary_facets)[0]
        mesh = revolve_outline(res.best.rest[loop], axis=axis, offset=offset)
        mesh.apply_scale(1e3)
        return {"outputs": {"revolved_stl": save_mesh(mesh, Path(out) / f"{stem}_optimized_revolved.stl")}}
    cm = res.problem.base
    kept = np.concatenate(scene.kept_regions) if scene is not None and scene.kept_regions else np.zeros(0, int)
    paths = revolved_scene(res.best.rest, fem, kept=kept, object_start=cm.pose(0.0)[1],
                           scene_xml=optimized["scene_xml"], scene_toml=optimized["scene_toml"], out=out, stem=stem,
                           axis=axis, offset=offset, arms=arms)
    cm3 = load_coupling_scene(paths["scene_xml"], device=fem.device)
    log(f"couple optimize: simulating the revolved part ({arms} arms, {cm3.fem.n_elements} 10-node tets)", quiet=quiet)
    t0 = time.perf_counter()
    r3 = simulate(cm3)
    fig = level_figures(r3, res.problem.brief.stress_radius)  # P2: stress averaged at quadrature points
    cons = B.constraints(fig, res.problem.limits)
    missed = [c.name for c in cons if not c.satisfied]
    warnings = list(r3.warnings)
    if missed:
        warnings.append(f"{stem}: the revolved 3D part ({arms} arms) misses the 2D brief on {', '.join(missed)} "
                        "(a plane-strain section and a 3D part with discrete arms on a ball are different mechanics: "
                        "see summary 'revolved')")
    return {"outputs": {"revolved_" + k: v for k, v in paths.items()} | {"revolved_stl": paths["stl"]},
            "elements": int(cm3.fem.n_elements), "seconds": time.perf_counter() - t0, "category": fig["category"],
            "figures": {k: v for k, v in fig.items() if k != "category"},
            "constraints": [dict(name=c.name, value=c.value, lo=c.lo, hi=c.hi, unit=c.unit, satisfied=c.satisfied)
                            for c in cons],
            "warnings": warnings}


def anneal_task(*, source: ProblemSource, settings: EvaluationSettings, seed: int):
    """One restart (a Dask task): the annealing of the problem ``source`` rebuilds
    (:class:`simfab.design.problem.ProblemSource`, handles already placed), scored with
    ``settings``, with ``seed``; returns the :class:`simfab.design.optimize.DesignResult` without
    its unpicklable parts (the problem and the insertion results, which the client rebuilds)."""
    res = optimize(rebuild(source, settings), seed=seed)
    res.problem = None
    res.initial.result = res.best.result = None
    return res


def _restarts(problem, seed, restarts, quiet, scheduler):
    tasks = [dict(source=problem.source, settings=problem.settings, seed=seed + i) for i in range(restarts)]
    results = run_tasks(anneal_task, tasks, scheduler=scheduler, quiet=quiet,
                        desc=f"optimize {problem.base.name} restarts")
    runs = []
    for t, r in zip(tasks, results):
        row = {"seed": t["seed"], "status": r.status, "message": r.message, "seconds": r.seconds}
        if r.ok:
            row.update(feasible=r.value.best.feasible, objective=r.value.best.objective, E_L=r.value.best.E_L,
                       iterations=r.value.iterations)
        runs.append(row)
    ok = [r.value for r in results if r.ok]
    if not ok:
        raise ConvergenceError(f"every restart failed; first: {results[0].message}")
    # feasible designs first, then the lowest objective
    res = min(ok, key=lambda v: (not v.best.feasible, v.best.objective))
    res.problem = problem
    res.initial = evaluate(problem, res.initial.h, keep_result=True)  # deterministic: the same figures
    res.best = evaluate(problem, res.best.h, keep_result=True)
    return res, runs
