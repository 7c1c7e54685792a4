"""One insertion run of a coupling scene as a typed result: :func:`run` -> :class:`CouplingResult`.

:func:`run` loads the scene (MJCF + TOML, or a bundled name) with the given overrides, runs the
quasi-static insertion (:func:`simfab.coupling.simulate.simulate_insertion`), reads its deformation profile
(:func:`simfab.coupling.profile.profile_of`) and the stress the design's yield constraint reads
(:func:`averaged_stress`), and writes every output (:func:`simfab.coupling.outputs.write_all`) only
when ``out`` is given. ``simfab couple simulate`` is this function and a table.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from simfab.results import Result, field, to_json

__all__ = ["CouplingResult", "run", "averaged_stress", "stress_radius", "scene_overrides"]


@dataclasses.dataclass(frozen=True, kw_only=True)
class CouplingResult(Result):
    """An insertion simulation's figures (the ``--json`` summary of ``simfab couple simulate``),
    its typed :class:`simfab.coupling.profile.Profile` and the raw run.

    Args:
        scene: the scene's name.
        category: "tight", "loose", "ejects", "jams", "held by friction" or "none" (O never touched A).
        E_max, E_ss: peak and steady-state elastic energy [J].
        coupling_ratio: E_ss / E_max [%].
        F_in, F_rm, F_grip: insertion, removal and grip force [N].
        s_max, s_ss: path length at E_max and at the steady state [m]; s_path_end: the path's length [m].
        E_ss_stationary: E_ss is a minimum of the energy along the path (not just the run's end).
        max_von_mises: the largest element von Mises stress over the run [Pa].
        averaged_von_mises: the largest von Mises stress averaged over ``stress_radius`` [Pa] (what the
            design's yield constraint reads); stress_radius [m]: the scene's [design] stress_radius.
        yield_stress: the material's yield stress [Pa], None when it states none.
        max_penetration, penetration_tolerance: deepest penetration of A into O and its bound [m].
        min_det_F: the smallest deformation-gradient determinant [-].
        steps, newton_iterations, elements, element_order, nodes, object_samples: counts.
        kappa_initial, kappa_final: barrier stiffness at the start and the end [N/m]; dhat: barrier range [m].
        seconds: wall time [s]; time_split: seconds per resource; phase_split: seconds per loop phase.
        friction: Coulomb coefficient [-]; F_hold: force to start sliding O out of its seat [N].
        removal_steps, newton_iterations_removal: the frictional removal's records and Newton iterations.
        dissipated: work friction dissipated over both traversals [J].
        energy_balance: |work on A - stored - dissipated| / E_max over both traversals [-].
        jammed_at: where a frictional insertion self-locked [m], None if it did not.
        lag_solves_per_step: friction lag solves per record [-].
        warnings, notes: one line each.
        units: key -> unit of the figures above (also in the written JSON).
        profile_columns: profile CSV column -> its meaning, unit and sign convention.
        profile: the typed deformation profile (figures and per-record arrays, ``.to_pandas()``).
        insertion: the :class:`simfab.coupling.simulate.InsertionResult` (model, records).
        outputs: label -> path (profile_csv, plot_png, usd, mjcf, profile_json) when written.
    """

    scene: str
    category: str
    E_max: float = field(unit="J")
    E_ss: float = field(unit="J")
    coupling_ratio: float = field(unit="%")
    F_in: float = field(unit="N")
    F_rm: float = field(unit="N")
    F_grip: float = field(unit="N")
    s_max: float = field(unit="m")
    s_ss: float = field(unit="m")
    E_ss_stationary: bool
    s_path_end: float = field(unit="m")
    max_von_mises: float = field(unit="Pa")
    averaged_von_mises: float = field(unit="Pa")
    stress_radius: float = field(unit="m")
    yield_stress: float | None = field(unit="Pa")
    max_penetration: float = field(unit="m")
    penetration_tolerance: float = field(unit="m")
    min_det_F: float = field(unit="-")
    steps: int
    newton_iterations: int
    elements: int
    element_order: int
    nodes: int
    kappa_initial: float = field(unit="N/m")
    kappa_final: float = field(unit="N/m")
    dhat: float = field(unit="m")
    object_samples: int
    seconds: float = field(unit="s")
    time_split: dict = field(unit="s")
    phase_split: dict = field(unit="s")
    friction: float = field(unit="-")
    F_hold: float = field(unit="N")
    removal_steps: int
    dissipated: float = field(unit="J")
    energy_balance: float = field(unit="-")
    jammed_at: float | None = field(unit="m")
    lag_solves_per_step: float
    newton_iterations_removal: int
    warnings: list
    notes: list
    units: dict
    profile_columns: dict
    profile: Any = field(json=False)
    insertion: Any = field(json=False)

    def to_json(self) -> dict:
        """The ``--json`` summary: the figures, then the output paths as top-level keys (as written
        into ``NAME_summary.json``).

        Returns:
            A dict of JSON values.
        """
        d = to_json(self)
        paths = d.pop("outputs")
        return {**d, **paths}


def _table_keys() -> dict[str, str]:
    """Option name -> its table: the fields of [simulation] (``InsertionConfig``) and [contact]."""
    from simfab.coupling.config import ContactConfig, InsertionConfig

    keys = {f.name: "simulation" for f in dataclasses.fields(InsertionConfig)}
    keys.update({f.name: "contact" for f in dataclasses.fields(ContactConfig)})
    return keys


def scene_overrides(overrides: dict) -> dict:
    """Overrides of a coupling scene's TOML tables from keyword arguments.

    Args:
        overrides: a field of the [simulation] or [contact] options by name (``steps=8``,
            ``friction=0.3``), or a whole table as a dict (``simulation={"steps": 8}``,
            ``material={...}``); None as a value removes the scene's own key.

    Returns:
        {table: {key: value}} for :func:`simfab.coupling.scene.load_coupling_scene`.

    Raises:
        InputError: a keyword that is neither a table nor an option of one.
    """
    from simfab.errors import InputError

    keys = _table_keys()
    out: dict = {}
    for k, v in overrides.items():
        if isinstance(v, dict):
            out.setdefault(k, {}).update(v)
        elif k in keys:
            out.setdefault(keys[k], {})[k] = v
        else:
            raise InputError(f"unknown override {k!r} (an option of [simulation] or [contact], or a table as a dict)",
                             where=k)
    return out


def stress_radius(scene) -> float:
    """The scene's [design] stress_radius [m], else the default the design brief uses.

    Args:
        scene: a coupling scene (path or bundled name).

    Returns:
        The radius [m].
    """
    from simfab.coupling.scene import read_scene_toml, scene_paths
    from simfab.design.brief import DesignConfig

    table = read_scene_toml(scene_paths(scene)[1]).get("design")
    return DesignConfig.from_dict(dict(table or {})).stress_radius


def averaged_stress(res, radius: float) -> dict:
    """The von Mises stress the design's yield constraint reads (:mod:`simfab.design.stress`).

    Args:
        res: an :class:`simfab.coupling.simulate.InsertionResult`.
        radius: the averaging radius [m].

    Returns:
        {"averaged_von_mises": the maximum over the run of the stress averaged over ``radius`` around
        each element (P1) or quadrature point (P2) [Pa], "stress_radius": ``radius`` [m]}.
    """
    from simfab.design.stress import averaged_von_mises, p2_averaged_von_mises

    fem = res.model.fem
    records = [*res.steps, *res.removal]
    if res.model.options.element_order == 2:
        vm = max(p2_averaged_von_mises(fem, r.x, radius) for r in records)
    else:
        vm = max(averaged_von_mises(fem, r.von_mises, radius) for r in records)
    return {"averaged_von_mises": float(vm), "stress_radius": float(radius)}


def result_of(res, *, radius: float) -> CouplingResult:
    """The :class:`CouplingResult` of an insertion (nothing written).

    Args:
        res: an :class:`simfab.coupling.simulate.InsertionResult`.
        radius: the stress-averaging radius [m] (:func:`stress_radius`).

    Returns:
        Its figures, profile and the run itself.
    """
    from simfab.coupling.outputs import summarize
    from simfab.coupling.profile import profile_of

    prof, d = summarize(res)
    d.update(averaged_stress(res, radius))
    return CouplingResult(**d, profile=profile_of(res, prof), insertion=res)


def run(scene, *, out=None, seed: int = 0, device: str = "cpu", progress: bool | None = None,
        stem: str | None = None, **overrides) -> CouplingResult:
    """Simulate inserting the scene's object into its compliant part.

    Args:
        scene: NAME.xml (with NAME.toml), or a bundled scene's name (``"cclamp2d"``).
        out: folder to write the outputs into (:func:`simfab.coupling.outputs.write_all`); None writes nothing.
        seed: no effect, kept for the areas' common signature: the insertion is deterministic, and its one
            seeded step, sampling a 3D mesh object's surface for its IMLS field, belongs to the scene and takes
            the scene's ``[object] seed`` (override it as ``object={"seed": 3}``).
        device: Warp device ("cpu" or "cuda").
        progress: True shows log lines and progress bars on stderr; None/False runs silently.
        stem: the output files' stem (default: the scene's name).
        **overrides: scene options (:func:`scene_overrides`), e.g. ``friction=0.3``, ``steps=8``,
            ``element_order=2``.

    Returns:
        The :class:`CouplingResult` (``outputs`` filled when ``out`` was given).

    Raises:
        InputError: bad scene or override (before anything is computed or written).
        ConvergenceError: a step that could not be solved.
    """
    from simfab._warp import device as check_device  # quiet Warp initialization
    from simfab.contact.sdf import PrimitiveField
    from simfab.coupling.fit import scene_fit_warnings
    from simfab.coupling.scene import load_coupling_scene, part_surface
    from simfab.coupling.simulate import check_start, simulate_insertion
    from simfab.design.scene import check_brief_table
    from simfab.progress import log

    del seed  # no effect (see Args)
    quiet = not progress
    dev = check_device(device)
    cm = load_coupling_scene(scene, overrides=scene_overrides(overrides), device=dev)
    check_brief_table(scene)  # the scene's [design] table, though simulating does not read it
    check_start(cm)  # before the log line: bad input gives exactly one line on stderr
    surface = part_surface(scene) if cm.dim == 3 else None  # (its surface file too, for the fit's check)
    kind = "quadratic elements" if cm.options.element_order == 2 else "elements"
    exact = isinstance(cm.field, PrimitiveField)  # exact signed distance, not sampled
    section = {"sphere": "circle", "box": "rectangle"} if cm.dim == 2 else {}  # 2D: the primitives' sections
    obj = (f"object: exact {', '.join(section.get(p.kind, p.kind) for p in cm.field.primitives)}" if exact
           else f"{len(cm.field.vertices)} object samples")
    mu = f", friction {cm.contact.friction:g}" if cm.contact.friction > 0 else ", frictionless"
    log(f"couple: {cm.name}: {cm.fem.n_elements} {kind}, {obj}, {len(cm.s_steps) - 1} steps{mu}", quiet=quiet)
    result = result_of(simulate_insertion(cm, quiet=quiet), radius=stress_radius(scene))
    if surface is not None and result.insertion.steps:  # (a part of the user's own: do its tets resolve the
        # fit where the object ends up? simfab.coupling.fit)
        fit = scene_fit_warnings(cm, surface, result.insertion.steps[-1].s)
        result = dataclasses.replace(result, warnings=[*result.warnings, *(f"{cm.name}: {w}" for w in fit)])
    if out is None:
        return result
    from simfab.coupling.outputs import write_all

    return write_all(result, Path(out), stem=stem)
