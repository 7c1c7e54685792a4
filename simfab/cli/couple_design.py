"""The design actions of ``simfab couple``: ``optimize`` and ``study handles`` (argument parsing
only; the work is in :mod:`simfab.design`).

simfab couple optimize SCENE changes the part's rest shape as little as possible (Laplacian
editing energy of the boundary) until the simulated insertion meets the scene's design brief
([design] in NAME.toml: grip tight|loose, grip/insertion/removal force bounds [N], yield
stress [Pa], or a target force profile). Command-line options override the brief.

simfab couple study handles SCENE runs the handle-placement study: displacement-based and
spatial placement and --random random picks, for each handle count of --counts, each an
optimization run as a Dask task (--scheduler); reports the fraction of runs that met every
constraint and the final E_L per method (table, CSV, PNG).

--json keys: scene, runs, failed_runs, rows (method, handles, runs, converged_fraction, E_L_median, E_L_best),
outputs (runs_csv, summary_csv, plot_png, summary_json), units.

The --json keys of optimize, which its --help prints, are :data:`OPTIMIZE_JSON_KEYS`; the typed
result with units is :class:`simfab.design.pipeline.DesignResult`.
"""

from __future__ import annotations

import os
import textwrap

#: The ``--json`` keys of ``simfab couple optimize``, printed by its ``--help`` (the typed fields, with units:
#: :class:`simfab.design.pipeline.DesignResult`).
OPTIMIZE_JSON_KEYS = """--json keys: scene, feasible, objective, objective_initial, E_L, constraints (per
constraint: value, lo, hi, unit, satisfied, initial; values mesh-corrected), corrections
(per figure: factor applied to the coarse figure, from the mesh check), category, category_initial, profile and
profile_initial (category, coupling_ratio_pct, E_max_J, E_ss_J, F_in_N, F_rm_N, F_grip_N,
max_von_mises_Pa (largest element stress), von_mises_avg_Pa (averaged over [design]
stress_radius: what the yield constraint reads)), handles, method (anneal | gradient), iterations,
stopped_early, insertions (every insertion simulation of the optimization: complete, stopped early or
speculative; the mesh check's excluded), gradient_evaluations (insertions that also gave gradients),
nonsmooth_events (gradient method: how many consecutive simulated designs differ in steady_state_index,
category, refinement, kappa, steps, of pairs; null for anneal),
simulations, simulations_stopped_early, speculative_simulations, acceptance_branches (the
annealer's proposals evaluated as if the running one were accepted: drawn, adopted), workers,
accepted, rejected
(count per reason), seconds,
simulation_seconds, fraction_outside_simulator, warnings, outputs (paths: part_stl, outline_csv
(2D), scene_xml, scene_toml, scene_mesh, profile_png, shape_png, history_csv, usd, summary_json,
revolved_stl with --revolve-axis; with --revolve-arms also revolved_scene_xml, revolved_scene_toml,
revolved_mesh), revolved (with --revolve-arms: the 3D part's simulation: elements, category,
figures, constraints of the brief with their values and satisfied flags), restarts (with --restarts: per
run seed, status, message, feasible, objective, E_L, iterations, seconds), mesh_check (unless --no-mesh-check: levels
(element_order, subdivisions, elements, nodes, seconds, category), figures (per figure: values per
level, extrapolated, order, converging, difference_of_optimization_mesh, reference_change, step_factor),
step_check (when the scene's steps do not resolve the profile: steps, factor, seconds, factors per figure,
category, still_too_coarse), constraints at the mesh-converged values, feasible_fine, reference, units),
correction_rounds (per round:
factors, feasible_fine, objective_fine, iterations, seconds, kept: whether its design was
better on the refined meshes; the outputs are the kept design's run), iterations_total (every
round's), insertions_total (every round's), objective_fine (the kept design's objective with mesh-converged figures)."""

_PARTS = [textwrap.fill(" ".join(p.split()), 78) for p in [*__doc__.split("\n\n"), OPTIMIZE_JSON_KEYS]]
OPTIMIZE_DESCRIPTION = "\n\n".join([_PARTS[1], _PARTS[-1]])
STUDY_DESCRIPTION = "\n\n".join(_PARTS[2:4])


def add_optimize_args(s) -> None:
    s.add_argument("scene", metavar="SCENE", help="NAME.xml (+ NAME.toml with a [design] table) or a bundled scene")
    g = s.add_argument_group("design brief (override the scene's [design] table)")
    g.add_argument("--grip", choices=["tight", "loose", "any"], help="wanted grip (coupling-ratio constraint)")
    g.add_argument("--grip-force", nargs=2, type=float, metavar=("LO", "HI"), help="grip force bounds [N]")
    g.add_argument("--insertion-force", nargs=2, type=float, metavar=("LO", "HI"), help="insertion force bounds [N]")
    g.add_argument("--removal-force", nargs=2, type=float, metavar=("LO", "HI"), help="removal force bounds [N]")
    g.add_argument("--hold-force", nargs=2, type=float, metavar=("LO", "HI"),
                   help="hold force bounds [N] (the force to start sliding the seated object out)")
    g.add_argument("--yield-stress", type=float, metavar="PA",
                   help="max von Mises bound [Pa] (default: the material's)")
    g.add_argument("--target-profile", metavar="CSV", help="force profile to match (distance_m, force_N rows)")
    g.add_argument("--handles", type=int, metavar="K", help="number of active handles")
    g.add_argument("--placement", choices=["displacement", "spatial", "random"], help="handle placement")
    g.add_argument("--iterations", type=int, metavar="N",
                   help="iterations at most (annealing: one proposal each; the gradient method: SQP iterations, "
                        "at most 30)")
    g.add_argument("--correction-rounds", type=int, metavar="N",
                   help="re-optimizations with mesh-corrected figures while the mesh check finds the brief missed")
    g.add_argument("--check-refinements", type=int, metavar="N",
                   help="the mesh check's P2 levels: on the optimization mesh and refined N times (default 1; "
                        "0: quick, without an estimate of the reference's own error)")
    g.add_argument("--patience", type=int, metavar="N",
                   help="stop once the best design is feasible and has not improved for N iterations")
    s.add_argument("--steps", type=int, metavar="N", help="insertion steps per simulation (overrides the scene)")
    s.add_argument("--friction", type=float, metavar="MU",
                   help="Coulomb friction coefficient between object and part (overrides the scene's [contact] "
                        "friction): every candidate's insertion and removal are simulated with it, and the brief "
                        "reads the frictional forces")
    s.add_argument("--element-order", type=int, choices=(1, 2), metavar="{1,2}",
                   help="elements every candidate is simulated with (overrides the scene's [simulation] "
                        "element_order): 1 linear (fast, too stiff on coarse meshes: the mesh check corrects), 2 "
                        "quadratic on the scene's mesh (the handles still act on its linear mesh)")
    s.add_argument("--workers", type=int, default=None, metavar="N",
                   help="processes evaluating the annealer's proposals at once (speculatively; the design "
                        "does not depend on it; default: this machine's cores, at most 4; 1 with --restarts)")
    s.add_argument("--method", choices=["anneal", "gradient"], default=None,
                   help="optimizer: a trust-region SQP on the profile's exact sensitivities (default; adjoint "
                        "method, one insertion per iteration; with friction its lag solved to 1 %%), or simulated "
                        "annealing (the default with --restarts N > 1)")
    s.add_argument("--restarts", type=int, default=1, metavar="N",
                   help="independent annealing runs (seeds SEED..SEED+N-1) as Dask tasks; the best design is kept")
    s.add_argument("--scheduler", metavar="ADDRESS",
                   help="Dask scheduler for --restarts (default: a local cluster sized to this machine)")
    s.add_argument("--no-mesh-check", action="store_true",
                   help="skip re-running the optimized shape with quadratic (P2) elements (on the "
                        "optimization mesh and refined, see --check-refinements; with 4x the steps where the scene's "
                        "steps do not resolve the profile), which reports the optimization mesh's discretization "
                        "error and corrects the figures while the brief is missed there")
    s.add_argument("--revolve-axis", choices=["x", "y"], help="2D: also revolve the optimized section about this axis")
    s.add_argument("--revolve-offset", type=float, default=0.0, metavar="M",
                   help="position of the revolution axis [m] (x = M for axis y, y = M for axis x)")
    s.add_argument("--revolve-arms", type=int, default=0, metavar="K",
                   help="with --revolve-axis: revolve only the base (the keep sites) and replicate the arms K times "
                        "around the axis (K >= 2, the thesis' building blocks), then simulate that 3D part "
                        "(10-node tets); 0 (default): the whole section a full turn, STL only")


def add_study_args(s) -> None:
    s.add_argument("study", choices=["handles"], help="which study (handles: handle placement)")
    s.add_argument("scene", metavar="SCENE", help="design scene")
    s.add_argument("--counts", type=int, nargs="+", default=[2, 4, 6], metavar="K",
                   help="handle counts (default 2 4 6)")
    s.add_argument("--random", type=int, default=10, metavar="N", help="random placements per count (default 10)")
    s.add_argument("--iterations", type=int, metavar="N", help="annealing iterations per run (default: the brief's)")
    s.add_argument("--steps", type=int, metavar="N", help="insertion steps per simulation")
    s.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler to run on (default: a local cluster)")


def design_overrides(args) -> dict:
    from simfab.errors import InputError
    from simfab.io.tables import flag_overrides

    d = {}
    for k in ("grip", "yield_stress", "target_profile", "handles", "placement", "iterations", "patience",
              "correction_rounds", "check_refinements"):
        v = getattr(args, k, None)
        if v is not None:
            d[k] = v
    for k in ("grip_force", "insertion_force", "removal_force", "hold_force"):
        v = getattr(args, k, None)
        if v is not None:
            d[k] = list(v)
    for k in ("handles", "iterations", "patience", "correction_rounds", "check_refinements"):
        lo = 0 if k in ("iterations", "correction_rounds", "check_refinements") else 1
        if k in d and d[k] < lo:
            raise InputError(f"must be >= {lo}, got {d[k]}", where=f"--{k.replace('_', '-')}")
    return flag_overrides(d)


def simulation_overrides(args) -> dict:
    from simfab.errors import InputError

    if getattr(args, "steps", None) is None:
        return {}
    if args.steps < 1:
        raise InputError(f"must be >= 1, got {args.steps}", where="--steps")
    return {"steps": args.steps, "h_in": None}


def optimize_kwargs(args) -> dict:
    """``simfab couple optimize``'s flags as the keyword arguments of :func:`simfab.design.run`
    (besides scene, out, seed, device, progress)."""
    from simfab.errors import InputError

    if args.restarts < 1:
        raise InputError(f"must be >= 1, got {args.restarts}", where="--restarts")
    if args.workers is not None and args.workers < 1:
        raise InputError(f"must be >= 1, got {args.workers}", where="--workers")
    workers = args.workers if args.workers is not None else (1 if args.restarts > 1 else min(os.cpu_count() or 1, 4))
    if args.revolve_arms and not args.revolve_axis:
        raise InputError("needs --revolve-axis", where="--revolve-arms")
    if args.revolve_arms < 0 or args.revolve_arms == 1:
        raise InputError(f"must be 0 (a full turn) or >= 2, got {args.revolve_arms}", where="--revolve-arms")
    revolve = (args.revolve_axis, args.revolve_offset, args.revolve_arms) if args.revolve_axis else None
    from simfab.io.tables import flag_overrides

    contact = flag_overrides({"friction": args.friction})
    sim = simulation_overrides(args) | ({} if args.element_order is None else {"element_order": args.element_order})
    return dict(design=design_overrides(args), simulation=sim, contact=contact, revolve=revolve,
                restarts=args.restarts, scheduler=args.scheduler, workers=workers, mesh_check=not args.no_mesh_check,
                method=args.method)


def run_optimize(args) -> dict:
    from simfab.design import run
    from simfab.progress import log

    result = run(args.scene, out=args.out, device=args.device, progress=not args.quiet, seed=args.seed,
                 **optimize_kwargs(args))
    for w in result.warnings:  # warnings show even with --quiet
        log(f"simfab: warning: {w}")
    return result.to_json()


def run_study(args) -> dict:
    from simfab._warp import device as check_device
    from simfab.design.study import handle_study
    from simfab.errors import InputError

    check_device(args.device)
    if any(k < 1 for k in args.counts):
        raise InputError("handle counts must be >= 1", where="--counts")
    if args.random < 0:
        raise InputError(f"must be >= 0, got {args.random}", where="--random")
    design = {}
    if args.iterations is not None:
        design["iterations"] = args.iterations
    return handle_study(args.scene, out=args.out, counts=args.counts, randoms=args.random, design=design,
                        simulation=simulation_overrides(args), seed=args.seed, quiet=args.quiet,
                        scheduler=args.scheduler)
