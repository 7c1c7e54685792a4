"""Growth scenes: an MJCF file (objects, root/target/obstacle sites) plus a companion TOML.

Scene format
------------
``scenes/growth/NAME.xml`` is a plain MJCF file that MuJoCo loads (open it with
``python -m mujoco.viewer --mjcf=NAME.xml``):

- **objects** are the geoms of the bodies (meshes or primitives: box, sphere, ellipsoid,
  cylinder, capsule; planes are ignored). Each body is one object, named after the body
  (geoms directly in ``<worldbody>`` form the object ``world``). The structure must not
  intersect them; the skin is carved by them.
- **roots** are sites named ``root_*``: growth starts there.
- **targets** are sites named ``target_*``: the structure must touch them.
- **obstacles** are sphere sites named ``obstacle_*`` (radius = ``size[0]``): growth avoids them.

Parameters are in ``NAME.toml`` next to the XML (optional; see :mod:`simfab.growth.config`
for every key). All lengths are metres.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np

import simfab.growth.tolerances as tol
from simfab._bundled import scenes_dir
from simfab.errors import InputError
from simfab.growth.config import GrowthSceneConfig, StructureConfig, params_from_toml, structure_from_toml
from simfab.io.mjcf import load_mjcf
from simfab.io.tables import read_toml


@dataclasses.dataclass(frozen=True, kw_only=True)
class GrowthScene:
    """Geometry and parameters of one growth problem (world frame, metres).

    Args:
        objects: body name -> ``trimesh.Trimesh`` (world frame).
        roots: (k, 3) root points [m]; root_names: k names.
        targets: (t, 3) target points [m]; target_names: t names.
        sphere_centers, sphere_radii: (s, 3) centres and (s,) radii of the obstacle spheres [m];
            sphere_names: s names.
        params: growth parameters (:class:`simfab.growth.config.GrowthSceneConfig`).
        path: the MJCF file (None when built in Python).
        structure: material and extra loads of the structural check ([material], [loads]).
        notes: what :meth:`with_params` overrode of the scene file (``--kill 0.003 overrides P.toml [growth]
            kill = 0.004``), for the caller to log once the run is under way.
    """

    objects: dict
    roots: np.ndarray
    root_names: tuple
    targets: np.ndarray
    target_names: tuple
    sphere_centers: np.ndarray
    sphere_radii: np.ndarray
    sphere_names: tuple = ()
    params: GrowthSceneConfig = dataclasses.field(default_factory=GrowthSceneConfig)
    path: Path | None = None
    structure: StructureConfig = dataclasses.field(default_factory=StructureConfig)
    notes: tuple = ()

    def __post_init__(self):
        object.__setattr__(self, "roots", np.asarray(self.roots, dtype=np.float64).reshape(-1, 3))
        object.__setattr__(self, "targets", np.asarray(self.targets, dtype=np.float64).reshape(-1, 3))
        object.__setattr__(self, "sphere_centers", np.asarray(self.sphere_centers, dtype=np.float64).reshape(-1, 3))
        object.__setattr__(self, "sphere_radii", np.asarray(self.sphere_radii, dtype=np.float64).reshape(-1))
        if not self.root_names:
            object.__setattr__(self, "root_names", tuple(f"root_{i}" for i in range(len(self.roots))))
        if not self.target_names:
            object.__setattr__(self, "target_names", tuple(f"target_{i}" for i in range(len(self.targets))))
        if not self.sphere_names:
            object.__setattr__(self, "sphere_names", tuple(f"obstacle_{i}" for i in range(len(self.sphere_radii))))

    @property
    def name(self) -> str:
        return self.path.stem if self.path is not None else "scene"

    def objects_bbox(self) -> np.ndarray:
        """Bounding box of all objects (and roots/targets).

        Returns:
            A (2, 3) array, min and max corner [m].
        """
        pts = [m.bounds for m in self.objects.values()] + [self.roots, self.targets]
        pts = np.concatenate([np.asarray(p).reshape(-1, 3) for p in pts if len(p)])
        return np.array([pts.min(axis=0), pts.max(axis=0)])

    def with_params(self, **overrides) -> "GrowthScene":
        """Copy with some growth parameters replaced, checked by :meth:`GrowthSceneConfig.replace`.

        Args:
            **overrides: flat parameter names (``kill``, ``attractors``, ``radius_decay``, ...) ->
                value or :class:`simfab.io.tables.Override` (an error then names its flag);
                ``None`` values are ignored.

        Returns:
            The scene; InputError naming the flag, or the companion TOML's table and key.
        """
        kw = {k: v for k, v in overrides.items() if v is not None and getattr(v, "value", 0) is not None}
        toml = self.path.with_suffix(".toml") if self.path is not None else None
        notes: list[str] = []
        params = self.params.replace(file=str(toml) if toml is not None and toml.is_file() else None,
                                     log=notes.append, **kw)
        return dataclasses.replace(self, params=params, notes=self.notes + tuple(notes))


def load_growth_scene(path: str | os.PathLike) -> GrowthScene:
    """Read a growth scene: its MJCF and its companion ``.toml``.

    Args:
        path: the MJCF file, or the name of a bundled scene such as ``"phone_stand"``.

    Returns:
        The :class:`GrowthScene`.

    Raises:
        InputError: anything unusable, naming the file and the field.
    """

    path = Path(path)
    bundled = scenes_dir("growth", f"{path.name}.xml")
    if not path.suffix and not path.exists() and bundled.is_file():  # a bundled name, as the other areas take
        path = bundled
    if path.suffix.lower() != ".xml":
        raise InputError("a growth scene is an MJCF .xml file", where=str(path))
    sc = load_mjcf(path)
    toml_path = path.with_suffix(".toml")
    params = GrowthSceneConfig()
    structure = StructureConfig()
    if toml_path.is_file():
        doc = read_toml(toml_path)
        params = params_from_toml(doc, str(toml_path))
        structure = structure_from_toml(doc, str(toml_path))

    def sites(prefix):
        names = sorted((n for n in sc.sites if n.startswith(prefix)), key=_natural_key)
        return tuple(names), np.array([sc.sites[n] for n in names]).reshape(-1, 3)

    root_names, roots = sites("root_")
    target_names, targets = sites("target_")
    sphere_names, centers = sites("obstacle_")
    radii = np.array([sc.site_size[n][0] for n in sphere_names], dtype=np.float64)
    objects = {k: v for k, v in sc.body_meshes().items() if len(v.faces)}
    scene = GrowthScene(objects=objects, roots=roots, root_names=root_names, targets=targets,
                        target_names=target_names, sphere_centers=centers, sphere_radii=radii,
                        sphere_names=sphere_names, params=params, path=path, structure=structure)
    unknown = [n for n, _ in structure.loads if n not in target_names]
    if unknown:
        raise InputError(f"unknown target site(s) {', '.join(unknown)} (targets: {', '.join(target_names)})",
                         where=f"{toml_path}: [loads]")
    validate_scene(scene)
    return scene


def _natural_key(name: str):
    import re

    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", name)]


def validate_scene(scene: GrowthScene) -> None:
    """Check that the problem is well posed; InputError names the first problem found."""
    where = str(scene.path) if scene.path else "scene"
    p = scene.params
    if len(scene.roots) == 0:
        raise InputError("no root sites (name them root_0, root_1, ...)", where=where)
    if p.mode in ("volume", "profile") and len(scene.targets) == 0:
        raise InputError(f"mode {p.mode!r} needs target sites (target_0, ...)", where=where)
    if p.mode == "surface" and not scene.objects:
        raise InputError("surface mode needs objects to sample attractors on", where=where)
    if p.mode == "profile" and p.profile is None:
        raise InputError("mode 'profile' needs a [profile] table in the TOML", where=where)
    if p.surface_objects:
        missing = [n for n in p.surface_objects if n not in scene.objects]
        if missing:
            raise InputError(f"surface_objects names unknown bodies {missing} (bodies: {sorted(scene.objects)})",
                             where=where)
    if p.stages:
        named = set(scene.target_names)
        for i, st in enumerate(p.stages.targets):
            bad = [n for n in st if n not in named]
            if bad:
                raise InputError(f"stage {i} names unknown target sites {bad}", where=where)
    if np.any(scene.sphere_radii <= 0):
        raise InputError("obstacle spheres need a positive radius (site size)", where=where)
    for name, r in zip(scene.root_names, scene.roots):
        d = np.linalg.norm(scene.sphere_centers - r, axis=1) - scene.sphere_radii
        if np.any(d < 0):
            raise InputError(f"root {name} lies inside an obstacle sphere", where=where)
    for name, m in scene.objects.items():
        if m.is_watertight and len(scene.roots):
            inside = m.contains(scene.roots)
            # points on the surface may test either way: only reject roots deeper than the
            # ground-contact band (the same band that makes an object a root's ground)
            if np.any(inside):
                dist = np.abs(_surface_distance(m, scene.roots[inside]))
                if np.any(dist > tol.GROUND_CONTACT * float(np.linalg.norm(m.extents))):
                    raise InputError(f"a root lies inside object {name!r}", where=where)


def _surface_distance(mesh, points) -> np.ndarray:
    _, d, _ = mesh.nearest.on_surface(points)
    return d
