"""The crowd actions as functions with typed results (``simfab crowd ACTION`` is each and a table).

- :func:`aggregate` (also :func:`run`) - one crowd's ratings, every aggregator, scored against truth
- :func:`study` - the micro-crowd study over sub-crowd sizes
- :func:`truth` - support volume / overhang area of a mesh per orientation
- :func:`synthesize` - a synthetic crowd drawn from the expertise/difficulty model
- :func:`bracket` - strength truth of the 2D bracket designs (FEM)

Files are written only when ``out`` is given, by the writers of :mod:`simfab.crowd.outputs`.
RMS errors are on the unit scale (label - lo) / (hi - lo).
"""

from __future__ import annotations

import dataclasses
import os

from simfab.errors import InputError
from simfab.results import Result, field, to_json

__all__ = ["AggregateResult", "StudyResult", "TruthResult", "SynthResult", "BracketResult", "run", "aggregate",
           "study", "truth", "synthesize", "bracket"]

#: The Bayesian model's entries in an aggregation's JSON (the posterior's per-rater draws stay in summary.json).
BAYES_KEYS = ("rhat_max", "ess_min", "seconds", "converged", "iterations_per_chain", "chains", "credible_mass",
              "x_interval")


@dataclasses.dataclass(frozen=True, kw_only=True)
class AggregateResult(Result):
    """One crowd aggregated by every method.

    Args:
        methods: name -> {estimates {task: value (scale units)}, rms, rms_discrete, percentile, ...} (RMS on the
            unit scale).
        bayes: the Bayesian model's convergence and intervals (:data:`BAYES_KEYS`; seconds [s]).
        warnings: one line each.
        individual_errors: worker -> RMS error on the unit scale (with truth; None without).
        tasks: the questions; workers: the number of raters; scale: [lo, hi].
        posterior: the Bayesian model's whole summary (per-rater expertise, ...).
    """

    methods: dict
    bayes: dict
    warnings: list
    individual_errors: dict | None = None
    tasks: list
    workers: int
    scale: list
    posterior: dict = field(json=False, default_factory=dict)

    def to_json(self) -> dict:
        """The ``--json`` object (keys in the order ``simfab crowd aggregate`` prints them).

        Returns:
            A dict of JSON values.
        """
        d = to_json(self)
        head = {k: d[k] for k in ("methods", "bayes", "warnings")}
        if d["individual_errors"] is not None:
            head["individual_errors"] = d["individual_errors"]
        return {**head, "outputs": d["outputs"], "tasks": d["tasks"], "workers": d["workers"], "scale": d["scale"]}


@dataclasses.dataclass(frozen=True, kw_only=True)
class StudyResult(Result):
    """A micro-crowd study.

    Args:
        sizes: per sub-crowd size: size, subcrowds, percentile_mean/sd [%], bias_mean/sd (unit scale),
            unconverged_fraction, rhat_median.
        seconds: wall time [s].
        study: the :class:`simfab.crowd.microcrowd.MicrocrowdStudy` (per-sub-crowd figures).
    """

    sizes: list
    seconds: float = field(unit="s")
    study: object = field(json=False, default=None)

    def to_json(self) -> dict:
        """The ``--json`` object: sizes, seconds, outputs.

        Returns:
            A dict of JSON values.
        """
        d = to_json(self)
        return {"sizes": d["sizes"], "seconds": d["seconds"], "outputs": d["outputs"]}


@dataclasses.dataclass(frozen=True, kw_only=True)
class TruthResult(Result):
    """Computed ground truth of a 3D-printing question per orientation.

    Args:
        orientations: rows: orientation, euler_deg, support_volume [m^3], overhang_area [m^2], raycast_volume
            [m^3], raycast_rel_diff, support_score, finish_score (survey scale).
        scale: [lo, hi] of the survey scale.
        mesh_notes: what was not taken as read (united bodies, implausible size).
    """

    orientations: list
    scale: list
    mesh_notes: list

    def to_json(self) -> dict:
        """The ``--json`` object: orientations, scale, mesh_notes, outputs.

        Returns:
            A dict of JSON values.
        """
        d = to_json(self)
        return {k: d[k] for k in ("orientations", "scale", "mesh_notes", "outputs")}


@dataclasses.dataclass(frozen=True, kw_only=True)
class SynthResult(Result):
    """A synthetic crowd.

    Args:
        raters: number of raters; tasks: the question names; malicious: number of malicious raters.
        crowd: the :class:`simfab.crowd.synth.SyntheticCrowd` (ratings, planted expertise and difficulty).
    """

    raters: int
    tasks: list
    malicious: int
    crowd: object = field(json=False, default=None)

    def to_json(self) -> dict:
        """The ``--json`` object: raters, tasks, malicious, outputs.

        Returns:
            A dict of JSON values.
        """
        d = to_json(self)
        return {k: d[k] for k in ("raters", "tasks", "malicious", "outputs")}


@dataclasses.dataclass(frozen=True, kw_only=True)
class BracketResult(Result):
    """Strength truth of the bracket designs.

    Args:
        setup: load [N], material, ... of the plane-stress FEM.
        designs: name -> {tip_deflection [m], score (1..5, stiffest 5), area [m^2]}.
        results: the per-design FEM results.
    """

    setup: dict
    designs: dict
    results: list = field(json=False, default_factory=list)

    def to_json(self) -> dict:
        """The ``--json`` object: setup, designs, outputs.

        Returns:
            A dict of JSON values.
        """
        d = to_json(self)
        return {k: d[k] for k in ("setup", "designs", "outputs")}


def _scale(scale):
    from simfab.crowd.data import Scale

    if isinstance(scale, Scale):
        return scale
    lo, hi = scale
    return Scale(lo=lo, hi=hi)


def aggregate(ratings, *, scale, truth=None, config=None, out=None, seed: int = 0, device: str = "cpu",
              progress: bool | None = None) -> AggregateResult:
    """Aggregate one crowd's ratings with every method, scored against ``truth``.

    Args:
        ratings: long-form CSV worker,task,label (integer labels on the scale).
        scale: (lo, hi) of the survey scale (or a :class:`simfab.crowd.data.Scale`).
        truth: CSV task,truth to score against, or None.
        config: the Bayesian sampler's :class:`simfab.crowd.config.SamplerConfig` (default: its defaults).
        out: folder for aggregates.csv, raters.csv, summary.json and (with truth) figures; None writes nothing.
        seed: the sampler's seed.
        device: Warp device.
        progress: True shows progress bars.

    Returns:
        The :class:`AggregateResult`.
    """
    from simfab._warp import device as check_device
    from simfab.crowd.analysis import aggregate_all
    from simfab.crowd.config import SamplerConfig
    from simfab.crowd.data import load_ratings, load_truth

    sc = _scale(scale)
    r = load_ratings(ratings, sc)
    t = load_truth(truth, r) if truth else None
    raw = aggregate_all(r, t, config=config or SamplerConfig(), seed=seed, quiet=not progress,
                        device=check_device(device))
    outputs = {}
    if out is not None:
        from simfab.crowd.outputs import aggregate_outputs

        outputs = aggregate_outputs(r, t, raw, out, title=os.path.basename(str(ratings)))["outputs"]
    return AggregateResult(methods=raw["methods"], bayes={k: raw["bayes"][k] for k in BAYES_KEYS},
                           warnings=list(raw["warnings"]), individual_errors=raw.get("individual_errors"),
                           tasks=list(r.tasks), workers=len(r.workers), scale=[r.scale.lo, r.scale.hi],
                           posterior=raw["bayes"], outputs=outputs)


def run(ratings, *, out=None, seed: int = 0, device: str = "cpu", progress: bool | None = None,
        **overrides) -> AggregateResult:
    """The crowd area's ``run``: :func:`aggregate` (``scale=(lo, hi)`` is required; ``truth``, ``config``).

    Args:
        ratings: long-form CSV worker,task,label.
        out: output folder; None writes nothing.
        seed: the sampler's seed.
        device: Warp device.
        progress: True shows progress bars.
        **overrides: :func:`aggregate`'s ``scale``, ``truth``, ``config``.

    Returns:
        The :class:`AggregateResult`.
    """
    unknown = set(overrides) - {"scale", "truth", "config"}
    if unknown:
        k = sorted(unknown)[0]
        raise InputError(f"unknown option {k!r} (scale, truth, config)", where=k)
    if "scale" not in overrides:
        raise InputError("give the survey scale, scale=(lo, hi)", where="scale")
    return aggregate(ratings, out=out, seed=seed, device=device, progress=progress, **overrides)


def study(ratings, *, scale, truth, subcrowds: int = 500, min_size: int = 5, scheduler: str | None = None,
          config=None, out=None, seed: int = 0, device: str = "cpu", progress: bool | None = None) -> StudyResult:
    """Micro-crowd study: percentile rank and population bias of the Bayesian estimate against sub-crowd size.

    Args:
        ratings: long-form CSV worker,task,label.
        scale: (lo, hi) of the survey scale.
        truth: CSV task,truth.
        subcrowds: sub-crowds drawn per size.
        min_size: the smallest sub-crowd; sizes run to N-1.
        scheduler: Dask scheduler address ('serial': in this process; None: a local cluster).
        config: the sampler's :class:`simfab.crowd.config.SamplerConfig` (default: ``STUDY_SAMPLER``).
        out: folder for study.csv, study.png, study.json; None writes nothing.
        seed: seed of the sub-crowd draws and the sampler.
        device: Warp device.
        progress: True shows progress bars.

    Returns:
        The :class:`StudyResult`.
    """
    from simfab._warp import device as check_device
    from simfab.crowd.config import STUDY_SAMPLER
    from simfab.crowd.data import load_ratings, load_truth
    from simfab.crowd.microcrowd import micro_crowd_study

    sc = _scale(scale)
    r = load_ratings(ratings, sc)
    t = load_truth(truth, r)
    res = micro_crowd_study(r, t, n_sub=subcrowds, min_size=min_size, config=config or STUDY_SAMPLER, seed=seed,
                            quiet=not progress, device=check_device(device), scheduler=scheduler)
    outputs = {}
    if out is not None:
        from simfab.crowd.outputs import study_outputs

        outputs = study_outputs(res, out, title=f"Micro-crowd study of {os.path.basename(str(ratings))}")["outputs"]
    return StudyResult(sizes=res.rows(), seconds=res.seconds, study=res, outputs=outputs)


def truth(mesh, *, orientations=("six",), units: str = "m", scale=(1.0, 10.0), raycast: bool = True, out=None,
          seed: int = 0, device: str = "cpu", progress: bool | None = None) -> TruthResult:
    """Support volume and overhang area of a closed mesh per print orientation, scored on the survey scale.

    Args:
        mesh: STL/OBJ/PLY/OFF/GLB, printed with +z up, plate under the lowest point.
        orientations: "six", "NAME=RX:RY:RZ" entries (degrees), ... (:func:`simfab.crowd.truth.parse_orientations`).
        units: the mesh's length unit ("m", "mm", "cm").
        scale: (lo, hi) of the survey scale.
        raycast: cross-check the support volume by ray casting.
        out: folder for truth_table.csv, truth_support.csv, truth_finish.csv, truth.json; None writes nothing.
        seed: accepted for the common signature (deterministic).
        device: accepted for the common signature (CPU geometry).
        progress: unused (no long loops).

    Returns:
        The :class:`TruthResult` (``mesh_notes``: what was not taken as read).
    """
    from simfab.crowd.truth import load_part, orientation_table, parse_orientations

    del seed, device, progress
    orients = parse_orientations(list(orientations))
    lo, hi = scale
    if not lo < hi:
        raise InputError(f"scale must have lo < hi, got {lo:g} {hi:g}", where="--scale")
    part, notes = load_part(mesh, units=units)
    rows = orientation_table(part.vertices, part.faces, orients, raycast=raycast, scale=(lo, hi))
    outputs = {}
    if out is not None:
        from simfab.crowd.outputs import truth_outputs

        outputs = truth_outputs(rows, out, scale=(lo, hi), notes=notes)["outputs"]
    return TruthResult(orientations=rows, scale=[lo, hi], mesh_notes=list(notes), outputs=outputs)


def synthesize(*, scale, tasks: int | None = None, truth=None, practitioners: int = 15, public: int = 0,
               malicious: float | None = None, difficulty=(1.0,), out=None, seed: int = 0, device: str = "cpu",
               progress: bool | None = None) -> SynthResult:
    """Draw a synthetic crowd from the expertise/difficulty model.

    Args:
        scale: (lo, hi) of the survey scale.
        tasks: number of questions (truths drawn uniformly on the scale), or None with ``truth``.
        truth: CSV task,truth of the questions to rate, or None with ``tasks``.
        practitioners: practitioner raters; public: general-public raters.
        malicious: the general public's malicious fraction in [0, 1] (default the model's).
        difficulty: one difficulty for every question, or one per question.
        out: folder for ratings.csv, truth.csv, planted.json; None writes nothing.
        seed: the draw's seed.
        device: accepted for the common signature (NumPy).
        progress: unused.

    Returns:
        The :class:`SynthResult`.
    """
    from simfab.crowd import synth
    from simfab.crowd.config import GENERAL_PUBLIC, PRACTITIONERS
    from simfab.crowd.data import read_truth

    del device, progress
    sc = _scale(scale)
    if practitioners < 0 or public < 0 or practitioners + public < 1:
        raise InputError("need at least one rater (--practitioners / --public, both >= 0)")
    mal = GENERAL_PUBLIC.malicious_fraction if malicious is None else malicious
    if not 0.0 <= mal <= 1.0:
        raise InputError(f"must be within [0, 1], got {mal}", where="--malicious")
    if (tasks is None) == (truth is None):
        raise InputError("give either a number of tasks or a truth CSV", where="--tasks/--truth")
    mixes = []
    if practitioners:
        mixes.append(dataclasses.replace(PRACTITIONERS, size=practitioners))
    if public:
        mixes.append(dataclasses.replace(GENERAL_PUBLIC, size=public, malicious_fraction=mal))
    if truth:
        names, values = read_truth(truth, sc)
    else:
        if tasks < 1:
            raise InputError(f"must be >= 1, got {tasks}", where="--tasks")
        names, values = None, None
    Q = len(names) if names else tasks
    difficulty = list(difficulty)
    if len(difficulty) not in (1, Q):
        raise InputError(f"give one difficulty or {Q} (one per question), got {len(difficulty)}",
                         where="--difficulty")
    beta = difficulty if len(difficulty) > 1 else difficulty[0]
    crowd = synth.simulate_crowd(mixes, scale=sc, truth=values, n_tasks=Q, beta=beta, seed=seed)
    if names:
        crowd = dataclasses.replace(crowd, ratings=dataclasses.replace(crowd.ratings, tasks=tuple(names)))
    outputs = {}
    if out is not None:
        from simfab.crowd.outputs import synth_outputs

        outputs = synth_outputs(crowd, out)
    r = crowd.ratings
    return SynthResult(raters=len(r.workers), tasks=list(r.tasks), malicious=int(sum(bool(b) for b in crowd.malicious)),
                       crowd=crowd, outputs=outputs)


def bracket(*, designs=None, load: float | None = None, material: str | None = None, out=None, seed: int = 0,
            device: str = "cpu", progress: bool | None = None) -> BracketResult:
    """Strength truth of the 2D bracket designs: plane-stress FEM tip deflection, scored 1..5 (stiffest 5).

    Args:
        designs: subset of the built-in design names (default all; at least two).
        load: total downward tip load [N] (default the setup's).
        material: built-in material name (default the setup's).
        out: folder for brackets.csv, truth_strength.csv, brackets.png, brackets.json; None writes nothing.
        seed: accepted for the common signature (deterministic).
        device: accepted for the common signature.
        progress: unused.

    Returns:
        The :class:`BracketResult`.
    """
    from simfab.crowd.bracket import BracketSetup, bracket_survey, strength_scores

    del seed, device, progress
    setup = BracketSetup()
    if load is not None:
        if not (load > 0 and load < float("inf")):
            raise InputError(f"must be a positive force in N, got {load}", where="--load")
        setup = dataclasses.replace(setup, load=load)
    if material is not None:
        from simfab.fem.materials import material_by_name

        try:
            material_by_name(material)
        except InputError as e:
            raise InputError(e.message, where="--material") from None
        setup = dataclasses.replace(setup, material=material)
    results = bracket_survey(setup, names=designs)
    if len(results) < 2:
        raise InputError("need at least two designs to scale scores", where="--designs")
    outputs = {}
    if out is not None:
        from simfab.crowd.outputs import bracket_outputs

        outputs = bracket_outputs(results, setup, out)["outputs"]
    scores = strength_scores(results)
    return BracketResult(setup=dataclasses.asdict(setup),
                         designs={r.name: {"tip_deflection": r.deflection, "score": float(s), "area": r.area}
                                  for r, s in zip(results, scores)},
                         results=list(results), outputs=outputs)
