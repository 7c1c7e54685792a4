"""MuJoCo scenes: loading an MJCF file into a :class:`Scene` (geometry, sites, custom parameters).

Scenes in ``scenes/`` are plain MJCF files: ``python -m mujoco.viewer --mjcf=FILE`` opens them.
simfab reads from them the **geometry** of bodies (:meth:`Scene.body_meshes`, world frame at
``qpos0``), **named sites** (roots, targets, obstacles, fixed regions...: :attr:`Scene.sites`) and
**custom parameters** (``<custom><numeric/><text/>``: :func:`numeric_config`). Every number is
checked finite before MuJoCo compiles the file; MuJoCo's warnings are collected
(:func:`mujoco_warnings`) instead of printed to stdout. Quaternions are (w, x, y, z); lengths in metres.
"""

from __future__ import annotations

import dataclasses
import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from simfab.errors import InputError

__all__ = ["MAX_KEYFRAMES", "Scene", "geom_mesh", "load_mjcf", "load_model", "mujoco_module", "mujoco_warnings",
           "numeric_config", "torus_radii"]


def mujoco_module():
    """The ``mujoco`` module, with simfab's warning handler installed (first call only).

    Returns:
        The module (imported on first use: ``import simfab`` stays light).
    """
    import mujoco

    if not getattr(mujoco, "_simfab_warnings", False):
        # MuJoCo's default warning handler prints to stdout and appends to MUJOCO_LOG.TXT in the
        # working directory; simfab collects the warnings instead (see :func:`mujoco_warnings`)
        # and shows each distinct one once on stderr, as one line.
        mujoco.set_mju_user_warning(_on_warning)
        mujoco._simfab_warnings = True
    return mujoco


_WARNINGS: list[str] = []
_SHOWN: set[str] = set()
_QUIET_LOAD = [False]  # while a model loads, its warnings become part of the error (if any)


def _on_warning(msg: str) -> None:
    import sys

    msg = " ".join(str(msg).split())
    _WARNINGS.append(msg)
    if not _QUIET_LOAD[0] and msg not in _SHOWN:
        _SHOWN.add(msg)
        print(f"simfab: warning: MuJoCo: {msg}", file=sys.stderr)


def mujoco_warnings(clear: bool = True) -> list[str]:
    """MuJoCo warnings since the last call (simfab keeps them off stdout and out of MUJOCO_LOG.TXT).

    Args:
        clear: forget them once returned.

    Returns:
        The warnings, one line each, oldest first.
    """
    out = list(_WARNINGS)
    if clear:
        _WARNINGS.clear()
    return out


_NONFINITE = re.compile(r"(?<![A-Za-z0-9_])[-+]?(nan|inf|infinity)(?![A-Za-z0-9_])", re.IGNORECASE)


#: Most ``<key>`` keyframes an MJCF file may hold: MuJoCo's compiler takes time quadratic in
#: their number (10,000 compile in a fraction of a second, 10^6 would take about half an hour;
#: docs/decisions.md), so a longer path is refused before it compiles; resample it.
MAX_KEYFRAMES = 10_000


def _check_finite_attributes(path: Path) -> None:
    """InputError naming the element and attribute of the first NaN/inf number in an MJCF file,
    or the ``<keyframe>`` section when it holds more than :data:`MAX_KEYFRAMES` keys (one
    streaming pass that stops at the first problem)."""
    n_keys = 0
    try:
        for _, el in ET.iterparse(path, events=("start",)):
            if el.tag == "key":
                n_keys += 1
                if n_keys > MAX_KEYFRAMES:
                    raise InputError(f"<keyframe> holds more than the {MAX_KEYFRAMES} keys simfab reads (MuJoCo "
                                     "compiles keyframes in time quadratic in their number); resample the path "
                                     "to fewer keys (a straight stretch needs only its two ends)", where=str(path))
            for k, v in el.attrib.items():
                if k in _NON_NUMERIC_ATTRIBUTES:
                    continue
                if _NONFINITE.search(v):
                    who = f"<{el.tag}{' name=' + repr(el.get('name')) if el.get('name') else ''}>"
                    raise InputError(f"{who} attribute {k}={v!r} is not a finite number", where=str(path))
    except ET.ParseError as e:
        raise InputError(f"not well-formed XML: {e}", where=str(path)) from None


_NON_NUMERIC_ATTRIBUTES = frozenset(("name", "file", "class", "childclass", "mesh", "material", "texture", "body",
                                     "body1", "body2", "joint", "site", "target", "model", "content_type"))


@dataclasses.dataclass(frozen=True)
class Scene:
    """A loaded MJCF scene.

    Args:
        path: the MJCF file.
        model: ``mujoco.MjModel``.
        sites: site name -> (3,) world position [m] at ``qpos0`` (mocap bodies at their body pos).
        site_size: site name -> (3,) MuJoCo site size [m] (sphere radius is ``size[0]``).
        site_axes: site name -> (3, 3) its frame's axes in the world (columns) at ``qpos0``.
        custom_numeric: ``<numeric name data>`` name -> (k,) float array.
        custom_text: ``<text name data>`` name -> str.
        sdf_plugins: plugin instance id -> (plugin name, config dict of strings), e.g. the
            ``mujoco.sdf.torus`` instance of an SDF geom (empty without plugins).
    """

    path: Path
    model: object
    sites: dict
    site_size: dict
    custom_numeric: dict
    custom_text: dict
    sdf_plugins: dict = dataclasses.field(default_factory=dict)
    site_axes: dict = dataclasses.field(default_factory=dict)

    def in_box(self, name: str, points: np.ndarray) -> np.ndarray:
        """Which points lie in the box site ``name``: within its half extents (``size``) along its own axes
        (a site turned by its ``quat`` or its body is a turned box).

        Args:
            name: the site's name.
            points: (k, dim) world points [m]; with dim 2 the box's section with the plane z = 0 (a box
                turned about z only), with dim 3 a zero z size is unbounded in its z.

        Returns:
            (k,) bool.
        """
        half = np.asarray(self.site_size[name], dtype=np.float64)
        if half[2] == 0:
            half = np.r_[half[:2], np.inf]
        return points_in_box(points, self.sites[name], half, self.site_axes.get(name, np.eye(3)))

    def body_names(self) -> list[str]:
        """The model's body names (``body<i>`` for an unnamed body).

        Returns:
            One name per body, in MuJoCo's order (world first).
        """
        mj = mujoco_module()
        return [mj.mj_id2name(self.model, mj.mjtObj.mjOBJ_BODY, i) or f"body{i}" for i in range(self.model.nbody)]

    def body_meshes(self, *, include_world: bool = True) -> dict:
        """Triangle meshes of all visible geoms per body, world frame at ``qpos0``.

        Planes are skipped (infinite); primitives are meshed (spheres subdivided twice, cylinders with
        48 sides). Bodies without meshable geoms are absent.

        Args:
            include_world: include the world body's geoms.

        Returns:
            body name -> ``trimesh.Trimesh`` (geoms of one body concatenated).
        """
        import trimesh

        mj = mujoco_module()
        m = self.model
        d = mj.MjData(m)
        mj.mj_forward(m, d)
        names = self.body_names()
        parts: dict[str, list] = {}
        for g in range(m.ngeom):
            b = int(m.geom_bodyid[g])
            if b == 0 and not include_world:
                continue
            mesh = geom_mesh(m, g, self.sdf_plugins)
            if mesh is None:
                continue
            T = np.eye(4)
            T[:3, :3] = d.geom_xmat[g].reshape(3, 3)
            T[:3, 3] = d.geom_xpos[g]
            mesh.apply_transform(T)
            parts.setdefault(names[b], []).append(mesh)
        return {k: trimesh.util.concatenate(v) if len(v) > 1 else v[0] for k, v in parts.items()}


def geom_mesh(model, g: int, plugins: dict | None = None):
    """Mesh of a geom in its own frame.

    SDF geoms: a torus (``mujoco.sdf.torus`` in ``plugins``) is meshed with 128 x 32 sections, others
    use the mesh MuJoCo extracts from their distance field.

    Args:
        model: ``mujoco.MjModel``.
        g: the geom's index.
        plugins: :attr:`Scene.sdf_plugins`.

    Returns:
        ``trimesh.Trimesh``, or None for planes and heightfields.
    """
    import trimesh

    mj = mujoco_module()
    t = int(model.geom_type[g])
    s = np.asarray(model.geom_size[g], dtype=np.float64)
    G = mj.mjtGeom
    if t == int(G.mjGEOM_SPHERE):
        return trimesh.creation.icosphere(subdivisions=2, radius=s[0])
    if t == int(G.mjGEOM_ELLIPSOID):
        m = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
        m.apply_scale(s)
        return m
    if t == int(G.mjGEOM_BOX):
        return trimesh.creation.box(extents=2 * s)
    if t == int(G.mjGEOM_CYLINDER):
        return trimesh.creation.cylinder(radius=s[0], height=2 * s[1], sections=48)
    if t == int(G.mjGEOM_CAPSULE):
        return trimesh.creation.capsule(height=2 * s[1], radius=s[0], count=[24, 24])
    torus = torus_radii(model, g, plugins)
    if torus is not None:
        return trimesh.creation.torus(major_radius=torus[0], minor_radius=torus[1], major_sections=128,
                                      minor_sections=32)
    if t in (int(G.mjGEOM_MESH), int(G.mjGEOM_SDF)) and int(model.geom_dataid[g]) >= 0:
        mid = int(model.geom_dataid[g])
        va, vn = int(model.mesh_vertadr[mid]), int(model.mesh_vertnum[mid])
        fa, fn = int(model.mesh_faceadr[mid]), int(model.mesh_facenum[mid])
        V = np.asarray(model.mesh_vert[va:va + vn], dtype=np.float64)
        F = np.asarray(model.mesh_face[fa:fa + fn], dtype=np.int64)
        return trimesh.Trimesh(V, F, process=False)
    return None


#: MuJoCo SDF plugin read as an exact torus (config radius1: major radius, radius2: tube radius [m];
#: simfab.contact.sdf).
TORUS_PLUGIN = "mujoco.sdf.torus"


def torus_radii(model, g: int, plugins: dict | None) -> tuple | None:
    """The radii of a torus geom of the ``mujoco.sdf.torus`` plugin.

    Args:
        model: ``mujoco.MjModel``.
        g: the geom's index.
        plugins: instance id -> (plugin name, config), :attr:`Scene.sdf_plugins`.

    Returns:
        (major, tube) radii [m], or None when the geom is not such a torus.
    """
    if int(model.geom_type[g]) != int(mujoco_module().mjtGeom.mjGEOM_SDF) or not plugins:
        return None
    name, config = plugins.get(int(model.geom_plugin[g]), (None, {}))
    if name != TORUS_PLUGIN:
        return None
    return float(config["radius1"]), float(config["radius2"])


def load_model(path: str | os.PathLike):
    """``mujoco.MjModel`` from an MJCF file, its numbers checked finite first.

    Args:
        path: the MJCF file.

    Returns:
        The compiled model; InputError (one line naming the file) when missing or invalid.
    """
    mj = mujoco_module()
    path = Path(path)
    if not path.is_file():
        raise InputError("file not found", where=str(path))
    _check_finite_attributes(path)
    _QUIET_LOAD[0] = True
    try:
        return mj.MjModel.from_xml_path(str(path))
    except ValueError as e:
        mujoco_warnings()
        raise InputError(f"MuJoCo cannot load this MJCF: {' '.join(str(e).split())}", where=str(path)) from None
    finally:
        _QUIET_LOAD[0] = False


def points_in_box(points: np.ndarray, centre: np.ndarray, half: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """Which points lie in a box: within ``half`` (3,) [m] of ``centre`` (3,) [m] along its ``axes`` (3, 3)
    (columns, in the world); 2D points (k, 2) against the box's section with the plane z = 0.

    Returns:
        (k,) bool.
    """
    pts = np.asarray(points, dtype=np.float64)
    dim = pts.shape[1]
    q = (pts - np.asarray(centre)[:dim]) @ np.asarray(axes)[:dim, :dim]  # (the points in the box's frame)
    return np.all(np.abs(q) <= np.asarray(half)[:dim] + 1e-12, axis=1)


def load_mjcf(path: str | os.PathLike) -> Scene:
    """Load an MJCF scene with its sites and custom parameters.

    Args:
        path: the MJCF file.

    Returns:
        The :class:`Scene`; InputError naming the file when it is missing or invalid.
    """
    mj = mujoco_module()
    path = Path(path)
    model = load_model(path)
    data = mj.MjData(model)
    mj.mj_forward(model, data)
    sites, sizes, axes = {}, {}, {}
    for i in range(model.nsite):
        name = mj.mj_id2name(model, mj.mjtObj.mjOBJ_SITE, i)
        if name:
            sites[name] = np.array(data.site_xpos[i], dtype=np.float64)
            sizes[name] = np.array(model.site_size[i], dtype=np.float64)
            axes[name] = np.array(data.site_xmat[i], dtype=np.float64).reshape(3, 3)
    numeric = {}
    for i in range(model.nnumeric):
        name = mj.mj_id2name(model, mj.mjtObj.mjOBJ_NUMERIC, i)
        a, n = int(model.numeric_adr[i]), int(model.numeric_size[i])
        numeric[name] = np.array(model.numeric_data[a:a + n], dtype=np.float64)
    text = {}
    for i in range(model.ntext):
        name = mj.mj_id2name(model, mj.mjtObj.mjOBJ_TEXT, i)
        a, n = int(model.text_adr[i]), int(model.text_size[i])
        text[name] = bytes(model.text_data[a:a + n]).split(b"\0", 1)[0].decode()
    return Scene(path=path, model=model, sites=sites, site_size=sizes, custom_numeric=numeric, custom_text=text,
                 sdf_plugins=_plugin_configs(path, model), site_axes=axes)


def _plugin_configs(path: Path, model) -> dict:
    """Plugin instance id -> (plugin name, config) of the model's plugin instances (the compiled
    model keeps neither; read from the MJCF's spec)."""
    if model.nplugin == 0:
        return {}
    mj = mujoco_module()
    ids = {mj.mj_id2name(model, mj.mjtObj.mjOBJ_PLUGIN, i): i for i in range(model.nplugin)}
    spec = mj.MjSpec.from_file(str(path))
    return {ids[p.name]: (p.plugin_name, dict(p.config)) for p in spec.plugins if p.name in ids}


def numeric_config(scene: Scene, prefix: str, config_type):
    """Keyword arguments for a dataclass from ``<numeric name="<prefix><field>">`` elements.

    Every field holds exactly one finite number, a whole number for an ``int`` field (a count);
    anything else, and a ``<prefix>...`` name that is not a field (a typo must not silently fall
    back to a default), is an InputError naming the file and the ``<numeric>``. Ranges are the
    dataclass's to check.

    Args:
        scene: the loaded scene.
        prefix: the name prefix of the parameters (e.g. ``"cell_"``).
        config_type: the dataclass.

    Returns:
        {field: value} of the fields given.
    """
    import dataclasses

    fields = {f.name: f for f in dataclasses.fields(config_type)}
    kw = {}
    for key, data in scene.custom_numeric.items():
        if not key.startswith(prefix):
            continue
        f = fields.get(key[len(prefix):])
        where = f"{scene.path}: <numeric name={key!r}>"
        if f is None:
            known = ", ".join(prefix + n for n in sorted(fields))
            raise InputError(f"unknown parameter <numeric name={key!r}> (known: {known})", where=str(scene.path))
        data = np.asarray(data, dtype=np.float64).reshape(-1)
        if data.size != 1:
            raise InputError(f"data must be one number, got {data.size} ({' '.join(f'{x:g}' for x in data[:8])}"
                             f"{' ...' if data.size > 8 else ''})", where=where)
        v = float(data[0])
        if not np.isfinite(v):
            raise InputError(f"data must be a finite number, got {v}", where=where)
        if f.type in (int, "int"):
            if not v.is_integer():
                raise InputError(f"data must be a whole number (a count), got {v:g}", where=where)
            kw[f.name] = int(v)
        else:
            kw[f.name] = v
    return kw

