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
    [material]   # young [Pa], poisson [-], density [kg/m^3]
    [deploy]     # increments, perturbation, beam_segments, spring_segments
    [mujoco]     # simfab.deploy.mjcf_sim.SimConfig
    [tune]       # simfab.deploy.tuning.TuneConfig (iterations = 0: no tuning)
    [cuts]       # simfab.deploy.cuts.CutsConfig (max_cones = 0: no cuts)

Unknown tables or fields are errors naming the file and the field.
"""

from __future__ import annotations

import dataclasses
import tomllib
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

BUNDLED = ("dome", "saddle", "mixed")
# the steep targets (insert catalogues; cuts with cones on the cap and the petal): bundled names too
BUNDLED_STEEP = ("cap80", "saddle_steep", "petal")
NAMES = BUNDLED + BUNDLED_STEEP


@dataclass(frozen=True)
class SurfaceScene:
    """A loaded scene: target (:class:`simfab.deploy.surface.Target`), pattern / deploy / MuJoCo
    configurations, the file path."""

    target: object
    pattern: object
    deploy: object
    mujoco: object
    path: str
    tune: object = None
    cuts: object = None
    decisions: object = None  # simfab.deploy.auto.Decisions: what the defaults decided from the target


def bundled_path(name: str) -> str:
    """``scenes/deploy/<name>.toml`` of the bundled surface scenes."""
    return str(scenes_dir("deploy", f"{name}.toml"))


def _make(cls, table: dict, where: str, section: str):
    names = {f.name for f in dataclasses.fields(cls)}
    bad = sorted(set(table) - names)
    if bad:
        raise InputError(f"unknown field(s) {', '.join(bad)} (known: {', '.join(sorted(names))})",
                         where=f"{where}: [{section}]")
    try:
        return cls(**table)
    except InputError as e:
        raise InputError(e.message, where=f"{where}: {e.where or section}") from None
    except TypeError as e:
        raise InputError(str(e), where=f"{where}: [{section}]") from None


def load_deploy_scene(path, *, units: str | None = None, overrides: dict | None = None,
                      auto: bool = True) -> SurfaceScene:
    """Read a scene TOML, or a bare mesh file (then all parameters are defaults + ``overrides``).

    ``overrides``: {"pattern": {...}, "material": {...}, "deploy": {...}, "mujoco": {...}, "tune": {...},
    "cuts": {...}}
    (command-line values, applied over the file's). ``auto``: the fields neither sets (spacing,
    cuts, insert catalogue, layout, tuning) decided from the target (:func:`simfab.deploy.auto.complete`;
    False: the dataclasses' fixed defaults)."""

    p = Path(path)
    where = str(p)
    if not p.is_file():
        raise InputError("file not found", where=where)
    overrides = overrides or {}
    if p.suffix.lower() == ".toml":
        try:
            doc = tomllib.loads(p.read_text(encoding="utf-8"))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
            raise InputError(f"not valid TOML: {e}", where=where) from None
        unknown = sorted(set(doc) - {"target", "pattern", "material", "deploy", "mujoco", "tune", "cuts"})
        if unknown:
            raise InputError(f"unknown table(s) {', '.join(unknown)}", where=where)
        tt = dict(doc.get("target", {}))
        if "mesh" in tt:
            mesh = (p.parent / tt.pop("mesh")).resolve()
            u = units or tt.pop("units", "m")
            tt.pop("units", None)
            if tt:
                raise InputError(f"unknown field(s) {', '.join(sorted(tt))} beside 'mesh'", where=f"{where}: [target]")
            target = surface.load(mesh, units=u)
            surface.check_size(target, units=u, where=f"{where}: [target] mesh")
        elif "kind" in tt:
            kind = tt.pop("kind")
            target = surface.procedural(kind, tt, where=f"{where}: [target]")
            surface.check_size(target, units="m", where=f"{where}: [target]")
        else:
            raise InputError("[target] needs 'kind' (procedural) or 'mesh' (file)", where=where)
    else:
        doc = {}
        target = surface.load(p, units=units or "m")
        surface.check_size(target, units=units or "m", where=where)
    tables = {k: {**doc.get(k, {}), **overrides.get(k, {})}
              for k in ("pattern", "material", "deploy", "mujoco", "tune", "cuts")}
    pat = _make(PatternConfig, tables["pattern"], where, "pattern")
    dep = _make(DeployConfig, {**tables["material"], **tables["deploy"]}, where, "material/deploy")
    sim = _make(SimConfig, tables["mujoco"], where, "mujoco")
    tune = _make(TuneConfig, tables["tune"], where, "tune")
    cut = _make(CutsConfig, tables["cuts"], where, "cuts")
    scene = SurfaceScene(target=target, pattern=pat, deploy=dep, mujoco=sim, path=where, tune=tune, cuts=cut)
    if not auto:
        return scene
    from simfab.deploy import auto as auto_

    scene, decisions = auto_.complete(scene, {k: set(tables[k]) for k in ("pattern", "cuts", "tune")})
    return dataclasses.replace(scene, decisions=decisions)
