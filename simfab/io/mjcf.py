"""MuJoCo scenes: loading MJCF, keyframe trajectories, and generating MJCF from Python.

Scenes in ``scenes/`` are plain MJCF files: ``python -m mujoco.viewer --mjcf=FILE`` opens
them. simfab reads from them

- the **geometry** of bodies (:meth:`Scene.body_meshes`, world frame at ``qpos0``),
- **named sites** (roots, targets, obstacles, fixed regions...): :attr:`Scene.sites`,
- **custom parameters** (``<custom><numeric/><text/>``),
- **trajectories**: a mocap body plus keyframes ``<key mpos=".." mquat=".."/>``; the
  object's pose along the path is :class:`Trajectory`.

Quaternions are (w, x, y, z) as in MuJoCo; lengths in metres.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from simfab.errors import InputError
from simfab.io.atomic import atomic_path
from simfab.rotations import quat_slerp, quat_to_matrix


def _mujoco():
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
    """MuJoCo warnings since the last call (simfab keeps them off stdout and out of MUJOCO_LOG.TXT)."""
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


# --------------------------------------------------------------------------- loading
@dataclasses.dataclass(frozen=True)
class Scene:
    """A loaded MJCF scene.

    Attributes
    ----------
    path : the MJCF file.
    model : ``mujoco.MjModel``.
    sites : site name -> (3,) world position [m] at ``qpos0`` (mocap bodies at their body pos).
    site_size : site name -> (3,) MuJoCo site size [m] (sphere radius is ``size[0]``).
    custom_numeric : ``<numeric name data>`` name -> (k,) float array.
    custom_text : ``<text name data>`` name -> str.
    sdf_plugins : plugin instance id -> (plugin name, config dict of strings), e.g. the
        ``mujoco.sdf.torus`` instance of an SDF geom (empty without plugins).
    """

    path: Path
    model: object
    sites: dict
    site_size: dict
    custom_numeric: dict
    custom_text: dict
    sdf_plugins: dict = dataclasses.field(default_factory=dict)

    def body_names(self) -> list[str]:
        mj = _mujoco()
        return [mj.mj_id2name(self.model, mj.mjtObj.mjOBJ_BODY, i) or f"body{i}" for i in range(self.model.nbody)]

    def body_meshes(self, *, include_world: bool = True) -> dict:
        """Triangle meshes of all visible geoms per body, world frame at ``qpos0``.

        Returns body name -> ``trimesh.Trimesh`` (geoms of one body concatenated). Planes are
        skipped (infinite); primitives are meshed (spheres subdivided twice, cylinders with 48
        sides). Bodies without meshable geoms are absent.
        """
        import trimesh

        mj = _mujoco()
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
    """Mesh of geom ``g`` in its own frame (``trimesh.Trimesh``), or None for planes/heightfields.
    SDF geoms: a torus (``mujoco.sdf.torus`` in ``plugins``, :attr:`Scene.sdf_plugins`) is meshed
    with 128 x 32 sections, others use the mesh MuJoCo extracts from their distance field."""
    import trimesh

    mj = _mujoco()
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
    """(major, tube) radii [m] of geom ``g`` when it is an SDF geom of the ``mujoco.sdf.torus``
    plugin (``plugins``: instance id -> (plugin name, config), :attr:`Scene.sdf_plugins`),
    else None."""
    if int(model.geom_type[g]) != int(_mujoco().mjtGeom.mjGEOM_SDF) or not plugins:
        return None
    name, config = plugins.get(int(model.geom_plugin[g]), (None, {}))
    if name != TORUS_PLUGIN:
        return None
    return float(config["radius1"]), float(config["radius2"])


def load_model(path: str | os.PathLike):
    """``mujoco.MjModel`` from an MJCF file; InputError (one line) when missing or invalid."""
    mj = _mujoco()
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


def load_scene(path: str | os.PathLike) -> Scene:
    """Load an MJCF scene with its sites and custom parameters (see :class:`Scene`)."""
    mj = _mujoco()
    path = Path(path)
    model = load_model(path)
    data = mj.MjData(model)
    mj.mj_forward(model, data)
    sites, sizes = {}, {}
    for i in range(model.nsite):
        name = mj.mj_id2name(model, mj.mjtObj.mjOBJ_SITE, i)
        if name:
            sites[name] = np.array(data.site_xpos[i], dtype=np.float64)
            sizes[name] = np.array(model.site_size[i], dtype=np.float64)
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
                 sdf_plugins=_plugin_configs(path, model))


def _plugin_configs(path: Path, model) -> dict:
    """Plugin instance id -> (plugin name, config) of the model's plugin instances (the compiled
    model keeps neither; read from the MJCF's spec)."""
    if model.nplugin == 0:
        return {}
    mj = _mujoco()
    ids = {mj.mj_id2name(model, mj.mjtObj.mjOBJ_PLUGIN, i): i for i in range(model.nplugin)}
    spec = mj.MjSpec.from_file(str(path))
    return {ids[p.name]: (p.plugin_name, dict(p.config)) for p in spec.plugins if p.name in ids}


def numeric_config(scene: Scene, prefix: str, config_type):
    """Keyword arguments for dataclass ``config_type`` from ``<numeric name="<prefix><field>">``.

    Every field holds exactly one finite number, a whole number for an ``int`` field (a count);
    anything else, and a ``<prefix>...`` name that is not a field (a typo must not silently fall
    back to a default), is an InputError naming the file and the ``<numeric>``. Ranges are the
    dataclass's to check. Returns a dict of the fields given.
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


# --------------------------------------------------------------------------- trajectories
@dataclasses.dataclass(frozen=True)
class Trajectory:
    """Piecewise path through keyframe poses, parameterized by path length.

    Between keyframes the position is linear and the orientation is slerped with the same
    parameter. The length of a segment is ``sqrt(|Δp|² + (ρ θ)²)`` where θ is the rotation
    angle and ρ = ``rot_length_scale`` [m/rad] (the object's bounding radius when built from a
    scene): a pure rotation advances the path by the distance its farthest point travels,
    and a pure translation by its length, so that insertion steps of size h make sense for
    both.

    Attributes
    ----------
    positions : (k, 3) keyframe positions [m].
    quats : (k, 4) keyframe orientations (w, x, y, z).
    rot_length_scale : ρ [m/rad].
    """

    positions: np.ndarray
    quats: np.ndarray
    rot_length_scale: float = 0.0

    def __post_init__(self):
        p = np.asarray(self.positions, dtype=np.float64)
        q = np.asarray(self.quats, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 3 or len(p) < 2 or q.shape != (len(p), 4):
            raise InputError("a trajectory needs at least 2 keyframes with mpos (3) and mquat (4)")
        bad = np.flatnonzero(~np.all(np.isfinite(p), axis=1))
        if bad.size:
            raise InputError(f"keyframe {bad[0]}: position {tuple(p[bad[0]].tolist())} is not finite", where="mpos")
        with np.errstate(all="ignore"):
            norm = np.linalg.norm(q, axis=1)
        bad = np.flatnonzero(~(np.isfinite(norm) & (norm > 0)))
        if bad.size:  # checked before normalizing: q / |q| of a zero quaternion is NaN
            raise InputError(f"keyframe {bad[0]}: quaternion {tuple(q[bad[0]].tolist())} is zero or not finite "
                             "(an orientation is a non-zero (w, x, y, z))", where="mquat")
        if not (np.isfinite(self.rot_length_scale) and self.rot_length_scale >= 0):
            raise InputError(f"must be a finite length >= 0 [m/rad], got {self.rot_length_scale}",
                             where="rot_length_scale")
        object.__setattr__(self, "positions", p)
        object.__setattr__(self, "quats", q / norm[:, None])

    @functools.cached_property
    def segment_lengths(self) -> np.ndarray:
        """(k-1,) path length of each keyframe segment [m] (computed once: the path is immutable).

        O(k) and vectorized: the rotation angle of each segment is :func:`quat_angle`'s
        2 arccos(min(|q_i . q_(i+1)|, 1)) over all segments at once."""
        dp = np.linalg.norm(np.diff(self.positions, axis=0), axis=1)
        q = self.quats
        qa = q[:-1] / np.linalg.norm(q[:-1], axis=1, keepdims=True)
        qb = q[1:] / np.linalg.norm(q[1:], axis=1, keepdims=True)
        th = 2.0 * np.arccos(np.minimum(np.abs((qa * qb).sum(axis=1)), 1.0))
        return np.sqrt(dp ** 2 + (self.rot_length_scale * th) ** 2)

    @functools.cached_property
    def _cumulative(self) -> np.ndarray:
        """(k,) path length at each keyframe [m]."""
        return np.concatenate([[0.0], np.cumsum(self.segment_lengths)])

    @property
    def length(self) -> float:
        """Total path length [m] (for translation-only paths: the arc length of the polyline)."""
        return float(self._cumulative[-1])

    def _locate(self, s: float) -> tuple[int, float]:
        """Segment index i and fraction f in [0, 1] of path length s (clamped to the path)."""
        seg, cum = self.segment_lengths, self._cumulative
        s = float(np.clip(s, 0.0, cum[-1]))
        i = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1))
        return i, (0.0 if seg[i] <= 0 else (s - cum[i]) / seg[i])

    def sampled_positions(self, samples: int) -> np.ndarray:
        """(samples, 3) positions [m] at ``samples`` evenly spaced path lengths from 0 to the end
        (computed once per count: the path is immutable)."""
        cache = self.__dict__.setdefault("_sampled", {})
        if samples not in cache:  # pose_at's positions, vectorized (linear within each segment)
            s = np.linspace(0.0, self.length, samples)
            seg, cum = self.segment_lengths, self._cumulative
            i = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1)
            f = np.where(seg[i] > 0, (s - cum[i]) / np.where(seg[i] > 0, seg[i], 1.0), 0.0)
            P = np.asarray(self.positions, dtype=float)
            cache[samples] = (1.0 - f)[:, None] * P[i] + f[:, None] * P[i + 1]
        return cache[samples]

    def pose_at_key(self, u: float):
        """Pose at keyframe parameter u in [0, k-1] (u = 1.5: halfway between keys 1 and 2)."""
        k = len(self.positions)
        u = float(np.clip(u, 0.0, k - 1))
        i = min(int(np.floor(u)), k - 2)
        f = u - i
        pos = (1 - f) * self.positions[i] + f * self.positions[i + 1]
        return pos, quat_slerp(self.quats[i], self.quats[i + 1], f)

    def pose_at(self, s: float):
        """Pose ``(pos (3,), quat (4,))`` at path length s [m], clamped to [0, length]."""
        i, f = self._locate(s)
        return self.pose_at_key(i + f)

    def direction_at(self, s: float) -> np.ndarray:
        """Unit translation direction (3,) of the segment containing s (zero for pure rotations)."""
        i, _ = self._locate(s)
        d = self.positions[i + 1] - self.positions[i]
        n = np.linalg.norm(d)
        return d / n if n > 0 else np.zeros(3)

    def sample(self, h: float, *, length: float | None = None):
        """Poses every h [m] from 0 to ``length`` (default the whole path), end included.

        Returns a list of ``(s, pos (3,), quat (4,))``; insertion step k is entry k.
        """
        if not h > 0:
            raise InputError(f"step size must be positive, got {h}", where="h_in")
        L = self.length if length is None else float(length)
        n = int(np.floor(L / h + 1e-9))
        ss = [k * h for k in range(n + 1)]
        if L - ss[-1] > 1e-9 * max(L, 1.0):
            ss.append(L)
        return [(s, *self.pose_at(s)) for s in ss]

    @classmethod
    def from_model(cls, model, body: str = "object", *, rot_length_scale: float | None = None) -> "Trajectory":
        """Trajectory of mocap ``body`` through the model's keyframes, in keyframe order."""
        mj = _mujoco()
        bid = mj.mj_name2id(model, mj.mjtObj.mjOBJ_BODY, body)
        if bid < 0:
            raise InputError(f"no body named {body!r} in the scene")
        mid = int(model.body_mocapid[bid])
        if mid < 0:
            raise InputError(f"body {body!r} is not a mocap body (add mocap=\"true\")")
        if model.nkey < 2:
            raise InputError(f"the scene needs at least 2 <key> keyframes for body {body!r}, found {model.nkey}")
        pos = np.array(model.key_mpos).reshape(model.nkey, -1, 3)[:, mid]
        quat = np.array(model.key_mquat).reshape(model.nkey, -1, 4)[:, mid]
        if rot_length_scale is None:
            rot_length_scale = _body_radius(model, bid)
        return cls(pos, quat, float(rot_length_scale))

    @classmethod
    def from_scene(cls, scene: Scene, body: str = "object", **kw) -> "Trajectory":
        """Trajectory of mocap ``body`` in a loaded :class:`Scene` (an InputError names the scene's file)."""
        try:
            return cls.from_model(scene.model, body, **kw)
        except InputError as e:
            raise e.in_file(scene.path) from None


def _body_radius(model, bid: int) -> float:
    """Largest distance of a body's geometry from the body frame origin [m]: exact for meshes (an
    SDF geom: its MuJoCo mesh) and for primitives centred on the body's origin (MuJoCo's bounding
    radius ``geom_rbound``); |geom pos| + that radius (an upper bound) for an offset primitive.
    No meshing (the scene loads without trimesh)."""
    mj = _mujoco()
    G = mj.mjtGeom
    r = 0.0
    for g in range(model.ngeom):
        if int(model.geom_bodyid[g]) != bid:
            continue
        t = int(model.geom_type[g])
        pos = np.asarray(model.geom_pos[g], dtype=np.float64)
        if t in (int(G.mjGEOM_MESH), int(G.mjGEOM_SDF)) and int(model.geom_dataid[g]) >= 0:
            mid = int(model.geom_dataid[g])
            va, vn = int(model.mesh_vertadr[mid]), int(model.mesh_vertnum[mid])
            V = np.asarray(model.mesh_vert[va:va + vn], dtype=np.float64) @ quat_to_matrix(model.geom_quat[g]).T + pos
            r = max(r, float(np.linalg.norm(V, axis=1).max()))
        elif t not in (int(G.mjGEOM_PLANE), int(G.mjGEOM_HFIELD)):  # a primitive (or a mesh-less SDF: its bound)
            r = max(r, float(np.linalg.norm(pos)) + float(model.geom_rbound[g]))
    return r


# --------------------------------------------------------------------------- generation
def _fmt(v) -> str:
    if isinstance(v, str):
        return v
    if isinstance(v, bool):
        return "true" if v else "false"
    a = np.asarray(v)
    if a.ndim == 0:
        return f"{float(a):.9g}" if a.dtype.kind == "f" else str(a.item())
    return " ".join(f"{x:.9g}" if a.dtype.kind == "f" else str(int(x)) for x in a.ravel())


class MJCFBuilder:
    """Build an MJCF model in Python and save it (validated by MuJoCo, atomically).

    Example::

        b = MJCFBuilder("deployed")
        b.mesh_asset("part", V, F)
        body = b.body("part", pos=[0, 0, 0])
        b.geom(body, type="mesh", mesh="part", rgba=[0.8, 0.6, 0.3, 1])
        b.save("out/deployed.xml")

    Attribute values may be strings, numbers, booleans or arrays (space-separated).
    """

    def __init__(self, model_name: str = "simfab", *, timestep: float | None = None, gravity=None):
        self.root = ET.Element("mujoco", model=model_name)
        self.compiler = ET.SubElement(self.root, "compiler", angle="radian", autolimits="true")
        opt = ET.SubElement(self.root, "option")
        if timestep is not None:
            opt.set("timestep", _fmt(timestep))
        if gravity is not None:
            opt.set("gravity", _fmt(gravity))
        vis = ET.SubElement(self.root, "visual")
        ET.SubElement(vis, "global", offwidth="1280", offheight="960")
        ET.SubElement(vis, "headlight", ambient="0.35 0.35 0.35", diffuse="0.6 0.6 0.6")
        self.asset = ET.SubElement(self.root, "asset")
        ET.SubElement(self.asset, "texture", name="sky", type="skybox", builtin="gradient", rgb1=".55 .65 .75",
                      rgb2=".12 .12 .15", width="256", height="1536")
        ET.SubElement(self.asset, "texture", name="grid", type="2d", builtin="checker", rgb1=".72 .72 .72",
                      rgb2=".62 .62 .62", width="256", height="256")
        ET.SubElement(self.asset, "material", name="grid", texture="grid", texrepeat="8 8", reflectance="0")
        self.worldbody = ET.SubElement(self.root, "worldbody")
        ET.SubElement(self.worldbody, "light", name="top", pos="0 0 3", dir="0 0 -1", directional="true")
        self._sections: dict[str, ET.Element] = {}

    def _section(self, tag: str) -> ET.Element:
        if tag not in self._sections:
            self._sections[tag] = ET.SubElement(self.root, tag)
        return self._sections[tag]

    def add(self, parent: ET.Element, tag: str, **attrs) -> ET.Element:
        """Generic child element with formatted attributes (None values are skipped)."""
        return ET.SubElement(parent, tag, {k: _fmt(v) for k, v in attrs.items() if v is not None})

    def mesh_asset(self, name: str, vertices, faces) -> ET.Element:
        """Inline mesh asset (vertices (n,3) [m], faces (m,3)); the MJCF stays self-contained."""
        V = np.asarray(vertices, dtype=np.float64)
        F = np.asarray(faces, dtype=np.int64)
        if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
            raise ValueError("mesh_asset needs vertices (n,3) and triangle faces (m,3)")
        return self.add(self.asset, "mesh", name=name, vertex=V, face=F)

    def body(self, name: str, parent: ET.Element | None = None, *, pos=(0, 0, 0), quat=(1, 0, 0, 0),
             mocap: bool = False, freejoint: bool = False, **attrs) -> ET.Element:
        """A body under ``parent`` (default worldbody). Mocap bodies must be children of the world."""
        el = self.add(self.worldbody if parent is None else parent, "body", name=name, pos=pos, quat=quat,
                      mocap=True if mocap else None, **attrs)
        if freejoint:
            ET.SubElement(el, "freejoint", name=f"{name}_free")
        return el

    def geom(self, body: ET.Element, *, sdf: str | None = None, **attrs) -> ET.Element:
        """A geom in ``body`` (type, size, mesh, rgba, pos, quat, contype, ...); ``sdf``: the name of
        an :meth:`sdf_asset` (an SDF geom of that plugin instance)."""
        if sdf is None:
            return self.add(body, "geom", **attrs)
        el = self.add(body, "geom", type="sdf", mesh=sdf, **attrs)
        ET.SubElement(el, "plugin", instance=sdf)
        return el

    def sdf_asset(self, name: str, plugin: str, **config) -> ET.Element:
        """An SDF plugin instance ``name`` (e.g. ``mujoco.sdf.torus`` with radius1, radius2 [m]) and
        the mesh asset MuJoCo renders it with; geoms use it through ``geom(body, sdf=name)``."""
        ext = self.add(self._section("extension"), "plugin", plugin=plugin)
        inst = ET.SubElement(ext, "instance", name=name)
        for k, v in config.items():
            ET.SubElement(inst, "config", key=k, value=_fmt(v))
        mesh = self.add(self.asset, "mesh", name=name)
        ET.SubElement(mesh, "plugin", instance=name)
        return mesh

    def site(self, body: ET.Element, name: str, pos, size=0.005, **attrs) -> ET.Element:
        """A named site (roots, targets, regions)."""
        return self.add(body, "site", name=name, pos=pos, size=size, **attrs)

    def floor(self, z: float = 0.0, size: float = 1.0) -> ET.Element:
        """A checkered ground plane at height z."""
        return self.geom(self.worldbody, name="floor", type="plane", pos=[0, 0, z], size=[size, size, 0.01],
                         material="grid")

    def key(self, name: str | None = None, **attrs) -> ET.Element:
        """A keyframe (``mpos``, ``mquat``, ``qpos``, ``time``...)."""
        return self.add(self._section("keyframe"), "key", name=name, **attrs)

    def equality(self, tag: str, **attrs) -> ET.Element:
        """An equality constraint: ``weld`` (body1, body2, relpose) or ``connect`` (body1, body2, anchor)."""
        return self.add(self._section("equality"), tag, **attrs)

    def custom_numeric(self, name: str, data) -> ET.Element:
        return self.add(self._section("custom"), "numeric", name=name, data=np.atleast_1d(np.asarray(data, float)))

    def custom_text(self, name: str, data: str) -> ET.Element:
        return self.add(self._section("custom"), "text", name=name, data=data)

    def to_xml(self) -> str:
        """The MJCF document as a string (indented)."""
        tree = ET.ElementTree(self.root)
        ET.indent(tree, space="  ")
        return ET.tostring(self.root, encoding="unicode") + "\n"

    def compile(self):
        """``mujoco.MjModel`` of the current document (raises ValueError if MuJoCo rejects it)."""
        return _mujoco().MjModel.from_xml_string(self.to_xml())

    def save(self, path: str | os.PathLike) -> Path:
        """Write the MJCF atomically after checking that MuJoCo loads it."""
        path = Path(path)
        with atomic_path(path) as tmp:
            tmp.write_text(self.to_xml(), encoding="utf-8")
            _mujoco().MjModel.from_xml_path(str(tmp))  # raises before the rename if invalid
        return path
