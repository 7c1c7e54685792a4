"""Surface-deployment scene files (TOML): the target and every parameter of the pipeline.

    [target]          # either a procedural surface ...
    kind = "spherical_cap"            # spherical_cap | saddle | mixed | cylinder (simfab.deploy.surface)
    radius = 0.15                     # kind-specific parameters [m, deg]
    angle_deg = 50
    rings = 24                        # triangulation rings
    # ... or a mesh file (OBJ/STL/PLY, relative to the scene file):
    # mesh = "lily.obj"
    # units = "mm"

    [pattern]    # simfab.deploy.pattern.PatternConfig   (spacing, beam_width, ..., lengths in m)
    [material]   # young [Pa], poisson [-], density [kg/m^3]      } simfab.deploy.network.DeployConfig
    [deploy]     # increments, perturbation, beam_segments, ...   }
    [mujoco]     # simfab.deploy.mjcf_sim.SimConfig
    [tune]       # simfab.deploy.tuning.TuneConfig (iterations = 0: no tuning)
    [cuts]       # simfab.deploy.cuts.CutsConfig (max_cones = 0: no cuts)

The config tables load through :func:`simfab.io.tables.load_table` (:data:`TABLES`): an unknown
table or key is refused naming the file, the table and the key; a bad value names the file and
``table.key``, or the flag (:class:`simfab.io.tables.Override`) that gave it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from simfab._bundled import scenes_dir
from simfab.deploy import surface
from simfab.deploy.cuts import CutsConfig
from simfab.deploy.mjcf_sim import SimConfig
from simfab.deploy.network import DeployConfig
from simfab.deploy.pattern import PatternConfig
from simfab.deploy.tuning import TuneConfig
from simfab.errors import InputError
from simfab.io.tables import Override, check_keys, load_table, read_toml

BUNDLED = ("dome", "saddle", "mixed")
# the steep targets (insert catalogues; cuts with cones on the cap and the petal): bundled names too
BUNDLED_STEEP = ("cap80", "saddle_steep", "petal")
NAMES = BUNDLED + BUNDLED_STEEP


@dataclass(frozen=True)
class SurfaceScene:
    """A loaded surface scene (:func:`load_deploy_scene`).

    Args:
        target: the :class:`simfab.deploy.surface.Target`.
        pattern: the :class:`simfab.deploy.pattern.PatternConfig` (``[pattern]``).
        deploy: the :class:`simfab.deploy.network.DeployConfig` (``[material]`` and ``[deploy]``).
        mujoco: the :class:`simfab.deploy.mjcf_sim.SimConfig` (``[mujoco]``).
        path: the scene file (or the target's name).
        tune: the :class:`simfab.deploy.tuning.TuneConfig` (``[tune]``).
        cuts: the :class:`simfab.deploy.cuts.CutsConfig` (``[cuts]``).
        decisions: the :class:`simfab.deploy.auto.Decisions` (what the defaults decided from the
            target; None without ``auto``).
    """

    target: object
    pattern: object
    deploy: object
    mujoco: object
    path: str
    tune: object = None
    cuts: object = None
    decisions: object = None  # simfab.deploy.auto.Decisions: what the defaults decided from the target


def bundled_path(name: str) -> str:
    """The file of a bundled surface scene.

    Args:
        name: one of :data:`NAMES`.

    Returns:
        The path of ``scenes/deploy/<name>.toml``.
    """
    return str(scenes_dir("deploy", f"{name}.toml"))


#: The config tables of a surface scene and what each loads into (``[material]`` and ``[deploy]``
#: both fill :class:`simfab.deploy.network.DeployConfig`, each with its own keys).
TABLES = {"pattern": PatternConfig, "material": DeployConfig, "deploy": DeployConfig, "mujoco": SimConfig,
          "tune": TuneConfig, "cuts": CutsConfig}
#: The keys of ``[material]``; the other fields of DeployConfig are ``[deploy]``'s.
MATERIAL_KEYS = ("young", "poisson", "density")


def _integral(v, where):
    """A count written as a float (``8.0``) read as the int it is, as the scenes always allowed."""
    return int(v) if isinstance(v, float) and v.is_integer() else v


#: Parsers of :func:`simfab.io.tables.load_table` per table: the counts that accept a whole float.
PARSERS = {"deploy": dict.fromkeys(("beam_segments", "spring_segments", "increments"), _integral),
           "mujoco": {"iterations": _integral}}


def _keys(table: str) -> tuple[str, ...] | None:
    """The keys ``table`` may hold (None: every field of its config)."""
    if TABLES[table] is not DeployConfig:
        return None
    fields = [f.name for f in dataclasses.fields(DeployConfig)]
    return MATERIAL_KEYS if table == "material" else tuple(k for k in fields if k not in MATERIAL_KEYS)


def _target(doc: dict, p: Path, units: str | None) -> surface.Target:
    """The ``[target]`` table's surface: a procedural kind or a mesh file (relative to the scene)."""
    where = str(p)
    tt = doc.get("target", {})
    if not isinstance(tt, dict):
        raise InputError(f"[target] must be a table, got {tt!r}", where=where)
    tt = dict(tt)
    if "mesh" in tt:
        check_keys(tt, ("mesh", "units"), table_name="target", file=where)
        mesh = (p.parent / tt.pop("mesh")).resolve()
        u = units or tt.get("units", "m")
        target = surface.load(mesh, units=u)
        surface.check_size(target, units=u, where=f"{where}: [target] mesh")
        return target
    if "kind" in tt:
        kind = tt.pop("kind")
        target = surface.procedural(kind, tt, where=f"{where}: [target]")
        surface.check_size(target, units="m", where=f"{where}: [target]")
        return target
    raise InputError("[target] needs 'kind' (procedural) or 'mesh' (file)", where=where)


def load_deploy_scene(path, *, units: str | None = None, overrides: dict | None = None,
                      auto: bool = True, log: Callable[[str], None] | None = None) -> SurfaceScene:
    """Read a surface scene TOML, or a bare mesh file (then every parameter is a default or an override).

    Every config table loads through :func:`simfab.io.tables.load_table`: an unknown table or key is
    refused naming the file, the table and the key; a bad value names the file and ``table.key``, or
    the flag an :class:`simfab.io.tables.Override` carries.

    Args:
        path: the scene TOML, or a mesh file (OBJ/STL/PLY).
        units: units of a mesh file ("m", "cm", "mm"; a scene's ``[target] units`` otherwise).
        overrides: {table: {key: value or Override}} applied over the file's values (``None``: the
            key's default), for the tables of :data:`TABLES`.
        auto: decide the fields neither the file nor ``overrides`` sets (spacing, cuts, insert
            catalogue, layout, tuning) from the target (:func:`simfab.deploy.auto.complete`);
            False: the dataclasses' fixed defaults.
        log: called once with a note for each Override that replaces a value of the file.

    Returns:
        The :class:`SurfaceScene`.
    """
    p = Path(path)
    where = str(p)
    overrides = overrides or {}
    for t in overrides:
        if t not in TABLES:
            raise InputError(f"unknown table [{t}] (known: {', '.join(f'[{k}]' for k in TABLES)})", where="overrides")
    if p.suffix.lower() == ".toml":
        doc = read_toml(p)
        known = ("target", *TABLES)
        for k, v in doc.items():
            if k not in known:
                what = f"table [{k}]" if isinstance(v, dict) else f"key {k!r}"
                raise InputError(f"unknown {what} (known: {', '.join(f'[{t}]' for t in sorted(known))})", where=where)
        target = _target(doc, p, units)
        file = where
    else:
        if not p.is_file():
            raise InputError("file not found", where=where)
        doc, file = {}, None
        target = surface.load(p, units=units or "m")
        surface.check_size(target, units=units or "m", where=where)
    cfg = {t: load_table(cls, doc.get(t), table_name=t, file=file, overrides=overrides.get(t), log=log,
                         keys=_keys(t), parsers=PARSERS.get(t))
           for t, cls in TABLES.items()}
    dep = dataclasses.replace(cfg["deploy"], **{k: getattr(cfg["material"], k) for k in MATERIAL_KEYS})
    scene = SurfaceScene(target=target, pattern=cfg["pattern"], deploy=dep, mujoco=cfg["mujoco"], path=where,
                         tune=cfg["tune"], cuts=cfg["cuts"])
    from simfab.deploy import auto as auto_

    given = {t: {k for k in (*(doc.get(t) or {}), *(overrides.get(t) or {}))
                 if _value(overrides.get(t, {}).get(k, True)) is not None} for t in ("pattern", "cuts", "tune")}
    try:
        if auto:
            scene, decisions = auto_.complete(scene, given)
            scene = dataclasses.replace(scene, decisions=decisions)
        scene.pattern.check_plates()  # (the catalogue final: decided, or as given)
    except InputError as e:  # a check of the decided values (e.g. the cell count) at a flag's key names the flag
        sources = {f"{t}.{k}": v.source for t, ov in overrides.items() for k, v in ov.items()
                   if isinstance(v, Override)}
        if e.where in sources:
            raise InputError(e.message, where=sources[e.where]) from None
        if file is not None and e.where and e.where.startswith(("pattern.", "cuts.", "tune.")):
            raise InputError(e.message, where=f"{file}: {e.where}") from None
        raise
    return scene


def _value(v):
    return v.value if isinstance(v, Override) else v
