"""``simfab couple optimize``'s pipeline: load the design scene, place handles (from one
insertion of the initial shape), anneal (:mod:`simfab.design.optimize`, on worker processes:
:mod:`simfab.design.parallel`), check the design on refined meshes and re-optimize with
mesh-corrected figures while it misses the brief there (:mod:`simfab.design.verify`), write the
outputs (:mod:`simfab.design.outputs`)."""

from __future__ import annotations

from pathlib import Path

from simfab.errors import InputError


def optimize_scene(scene, *, out, design: dict | None = None, simulation: dict | None = None, device: str = "cpu",
                   quiet: bool = True, seed: int = 0, revolve: tuple[str, float] | None = None, restarts: int = 1,
                   scheduler: str | None = None, workers: int = 1, mesh_check: bool = True) -> dict:
    """Optimize a design scene's part and write every output into ``out``; returns the summary.

    design : overrides of the ``[design]`` table (e.g. ``{"iterations": 60, "handles": 4}``)
    simulation : overrides of ``[simulation]``
    seed : random seed of the handle placement and the annealing
    restarts : independent annealing runs (seeds seed, seed+1, ...) on the same handles, run as
        Dask tasks (:func:`simfab.sweep.run_tasks`, on ``scheduler`` or a local cluster); the
        best final design is kept and every run is reported
    revolve : (axis "x"|"y", offset [m]) to also write the optimized 2D section revolved into a
        3D part (``NAME_optimized_revolved.stl``, mm)
    workers : processes evaluating the annealer's proposals (:mod:`simfab.design.parallel`; the
        result does not depend on it); without restarts only
    mesh_check : re-run the optimized shape with quadratic elements, refined in 2D
        (:mod:`simfab.design.verify`) and report how far the optimization mesh's figures are from
        the mesh-converged ones, warning when a constraint holds only on the coarse mesh
    """
    from simfab.coupling.simulate import simulate
    from simfab.design import outputs
    from simfab.design.optimize import make_problem, optimize
    from simfab.design.parallel import ProblemSource
    from simfab.design.scene import load_design_scene
    from simfab.io.outpaths import make_out_dir
    from simfab.progress import log

    out = make_out_dir(out)
    ds = load_design_scene(scene, design=design, simulation=simulation, device=device)
    cm = ds.cm
    if revolve is not None and cm.dim != 2:
        raise InputError("only a 2D section can be revolved", where="--revolve-axis")
    log(f"couple optimize: {cm.name}: {cm.fem.n_elements} elements, {len(cm.s_steps) - 1} steps, "
        f"{ds.brief.handles} handles ({ds.brief.placement}), up to {ds.brief.iterations} iterations", quiet=quiet)
    initial = simulate(cm) if ds.brief.placement == "displacement" else None
    source = ProblemSource(scene=str(ds.xml), design=dict(design or {}), simulation=dict(simulation or {}), device=device)
    problem = make_problem(cm, ds.brief, kept_regions=ds.kept_regions, target=ds.target, initial=initial, seed=seed,
                           source=source)
    if restarts <= 1:
        res, runs = optimize(problem, quiet=quiet, seed=seed, workers=workers), None
    else:
        res, runs = _restarts(problem, seed, restarts, quiet, scheduler)
    extra = {} if runs is None else {"restarts": runs}
    if mesh_check and res.best.status == "ok":
        from simfab.design.verify import checked_objective

        first = res.iterations
        res, extra["mesh_check"], extra["correction_rounds"] = mesh_corrected(res, seed, workers, quiet)
        extra["iterations_total"] = first + sum(r["iterations"] for r in extra["correction_rounds"])
        extra["objective_fine"] = checked_objective(res.problem, res.best, extra["mesh_check"])
    summary = outputs.write_all(res, out, scene_xml=ds.xml, scene_toml=ds.toml, extra=extra)
    if revolve is not None:
        summary["outputs"]["revolved_stl"] = str(write_revolved(res, out, cm.name, *revolve))
    for w in summary["warnings"]:
        log(f"simfab: warning: {w}")
    return summary


def mesh_corrected(res, seed: int, workers: int, quiet: bool):
    """Mesh check of the optimized shape (:mod:`simfab.design.verify`); while the mesh-converged
    figures miss the brief, or a target profile is matched only on the coarse mesh
    (:func:`simfab.design.verify.needs_correction`; at most ``[design] correction_rounds``
    times), optimize again from the best checked design with the coarse figures multiplied by
    its check's correction factors (output space mapping: the coarse model stays the fast one,
    its bias is measured on the design it produced) and check again. A round can make things
    worse (the factors change along the way, e.g. when a contact event moves with the mesh), so
    the best checked design is kept: feasible on the refined meshes first, then the lowest
    objective there (:func:`simfab.design.verify.checked_objective`).

    Returns (result, its check, [per round: factors, feasible_fine, checked objective, iterations,
    seconds, kept]).
    """
    import dataclasses

    from simfab.design.optimize import optimize
    from simfab.design.verify import checked_objective, correction_factors, mesh_check, needs_correction
    from simfab.progress import log

    name = res.problem.base.name
    log(f"couple optimize: {name}: mesh check of the optimized shape (quadratic elements)", quiet=quiet)
    check = mesh_check(res.problem, res.best.rest, figures0=res.best.figures, quiet=quiet)

    def key(r, c):
        return (not c["feasible_fine"], checked_objective(r.problem, r.best, c))

    best, rounds = (res, check), []
    for k in range(res.problem.brief.correction_rounds):
        res_b, check_b = best
        if not needs_correction(check_b, res_b.problem.corrections):
            break
        factors = correction_factors(check_b)
        p = res_b.problem
        src = None if p.source is None else dataclasses.replace(p.source, corrections=factors)
        problem = dataclasses.replace(p, corrections=factors, source=src)
        log(f"couple optimize: {name}: correction round {k + 1}: the coarse figures times "
            + ", ".join(f"{n} {v:.3g}" for n, v in factors.items()), quiet=quiet)
        nxt = optimize(problem, seed=seed + 1 + k, quiet=quiet, workers=workers if src is not None else 1,
                       start=res_b.best.h, iterations=max(problem.brief.iterations // 2, 1))
        c = mesh_check(problem, nxt.best.rest, figures0=nxt.best.figures, quiet=quiet)
        better = key(nxt, c) < key(*best)
        rounds.append({"round": k + 1, "factors": factors, "feasible_fine": c["feasible_fine"],
                       "objective_fine": key(nxt, c)[1], "iterations": nxt.iterations, "seconds": nxt.seconds,
                       "kept": better})
        if better:
            best = (nxt, c)
    return best[0], best[1], rounds


def write_revolved(res, out: Path, stem: str, axis: str, offset: float) -> Path:
    """The optimized 2D section's outer outline revolved about ``axis`` (mm STL)."""
    from simfab.design.synthesis import boundary_loops, revolve_outline
    from simfab.io.mesh import save_mesh

    fem = res.problem.base.fem
    loop = boundary_loops(fem.boundary_facets)[0]
    mesh = revolve_outline(res.best.rest[loop], axis=axis, offset=offset)
    mesh.apply_scale(1e3)
    return save_mesh(mesh, Path(out) / f"{stem}_optimized_revolved.stl")


def anneal_task(*, source, seed: int):
    """One restart (a Dask task): the annealing of the problem ``source`` rebuilds
    (:class:`simfab.design.parallel.ProblemSource`, handles already placed) with ``seed``;
    returns the :class:`simfab.design.optimize.DesignResult` without its unpicklable parts (the
    problem and the insertion results, which the client rebuilds)."""
    from simfab.design.optimize import optimize
    from simfab.design.parallel import rebuild

    res = optimize(rebuild(source), seed=seed)
    res.problem = None
    res.initial.result = res.best.result = None
    return res


def _restarts(problem, seed, restarts, quiet, scheduler):
    from simfab.design.optimize import evaluate
    from simfab.errors import ConvergenceError
    from simfab.sweep import run_tasks

    tasks = [dict(source=problem.source, seed=seed + i) for i in range(restarts)]
    results = run_tasks(anneal_task, tasks, scheduler=scheduler, quiet=quiet, desc=f"optimize {problem.base.name} restarts")
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
