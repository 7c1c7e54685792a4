"""Growth scenes from a user's own meshes (``simfab grow new``): no hand-written MJCF.

:func:`new_scene` takes the objects to support as mesh files (one body each, named after the file),
the root points growth starts from and the target points the support must touch, and writes
``NAME.xml`` (the bodies as mesh geoms with their masses, sites ``root_*`` / ``target_*``, a
plate under the roots unless one of the objects is the ground) and ``NAME.toml`` that
``simfab grow`` and ``simfab grow --check`` run. Targets are snapped onto the nearest object's
surface (the notes say by how much); an object given no mass is loaded with MuJoCo's default
density (1000 kg/m^3) times its volume, and the notes say so with the mass that gives.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simfab.errors import InputError
from simfab.results import Result, field

__all__ = ["GrowthAuthorConfig", "AuthoredGrowthScene", "new_scene"]

#: MuJoCo's default geom density [kg/m^3]: the load of a body given no mass.
MUJOCO_DEFAULT_DENSITY = 1000.0
#: A target farther than this fraction of its object's diagonal from the surface is refused.
SNAP_MAX_REL = 0.1
#: Plate: thickness and margin around everything, relative to the scene's diagonal.
PLATE_THICKNESS_REL = 0.03
PLATE_MARGIN_REL = 0.2


@dataclass(frozen=True, kw_only=True)
class GrowthAuthorConfig:
    """What ``simfab grow new`` is asked for (points in ``units``).

    Attributes:
        objects: mesh files of the objects to support (STL / OBJ / PLY, watertight), one common frame.
        roots: points ``X,Y,Z`` growth starts from (on the plate, or on an object used as the ground).
        targets: points ``X,Y,Z`` the support must touch (snapped onto the nearest object's surface).
        masses: the objects' masses [kg], one per object or one for all; empty: MuJoCo's default density.
        name: the scene's name; None: the first object's stem.
        units: "mm" or "m".
        plate: add a plate whose top is at the lowest root (the objects are then all loads).
    """

    objects: tuple
    roots: tuple
    targets: tuple
    masses: tuple = ()
    name: str | None = None
    units: str = "mm"
    plate: bool = True


@dataclass(frozen=True, kw_only=True)
class AuthoredGrowthScene(Result):
    """The scene ``simfab grow new`` wrote.

    Args:
        scene: the MJCF scene's path.
        masses: object -> mass used [kg].
        targets: the target points, snapped onto the objects [m].
        notes: one line each (what was assumed or adjusted).
        next_commands: the commands to run next (grow, check).
        outputs: label -> path of the files written.
    """

    scene: str = field(default="")
    masses: dict = field(unit="kg", default_factory=dict)
    targets: list = field(unit="m", default_factory=list)
    notes: list = field(default_factory=list)
    next_commands: list = field(default_factory=list)


def parse_point(text: str, where: str, scale: float) -> np.ndarray:
    """``X,Y,Z`` [units] -> (3,) [m]; InputError naming ``where`` otherwise."""
    try:
        p = np.array([float(v) for v in str(text).split(",")]) * scale
    except ValueError:
        p = np.zeros(0)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise InputError(f"must be a point X,Y,Z, got {text!r}", where=where)
    return p


def new_scene(spec: GrowthAuthorConfig, out) -> AuthoredGrowthScene:
    """Write a growth scene for the user's objects, roots and targets (module docstring).

    Args:
        spec: the request (:class:`GrowthAuthorConfig`).
        out: the folder the scene's files are written to (created).

    Returns:
        An :class:`AuthoredGrowthScene`: files written, masses used, snapped targets, notes, next command.

    Raises:
        InputError: a missing or unreadable mesh, a bad point, a target far from every object, a
            scene the growth loader rejects (nothing is left written then).
    """
    from simfab.io.atomic import write_text
    from simfab.io.mesh import load_mesh
    from simfab.io.mjcf import MJCFBuilder
    from simfab.io.outpaths import name_from_stem

    if spec.units not in ("mm", "m"):
        raise InputError(f"must be mm or m, got {spec.units!r}", where="--units")
    scale = 1e-3 if spec.units == "mm" else 1.0
    if not spec.objects:
        raise InputError("give at least one object mesh", where="OBJECT")
    if not spec.roots:
        raise InputError("give at least one root point", where="--root")
    if not spec.targets:
        raise InputError("give at least one target point", where="--target")
    meshes = {}
    for f in spec.objects:
        stem = name_from_stem(f)
        if stem in meshes or stem in ("plate", "world"):
            stem = f"{stem}_{len(meshes)}"
        meshes[stem] = load_mesh(f, units=spec.units, require_watertight=True)
    masses = list(spec.masses)
    if len(masses) == 1:
        masses = masses * len(meshes)
    if masses and len(masses) != len(meshes):
        raise InputError(f"give one mass per object ({len(meshes)}) or one for all, got {len(masses)}", where="--mass")
    if any(not (m > 0 and np.isfinite(m)) for m in masses):
        raise InputError(f"masses must be positive [kg], got {masses}", where="--mass")
    roots = np.array([parse_point(r, "--root", scale) for r in spec.roots])
    notes: list[str] = []
    targets = []
    for i, t in enumerate(spec.targets):
        p = parse_point(t, "--target", scale)
        best = None
        for name, m in meshes.items():
            q, d, _ = m.nearest.on_surface(p[None])
            if best is None or d[0] < best[2]:
                best = (name, q[0], float(d[0]))
        name, q, d = best
        if d > SNAP_MAX_REL * float(np.linalg.norm(meshes[name].extents)):
            raise InputError(f"target {t} lies {d / scale:.3g} {spec.units} from the nearest object ({name}); "
                             "targets are points on the supported objects' surfaces", where="--target")
        if d > 1e-9:
            notes.append(f"target_{i} snapped {d / scale:.3g} {spec.units} onto {name}'s surface")
        targets.append(q)
    name = spec.name or next(iter(meshes))
    b = MJCFBuilder(name)
    used = {}
    for k, (oname, m) in enumerate(meshes.items()):
        b.mesh_asset(oname, m.vertices, m.faces)
        body = b.body(oname)
        if masses:
            b.geom(body, type="mesh", mesh=oname, mass=float(masses[k]), rgba=[0.2, 0.2, 0.25, 1])
            used[oname] = float(masses[k])
        else:
            b.geom(body, type="mesh", mesh=oname, rgba=[0.2, 0.2, 0.25, 1])
            used[oname] = MUJOCO_DEFAULT_DENSITY * float(abs(m.volume))
            notes.append(f"{oname}: no --mass, so its load is MuJoCo's default density 1000 kg/m^3 x its volume: "
                         f"{used[oname]:.4g} kg (give --mass KG for the real weight)")
    if spec.plate:
        pts = np.vstack([np.vstack([m.bounds for m in meshes.values()]), roots])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        diag = float(np.linalg.norm(hi - lo))
        zt = float(roots[:, 2].min())
        th = PLATE_THICKNESS_REL * diag
        half_xy = 0.5 * (hi[:2] - lo[:2]) + PLATE_MARGIN_REL * diag
        plate = b.body("plate")
        b.geom(plate, type="box", size=[half_xy[0], half_xy[1], 0.5 * th],
               pos=[0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), zt - 0.5 * th], rgba=[0.55, 0.4, 0.3, 1])
    for i, r in enumerate(roots):
        b.site(b.worldbody, f"root_{i}", pos=r, size=0.003, rgba=[0.9, 0.2, 0.2, 1])
    for i, t in enumerate(targets):
        b.site(b.worldbody, f"target_{i}", pos=t, size=0.003, rgba=[0.2, 0.3, 0.9, 1])
    b.compile()
    toml = (f"# {name}: written by simfab grow new from {', '.join(Path(f).name for f in spec.objects)} "
            f"({spec.units}).\n# Every key: the growth user guide's scene reference.\n\n[growth]\nmode = \"volume\"\n")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    xml = b.save(out / f"{name}.xml")
    tml = write_text(out / f"{name}.toml", toml)
    try:
        from simfab.growth.scene import load_growth_scene

        load_growth_scene(xml)
    except InputError:
        xml.unlink(missing_ok=True)
        tml.unlink(missing_ok=True)
        raise
    return AuthoredGrowthScene(outputs={"scene_xml": str(xml), "scene_toml": str(tml)}, scene=name, masses=used,
                               targets=[[float(v) for v in t] for t in targets], notes=notes,
                               next_commands=[f"simfab grow {xml}", f"simfab grow {xml} --check"])
