"""simfab crowd: wisdom of micro-crowds -- aggregate ratings, study crowd size, compute truths.

    simfab crowd aggregate RATINGS.csv --scale 1 10 [--truth TRUTH.csv]
    simfab crowd study RATINGS.csv --scale 1 10 --truth TRUTH.csv [--subcrowds 500] [--scheduler ADDRESS]
    simfab crowd truth MESH [--orientations six | NAME=RX:RY:RZ ...] [--units mm]
    simfab crowd simulate --tasks 6 --scale 1 10 [--practitioners 15] [--public 100]
    simfab crowd bracket [--designs NAME ...] [--load 20]

RATINGS.csv is long-form worker,task,label (integer labels on the scale); TRUTH.csv is
task,truth. RMS errors are on the unit scale [0, 1] (label - lo) / (hi - lo). The
bundled 3D-printing survey is in ``scenes/crowd`` (see its README).
"""

from __future__ import annotations

import os

from simfab.errors import InputError

#: units of summary keys for the plain-text table
UNITS = {"support_volume": "m³", "overhang_area": "m²", "raycast_volume": "m³", "euler_deg": "deg",
         "tip_deflection": "m", "area": "m²", "load": "N", "seconds": "s", "rms_continuous": "unit scale",
         "rms_rounded": "unit scale"}

HELP = "wisdom of micro-crowds: aggregate ratings, micro-crowd study, computed truths, synthetic crowds"
DESCRIPTION = (
    "Wisdom of micro-crowds. Actions: 'aggregate' (all aggregators incl. the Bayesian "
    "expertise/difficulty model, scored against --truth), 'study' (micro-crowd study over "
    "sub-crowd sizes), 'truth' (support volume / overhang area of a mesh per orientation), "
    "'simulate' (synthetic crowds), 'bracket' (FEM strength of bracket designs). Ratings are "
    "long-form CSV worker,task,label with integer labels; truth is task,truth. RMS errors are "
    "on the unit scale (label - lo) / (hi - lo). Bundled example: scenes/crowd."
)


def _sampler_args(p, *, study: bool):
    from simfab.crowd.config import STUDY_SAMPLER, SamplerConfig

    d = STUDY_SAMPLER if study else SamplerConfig()
    g = p.add_argument_group("Bayesian sampler")
    g.add_argument("--chains", type=int, default=d.chains, help=f"chains per crowd (default {d.chains})")
    g.add_argument("--burn-in", type=int, default=d.burn_in,
                   help=f"adaptive burn-in sweeps per chain (default {d.burn_in})")
    rounds = "" if study else " per round; rounds repeat until converged"
    g.add_argument("--draws", type=int, default=d.draws, help=f"recorded sweeps per chain{rounds} (default {d.draws})")
    g.add_argument("--likelihood", choices=["rounded", "density"], default=d.likelihood,
                   help="rounded: probability of the integer answer's cell (default); "
                        "density: the thesis' density at the answer")
    if not study:
        g.add_argument("--max-draws", type=int, default=d.max_draws,
                       help=f"cap on recorded sweeps per chain (default {d.max_draws})")


def _sampler_config(args, *, study: bool):
    import dataclasses

    from simfab.crowd.config import STUDY_SAMPLER, SamplerConfig

    for name in ("chains", "burn_in", "draws") + (() if study else ("max_draws",)):
        v = getattr(args, name)
        lo = 2 if name == "chains" else (0 if name == "burn_in" else 4)
        if v < lo:
            raise InputError(f"must be >= {lo}, got {v}", where="--" + name.replace("_", "-"))
    base = STUDY_SAMPLER if study else SamplerConfig()
    kw = {"chains": args.chains, "burn_in": args.burn_in, "draws": args.draws, "likelihood": args.likelihood}
    kw["max_draws"] = args.draws if study else max(args.max_draws, args.draws)
    return dataclasses.replace(base, **kw)


def _scale_arg(p):
    p.add_argument("--scale", nargs=2, type=float, metavar=("LO", "HI"), required=True,
                   help="integer rating scale, e.g. 1 10")


_RAW = {"formatter_class": __import__("argparse").RawDescriptionHelpFormatter}

AGGREGATE_DESCRIPTION = """Aggregate one crowd's ratings with every method (mean, median, majority, trimmed
mean, the Bayesian expertise/difficulty model with R-hat/ESS convergence checks) and, with
--truth, score each against it (RMS on the unit scale). Writes aggregates.csv, raters.csv,
summary.json and, with --truth, expert_network.png and errors_per_question.png to --out.

--json keys: methods {name: estimates {task: value}, rms, rms_discrete, percentile, ...},
  bayes {rhat_max, ess_min, seconds, converged, iterations_per_chain, chains, credible_mass,
  x_interval {task: [lo, hi]}}, warnings, individual_errors {worker: rms} (with --truth),
  tasks, workers, scale [lo, hi], outputs {aggregates_csv, raters_csv, summary_json,
  expert_network_png, errors_png}."""

STUDY_DESCRIPTION = """Micro-crowd study: for every sub-crowd size from --min-size to N-1, draw --subcrowds random
sub-crowds, aggregate each with the Bayesian model and report the crowd estimate's percentile
rank among the individual raters and the population bias. Writes study.csv, study.png and
study.json to --out.

--json keys: sizes (rows: size, subcrowds, percentile_mean, percentile_sd, bias_mean, bias_sd,
  unconverged_fraction, rhat_median), seconds, outputs {study_csv, study_png, study_json}."""

TRUTH_DESCRIPTION = """Computed ground truth of a 3D-printing question: support volume (m^3) and overhang area
(m^2) of a closed mesh in each orientation (printed with +z up, plate under the lowest point),
cross-checked by ray casting, scaled onto the survey scale. Overlapping bodies are united
first and a mesh size implausible for --units is reported (stderr and mesh_notes). Writes
truth_table.csv, truth_support.csv, truth_finish.csv and truth.json to --out.

--json keys: orientations (rows: orientation, euler_deg, support_volume [m^3], overhang_area
  [m^2], raycast_volume [m^3], raycast_rel_diff, support_score, finish_score), scale,
  mesh_notes (what was not taken as read), outputs {table_csv, support_truth_csv,
  finish_truth_csv, truth_json}."""

SIMULATE_DESCRIPTION = """Draw a synthetic crowd from the expertise/difficulty model: practitioners and general
public (a fraction of it malicious) rating --tasks questions with truths drawn uniformly on the
scale, or the questions of --truth. Writes ratings.csv, truth.csv and planted.json (the planted
expertise, difficulty and malicious raters) to --out.

--json keys: raters, tasks (names), malicious (count), outputs {ratings_csv, truth_csv,
  planted_json}."""

BRACKET_DESCRIPTION = """Strength ground truth of the 2D bracket designs of the structural survey: plane-stress FEM
tip deflection under --load, scored 1..5 (stiffest = 5). Writes brackets.csv,
truth_strength.csv, brackets.png and brackets.json to --out.

--json keys: setup (load [N], material, ...), designs {name: tip_deflection [m], score, area
  [m^2]}, outputs {table_csv, truth_csv, designs_png, summary_json}."""


def add_args(p):
    from simfab.cli import add_common_args

    sub = p.add_subparsers(dest="crowd_command", metavar="ACTION", parser_class=type(p))

    a = sub.add_parser("aggregate", help="aggregate one crowd's ratings (all methods), score against truth",
                       description=AGGREGATE_DESCRIPTION, **_RAW)
    a.add_argument("ratings", help="long-form CSV: worker,task,label")
    _scale_arg(a)
    a.add_argument("--truth", help="CSV task,truth (scale units) to score against")
    _sampler_args(a, study=False)
    add_common_args(a)

    s = sub.add_parser("study", help="micro-crowd study: percentile rank and population bias against crowd size",
                       description=STUDY_DESCRIPTION, **_RAW)
    s.add_argument("ratings", help="long-form CSV: worker,task,label")
    _scale_arg(s)
    s.add_argument("--truth", required=True, help="CSV task,truth")
    s.add_argument("--subcrowds", type=int, default=500, help="sub-crowds per size (default 500)")
    s.add_argument("--min-size", type=int, default=5, help="smallest sub-crowd (default 5); sizes run to N-1")
    s.add_argument("--scheduler", metavar="ADDRESS",
                   help="Dask scheduler to run the sizes on (default: a local cluster, one worker per core; "
                        "'serial': in this process)")
    _sampler_args(s, study=True)
    add_common_args(s)

    t = sub.add_parser("truth", help="support volume / overhang area of a mesh in given orientations",
                       description=TRUTH_DESCRIPTION, **_RAW)
    t.add_argument("mesh", help="STL/OBJ/PLY/OFF/GLB; printed with +z up, plate under the lowest point")
    t.add_argument("--orientations", nargs="+", default=["six"], metavar="O",
                   help="'six' (the six axis directions down) or [NAME=]RX:RY:RZ in degrees (extrinsic x, y, z); "
                        "default six")
    t.add_argument("--units", default="m", choices=["m", "mm", "cm"],
                   help="units of the mesh file: m, mm or cm (default m)")
    t.add_argument("--scale", nargs=2, type=float, metavar=("LO", "HI"), default=[1.0, 10.0],
                   help="survey scale for the scores (default 1 10)")
    t.add_argument("--no-raycast", action="store_true", help="skip the ray-cast cross-check")
    add_common_args(t)

    m = sub.add_parser("simulate", help="draw a synthetic crowd from the model (practitioners and general public)",
                       description=SIMULATE_DESCRIPTION, **_RAW)
    _scale_arg(m)
    g = m.add_mutually_exclusive_group(required=True)
    g.add_argument("--tasks", type=int, help="number of questions (truth drawn uniformly on the scale)")
    g.add_argument("--truth", help="CSV task,truth to rate")
    m.add_argument("--practitioners", type=int, default=15, help="practitioner raters (default 15)")
    m.add_argument("--public", type=int, default=0, help="general-public raters (default 0)")
    m.add_argument("--malicious", type=float, default=None,
                   help="fraction of the general public that is malicious (default 0.1)")
    m.add_argument("--difficulty", type=float, nargs="+", default=[1.0],
                   help="question difficulty beta (one value or one per question; default 1)")
    add_common_args(m)

    b = sub.add_parser("bracket", help="strength truth of the 2D bracket designs (FEM tip deflection, scores 1..5)",
                       description=BRACKET_DESCRIPTION, **_RAW)
    b.add_argument("--designs", nargs="+", metavar="NAME", help="subset of the built-in designs (default all)")
    b.add_argument("--load", type=float, default=None, help="total downward tip load, N (default 20)")
    b.add_argument("--material", default=None, help="built-in material name (default PLA)")
    add_common_args(b)


def run(args):
    cmd = getattr(args, "crowd_command", None)
    if cmd is None:
        raise InputError("choose an action: aggregate, study, truth, simulate or bracket (see 'simfab crowd --help')")
    return {"aggregate": run_aggregate, "study": run_study, "truth": run_truth, "simulate": run_simulate,
            "bracket": run_bracket}[cmd](args)


def _device(args) -> str:
    from simfab._warp import device

    return device(args.device)


def _scale(args):
    from simfab.crowd.data import Scale

    return Scale(lo=args.scale[0], hi=args.scale[1])


def run_aggregate(args):
    from simfab.crowd.analysis import aggregate_all
    from simfab.crowd.data import load_ratings, load_truth
    from simfab.progress import log

    scale = _scale(args)
    cfg = _sampler_config(args, study=False)
    ratings = load_ratings(args.ratings, scale)
    truth = load_truth(args.truth, ratings) if args.truth else None
    result = aggregate_all(ratings, truth, config=cfg, seed=args.seed, quiet=args.quiet, device=_device(args))
    for m in result["warnings"]:  # warnings show even with --quiet
        log(f"simfab: warning: {m}")
    from simfab.crowd.outputs import aggregate_outputs

    summary = aggregate_outputs(ratings, truth, result, args.out, title=os.path.basename(args.ratings))
    summary["bayes"] = {k: summary["bayes"][k] for k in ("rhat_max", "ess_min", "seconds", "converged",
                                                         "iterations_per_chain", "chains", "credible_mass",
                                                         "x_interval")}
    return summary


def run_study(args):
    from simfab.crowd.data import load_ratings, load_truth
    from simfab.crowd.study import micro_crowd_study

    scale = _scale(args)
    cfg = _sampler_config(args, study=True)
    ratings = load_ratings(args.ratings, scale)
    truth = load_truth(args.truth, ratings)
    res = micro_crowd_study(ratings, truth, n_sub=args.subcrowds, min_size=args.min_size, config=cfg, seed=args.seed,
                            quiet=args.quiet, device=_device(args), scheduler=args.scheduler)
    from simfab.crowd.outputs import study_outputs

    return study_outputs(res, args.out, title=f"Micro-crowd study of {os.path.basename(args.ratings)}")


def run_truth(args):
    from simfab.crowd.truth import load_part, orientation_table, parse_orientations
    from simfab.progress import log

    orients = parse_orientations(args.orientations)
    lo, hi = args.scale
    if not lo < hi:
        raise InputError(f"scale must have lo < hi, got {lo:g} {hi:g}", where="--scale")
    mesh, notes = load_part(args.mesh, units=args.units)
    for n in notes:  # shown even with --quiet: the part was not taken exactly as read
        log(f"simfab: warning: {n}")
    rows = orientation_table(mesh.vertices, mesh.faces, orients, raycast=not args.no_raycast, scale=(lo, hi))
    from simfab.crowd.outputs import truth_outputs

    summary = truth_outputs(rows, args.out, scale=(lo, hi), notes=notes)
    return summary


def run_simulate(args):
    import dataclasses

    from simfab.crowd import synth
    from simfab.crowd.config import GENERAL_PUBLIC, PRACTITIONERS
    from simfab.crowd.data import read_truth
    from simfab.io.atomic import write_csv, write_json

    scale = _scale(args)
    if args.practitioners < 0 or args.public < 0 or args.practitioners + args.public < 1:
        raise InputError("need at least one rater (--practitioners / --public, both >= 0)")
    mal = GENERAL_PUBLIC.malicious_fraction if args.malicious is None else args.malicious
    if not 0.0 <= mal <= 1.0:
        raise InputError(f"must be within [0, 1], got {mal}", where="--malicious")
    mixes = []
    if args.practitioners:
        mixes.append(dataclasses.replace(PRACTITIONERS, size=args.practitioners))
    if args.public:
        mixes.append(dataclasses.replace(GENERAL_PUBLIC, size=args.public, malicious_fraction=mal))
    if args.truth:
        tasks, truth = read_truth(args.truth, scale)
    else:
        if args.tasks < 1:
            raise InputError(f"must be >= 1, got {args.tasks}", where="--tasks")
        tasks, truth = None, None
    Q = len(tasks) if tasks else args.tasks
    if len(args.difficulty) not in (1, Q):
        raise InputError(f"give one difficulty or {Q} (one per question), got {len(args.difficulty)}",
                         where="--difficulty")
    beta = args.difficulty if len(args.difficulty) > 1 else args.difficulty[0]
    crowd = synth.simulate(mixes, scale=scale, truth=truth, n_tasks=Q, beta=beta, seed=args.seed)
    r = crowd.ratings
    if tasks:
        r = dataclasses.replace(r, tasks=tuple(tasks))
    os.makedirs(args.out, exist_ok=True)
    outputs = {
        "ratings_csv": str(write_csv(os.path.join(args.out, "ratings.csv"), ["worker", "task", "label"], r.to_long())),
        "truth_csv": str(write_csv(os.path.join(args.out, "truth.csv"), ["task", "truth"],
                                   list(zip(r.tasks, crowd.truth.tolist())))),
    }
    planted = {"alpha": dict(zip(r.workers, crowd.alpha.tolist())),
               "malicious": [w for w, b in zip(r.workers, crowd.malicious) if b],
               "beta": dict(zip(r.tasks, crowd.beta.tolist())), "truth": dict(zip(r.tasks, crowd.truth.tolist()))}
    outputs["planted_json"] = str(write_json(os.path.join(args.out, "planted.json"), planted))
    return {"raters": len(r.workers), "tasks": list(r.tasks), "malicious": len(planted["malicious"]),
            "outputs": outputs}


def run_bracket(args):
    import dataclasses

    from simfab.crowd.bracket import BracketSetup, bracket_survey

    setup = BracketSetup()
    if args.load is not None:
        if not (args.load > 0 and args.load < float("inf")):
            raise InputError(f"must be a positive force in N, got {args.load}", where="--load")
        setup = dataclasses.replace(setup, load=args.load)
    if args.material is not None:
        from simfab.fem.materials import material_by_name

        try:
            material_by_name(args.material)
        except InputError as e:
            raise InputError(e.message, where="--material") from None
        setup = dataclasses.replace(setup, material=args.material)
    results = bracket_survey(setup, names=args.designs)
    if len(results) < 2:
        raise InputError("need at least two designs to scale scores", where="--designs")
    from simfab.crowd.outputs import bracket_outputs

    return bracket_outputs(results, setup, args.out)


def demo(ctx):
    """The bundled 3D-printing survey (truth from the mesh, practitioners vs general public,
    micro-crowd study) and the bracket-strength truth of the structural survey (FEM)."""
    from simfab.crowd.bracket import BracketSetup, bracket_survey
    from simfab.crowd.survey import run_bundled_survey
    from simfab.progress import log

    summary = run_bundled_survey(out=ctx.out, seed=ctx.seed, quiet=ctx.quiet)
    log("crowd demo: bracket strength truth (FEM)", quiet=ctx.quiet)
    from simfab.crowd.outputs import bracket_outputs

    b = bracket_outputs(bracket_survey(BracketSetup()), BracketSetup(), os.path.join(ctx.out, "bracket"))
    summary["bracket"] = {"scores": {k: v["score"] for k, v in b["designs"].items()}, "outputs": b["outputs"]}
    return summary
