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
    from simfab.crowd import pipeline

    cmd = getattr(args, "crowd_command", None)
    if cmd is None:
        raise InputError("choose an action: aggregate, study, truth, simulate or bracket (see 'simfab crowd --help')")
    name, pos, kw = call_args(args)
    r = getattr(pipeline, name)(*pos, out=args.out, progress=not args.quiet, **kw)
    # shown even with --quiet: the sampler's warnings; the mesh not taken exactly as read
    _log_warnings(getattr(r, "warnings", None) or getattr(r, "mesh_notes", None) or [])
    return r.to_json()


def call_args(args) -> tuple[str, tuple, dict]:
    """(function of :mod:`simfab.crowd.pipeline`, positional, keyword arguments) of a crowd command line."""
    cmd = args.crowd_command
    common = dict(seed=args.seed, device=args.device)
    if cmd == "aggregate":
        return "aggregate", (args.ratings,), dict(scale=tuple(args.scale), truth=args.truth,
                                                   config=_sampler_config(args, study=False), **common)
    if cmd == "study":
        return "study", (args.ratings,), dict(scale=tuple(args.scale), truth=args.truth, subcrowds=args.subcrowds,
                                               min_size=args.min_size, scheduler=args.scheduler,
                                               config=_sampler_config(args, study=True), **common)
    if cmd == "truth":
        return "truth", (args.mesh,), dict(orientations=args.orientations, units=args.units, scale=tuple(args.scale),
                                           raycast=not args.no_raycast, **common)
    if cmd == "simulate":
        return "synthesize", (), dict(scale=tuple(args.scale), tasks=args.tasks, truth=args.truth,
                                      practitioners=args.practitioners, public=args.public, malicious=args.malicious,
                                      difficulty=args.difficulty, **common)
    return "bracket", (), dict(designs=args.designs, load=args.load, material=args.material, **common)


def api_call(args):
    """The area function a ``crowd`` command line calls (for sweeps)."""
    from simfab.sweep.runs import ApiCall

    if getattr(args, "crowd_command", None) is None:
        return None
    _, pos, kw = call_args(args)
    return ApiCall(command=f"crowd {args.crowd_command}", args=pos, kwargs=kw)


def _log_warnings(lines) -> None:
    from simfab.progress import log

    for m in lines:
        log(f"simfab: warning: {m}")


def demo(ctx):
    """The bundled 3D-printing survey (truth from the mesh, practitioners vs general public,
    micro-crowd study) and the bracket-strength truth of the structural survey (FEM)."""
    import os

    from simfab.crowd.pipeline import bracket
    from simfab.crowd.survey import run_bundled_survey
    from simfab.progress import log

    summary = run_bundled_survey(out=ctx.out, seed=ctx.seed, quiet=ctx.quiet)
    log("crowd demo: bracket strength truth (FEM)", quiet=ctx.quiet)
    b = bracket(out=os.path.join(ctx.out, "bracket")).to_json()
    summary["bracket"] = {"scores": {k: v["score"] for k, v in b["designs"].items()}, "outputs": b["outputs"]}
    return summary
