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
    """A deployed target's headline figures; ``summary`` is the whole JSON summary (``to_json()``
    returns it with ``outputs``, the keys of ``simfab deploy surface --json``); ``run`` the pipeline's
    own result (arrays, pattern, network, deployment; not in the JSON)."""

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
        """The ``--json`` summary (keys unchanged from ``simfab deploy surface``), with ``outputs``."""
        return {**self.summary, "outputs": dict(self.outputs)} if self.outputs else dict(self.summary)


def _scene(target, units, overrides: dict):
    from simfab.deploy import scene as sc
    from simfab.deploy import surface

    ov = {"pattern": {}, "material": {}, "tune": {}}
    for k, v in overrides.items():
        if k not in OVERRIDES:
            raise InputError(f"unknown override {k!r} (known: {', '.join(sorted(OVERRIDES))})", where="run")
        if v is not None:
            table, name = OVERRIDES[k]
            ov[table][name] = v
    if isinstance(target, surface.Target):
        import tempfile

        import trimesh

        with tempfile.TemporaryDirectory() as tmp:
            p = os.path.join(tmp, "target.obj")
            trimesh.Trimesh(target.V, target.F, process=False).export(p)
            s = sc.load_scene(p, overrides=ov)
        return dataclasses.replace(s, target=target, path=target.name)
    target = str(target)
    path = sc.bundled_path(target) if target in sc.NAMES and not os.path.exists(target) else target
    try:
        return sc.load_scene(path, units=units, overrides=ov)
    except InputError as e:  # a given override's bad value is blamed on the override, not on the file
        for k, (table, name) in OVERRIDES.items():
            if overrides.get(k) is not None and str(e.where or "").endswith(f"{table}.{name}"):
                raise InputError(e.message, where=k) from None
        raise


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
    scene = _scene(target, units, overrides)
    size = scene.target.diameter
    if scene.pattern.spacing > size:  # not one grid cell fits: an input error, not an empty pattern
        raise InputError(f"{scene.pattern.spacing:.4g} m is larger than the target surface (its bounding-box "
                         f"diagonal {size:.4g} m)", where="spacing" if overrides.get("spacing") is not None
                         else f"{scene.path}: pattern.spacing")
    if out is not None and os.path.exists(out) and not os.path.isdir(out):
        raise InputError("output location exists and is not a folder", where=str(out))
    import simfab.rods  # noqa: F401  (quiet Warp start-up before simfab._warp initializes it)
    from simfab._warp import device as _device
    from simfab.deploy import outputs, pipeline

    res = pipeline.run(scene, device=_device(device), quiet=progress is None, mujoco_check=mujoco_check)
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
