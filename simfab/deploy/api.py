"""``simfab.deploy.run``: a target surface deployed, as one call.

The target (a scene TOML, a bundled name, a mesh file or a :class:`simfab.deploy.surface.Target`)
goes through the whole pipeline (:mod:`simfab.deploy.pipeline`) on the defaults decided from it
(:mod:`simfab.deploy.auto`) and the ``overrides``; files are written only when ``out`` is given
(:mod:`simfab.deploy.outputs`). The result's JSON form is the ``--json`` summary of ``simfab
deploy surface``.
"""

from __future__ import annotations

import dataclasses
import os

from simfab.errors import InputError
from simfab.results import Result, field

#: override name -> (scene table, field)
OVERRIDES = dict(spacing=("pattern", "spacing"), beam_width=("pattern", "beam_width"),
                 beam_thickness=("pattern", "beam_thickness"), insert_size=("pattern", "insert_half_size"),
                 young=("material", "young"), tune=("tune", "iterations"))


@dataclasses.dataclass(frozen=True, kw_only=True)
class SurfaceResult(Result):
    """A deployed target's headline figures (:func:`run`).

    Args:
        rms: RMS deviation after the best rigid alignment over the target's diameter [-].
        hausdorff: Hausdorff deviation over the diameter [-].
        height_error: deployed out-of-plane height over the target's, less 1 [-].
        inserts: the number of inserts.
        unreachable_gaps: inserts whose gap is out of the achievable range.
        cones: cone singularities of the cut flattening (0: no cuts).
        covered: fraction of the (cut) flat domain the pattern's quads cover [-].
        mujoco_at_rest: the MuJoCo relaxation settled (None: not checked).
        missed: one line per missed deployment bound, with the key or flag that would help.
        summary: the whole JSON summary (the keys of ``simfab deploy surface --json``; not in the JSON form).
        run: the pipeline's own :class:`simfab.deploy.pipeline.SurfaceRun` (arrays, pattern, network,
            deployment; not in the JSON form).
        outputs: label -> path of the files written (empty without ``out``).
    """

    rms: float = field(unit="-", default=0.0)
    """RMS deviation after the best rigid alignment over the target's diameter."""
    hausdorff: float = field(unit="-", default=0.0)
    """Hausdorff deviation over the diameter."""
    height_error: float = field(unit="-", default=0.0)
    """Deployed out-of-plane height over the target's, less 1."""
    inserts: int = 0
    unreachable_gaps: int = 0
    cones: int = 0
    covered: float = field(unit="-", default=0.0)
    """Fraction of the (cut) flat domain the pattern's quads cover."""
    mujoco_at_rest: bool | None = None
    missed: tuple = ()
    """One line per missed deployment bound, with the key or flag that would help."""
    summary: dict = field(json=False, default_factory=dict)
    run: object = field(json=False, default=None)

    def to_json(self) -> dict:
        """The ``--json`` summary (keys unchanged from ``simfab deploy surface``).

        Returns:
            ``summary`` with ``outputs`` (when files were written).
        """
        return {**self.summary, "outputs": dict(self.outputs)} if self.outputs else dict(self.summary)


def _scene(target, units, overrides: dict, notes: list | None = None):
    """The scene with ``overrides`` ({name: value or Override}) applied; an error of an override's
    value names its flag (an Override's source) or its keyword; ``notes`` gets one line per override
    that replaces a value of the scene file."""
    from simfab.deploy import scene as sc
    from simfab.deploy import surface
    from simfab.io.tables import Override

    ov: dict = {}
    for k, v in overrides.items():
        if k not in OVERRIDES:
            raise InputError(f"unknown override {k!r} (known: {', '.join(sorted(OVERRIDES))})", where="run")
        if v is not None and not (isinstance(v, Override) and v.value is None):
            table, name = OVERRIDES[k]
            ov.setdefault(table, {})[name] = v if isinstance(v, Override) else Override(v, k)
    log = notes.append if notes is not None else None
    if isinstance(target, surface.Target):
        import tempfile

        import trimesh

        with tempfile.TemporaryDirectory() as tmp:
            p = os.path.join(tmp, "target.obj")
            trimesh.Trimesh(target.V, target.F, process=False).export(p)
            s = sc.load_deploy_scene(p, overrides=ov, log=log)
        return dataclasses.replace(s, target=target, path=target.name)
    target = str(target)
    path = sc.bundled_path(target) if target in sc.NAMES and not os.path.exists(target) else target
    return sc.load_deploy_scene(path, units=units, overrides=ov, log=log)


def run(target, *, out=None, seed: int = 0, device: str = "cpu", progress=None, units: str | None = None,
        mujoco_check: bool = True, **overrides) -> SurfaceResult:
    """Deploy a target surface: flattening, pattern, laser-cut files, deployment, deviation, MuJoCo check.

    Args:
        target: a scene TOML, a bundled name (dome, saddle, mixed, cap80, saddle_steep, petal), a mesh
            file (OBJ/STL/PLY, ``units``) or a :class:`simfab.deploy.surface.Target`.
        out: folder for the output files (:data:`simfab.deploy.outputs.NAMES`); None: nothing written.
        seed: unused (the pipeline is deterministic); accepted as every area's ``run`` does.
        device: Warp device ("cpu").
        progress: None for quiet, anything else to log the stages.
        units: units of a mesh file ("m", "cm", "mm").
        mujoco_check: step the MuJoCo scene (stability, relaxation).
        **overrides: spacing, beam_width, beam_thickness, insert_size [m], young [Pa], tune (steps).

    Returns:
        The :class:`SurfaceResult`.
    """
    del seed
    from simfab.io.tables import Override

    # an Override (a command-line flag) names its flag in errors and notes; a plain keyword names itself
    sources = {k: (v.source if isinstance(v, Override) else k) for k, v in overrides.items()}
    notes: list = []
    scene = _scene(target, units, overrides, notes)
    overrides = {k: (v.value if isinstance(v, Override) else v) for k, v in overrides.items()}
    size = scene.target.diameter
    if scene.pattern.spacing > size:  # not one grid cell fits: an input error, not an empty pattern
        raise InputError(f"{scene.pattern.spacing:.4g} m is larger than the target surface (its bounding-box "
                         f"diagonal {size:.4g} m)", where=sources.get("spacing", "spacing")
                         if overrides.get("spacing") is not None else f"{scene.path}: pattern.spacing")
    if out is not None and os.path.exists(out) and not os.path.isdir(out):
        raise InputError("output location exists and is not a folder", where=str(out))
    import simfab.rods  # noqa: F401  (quiet Warp start-up before simfab._warp initializes it)
    from simfab._warp import device as _device
    from simfab.deploy import outputs, pipeline

    res = pipeline.run(scene, device=_device(device), quiet=progress is None, mujoco_check=mujoco_check)
    from simfab.progress import log

    for n in notes:  # once, after the run: a failing run stays one line
        log(n, quiet=progress is None)
    summary = pipeline.summary(res)
    paths = {}
    if out is not None:
        summary["outputs"] = outputs.paths(out)
        paths = outputs.write_all(res, summary, out)
    b, st = summary["bounds"], (summary.get("mujoco") or {}).get("stability") or {}
    return SurfaceResult(outputs=paths, rms=b["rms"], hausdorff=summary["deviation"]["hausdorff"],
                         height_error=b["height_error"], inserts=summary["inserts"],
                         unreachable_gaps=b["unreachable_gaps"], cones=(summary.get("cuts") or {}).get("cones", 0),
                         covered=summary["flat_area_covered"], mujoco_at_rest=st.get("settled"),
                         missed=tuple(b["missed"]), summary=summary, run=res)


#: ``mjcf_rods`` values of :func:`cell`
MJCF_RODS = ("capsules", "chain", "flexcomp")


@dataclasses.dataclass(frozen=True, kw_only=True)
class CellInsertResult:
    """One insert of the unit cell deployed (an entry of :attr:`CellResult.inserts`).

    Args:
        insert_half_size: the insert's half-size r [m].
        gap_half_size: the cell's gap half-size [m].
        relation: "larger" or "smaller": the insert's half-size against the gap's.
        angle_deficit: the fan's angle deficit at the insert centre [rad]
            (:func:`simfab.deploy.unitcell.gaussian_curvature`).
        gaussian_curvature: the discrete Gaussian curvature [1/m^2].
        kind: "dome" (positive) or "saddle".
        insert_rise: height of the insert centre above the ring's best-fit plane [m].
        saddle_amplitude: amplitude of the ring's cos/sin 2 phi height pattern [m].
        stable: the unloaded equilibrium's Hessian is positive definite.
        increments: quasi-static increments.
        newton_iterations: Newton iterations per increment.
        energy: elastic energy of the deployed state [J].
        gaussian_curvature_per_increment: the discrete Gaussian curvature per increment [1/m^2].
        max_bending_strain: the largest bending strain of the deployed rods [-].
        outputs: the files written (usd, mjcf, png; empty without ``out``).
        deployment: the :class:`simfab.deploy.unitcell.CellDeployment` (states per increment, cell,
            insert; not in the JSON form).
    """

    insert_half_size: float = field(unit="m")
    gap_half_size: float = field(unit="m")
    relation: str
    """"larger" or "smaller": the insert's half-size against the gap's."""
    angle_deficit: float = field(unit="rad")
    gaussian_curvature: float = field(unit="1/m^2")
    kind: str
    """"dome" (positive discrete Gaussian curvature) or "saddle"."""
    insert_rise: float = field(unit="m")
    saddle_amplitude: float = field(unit="m")
    stable: bool
    increments: int
    newton_iterations: list
    """Newton iterations per increment."""
    energy: float = field(unit="J")
    gaussian_curvature_per_increment: list = field(unit="1/m^2")
    max_bending_strain: float = field(unit="-")
    outputs: dict = dataclasses.field(default_factory=dict)
    deployment: object = field(json=False, default=None)
    """The :class:`simfab.deploy.unitcell.CellDeployment` (states per increment, cell, insert)."""


@dataclasses.dataclass(frozen=True, kw_only=True)
class CellResult(Result):
    """The unit cell deployed by each of its inserts (:func:`cell`, ``simfab deploy``).

    Args:
        scene: the unit-cell MJCF scene.
        inserts: insert body name -> :class:`CellInsertResult`.
        summary_json: path of ``deploy.json`` (None without ``out``).
        outputs: label -> path of every file written (``<body>/<label>`` and ``json``).
    """

    scene: str
    inserts: dict
    """Insert body name -> :class:`CellInsertResult`."""
    summary_json: str | None = None
    """Path of ``deploy.json`` (None without ``out``)."""

    def to_json(self) -> dict:
        """The ``--json`` summary (keys unchanged from ``simfab deploy``), also written as ``deploy.json``.

        Returns:
            {scene, inserts (each with its ``outputs``), summary_json}.
        """
        d = super().to_json()
        d.pop("outputs")
        return d


def cell(scene=None, *, out=None, inserts=None, increments: int | None = None, mjcf_rods: str = "capsules",
         device: str = "cpu", progress=None) -> CellResult:
    """Deploy the four-beam unit cell by each insert of its scene (``simfab deploy``).

    Args:
        scene: unit-cell MJCF scene (None: the bundled ``scenes/deploy/unit_cell.xml``).
        out: folder for the outputs (per insert ``<body>/deploy.usda``, ``deployed.xml``,
            ``deployed.png``; ``deploy.json``), written together or not at all; None: nothing written.
        inserts: insert body names to deploy (None: every ``insert*`` body of the scene).
        increments: quasi-static increments (None: the scene's ``cell_increments``).
        mjcf_rods: rods in the deployed MJCF: "capsules" (static), "chain" (simulatable) or "flexcomp".
        device: Warp device ("cpu").
        progress: None for quiet, anything else to log each insert and show the increments.

    Returns:
        The :class:`CellResult`. InputError (naming the keyword) on a bad value, before any solve.
    """
    import simfab.rods  # noqa: F401  (quiet Warp start-up before simfab._warp initializes it)
    from simfab._warp import device as _device
    from simfab.deploy import export, unitcell
    from simfab.deploy import outputs as outs
    from simfab.progress import log

    if mjcf_rods not in MJCF_RODS:
        raise InputError(f"must be one of {', '.join(MJCF_RODS)} (got {mjcf_rods!r})", where="mjcf_rods")
    if out is not None and os.path.exists(out) and not os.path.isdir(out):
        raise InputError("output location exists and is not a folder", where=str(out))
    quiet = progress is None
    dev = _device(device)
    scene = str(scene) if scene is not None else unitcell.default_scene_path()
    cfg, bodies = unitcell.load_cell_scene(scene)
    if increments is not None:
        lo, hi = unitcell.COUNT_RANGES["increments"]
        if not lo <= increments <= hi:
            raise InputError(f"must be in [{lo}, {hi}] (got {increments})", where="increments")
        cfg = dataclasses.replace(cfg, increments=increments)
    names = list(inserts) if inserts else sorted(bodies)
    for n in names:
        if n not in bodies:
            raise InputError(f"no insert body {n!r} in the scene (have: {', '.join(sorted(bodies))})",
                             where="inserts")
    paths = outs.cell_paths(out, names) if out is not None else None
    results = {}
    for n in names:
        ins = bodies[n]
        log(f"deploy: {n} (half-size {ins.r * 1e3:.1f} mm, gap half-size {cfg.gap * 1e3:.1f} mm)", quiet=quiet)
        d = unitcell.deploy_cell(cfg, ins, device=dev, quiet=quiet)
        results[n] = CellInsertResult(
            insert_half_size=ins.r, gap_half_size=cfg.gap, relation="larger" if ins.r > cfg.gap else "smaller",
            **d.curvature, stable=d.stable, increments=len(d.iterations), newton_iterations=d.iterations,
            energy=d.energy, gaussian_curvature_per_increment=d.curvature_history,
            max_bending_strain=float(export.bending_strain(d.cell.model, d.states[-1]).max()),
            outputs={k: paths[n, k] for k in outs.CELL_NAMES} if paths else {}, deployment=d)
    files = {f"{k[0]}/{k[1]}" if isinstance(k, tuple) else k: v for k, v in (paths or {}).items()}
    res = CellResult(scene=scene, inserts=results, summary_json=paths["json"] if paths else None, outputs=files)
    if paths is not None:
        outs.write_cell(res, paths, mjcf_rods=mjcf_rods)
    return res
