"""Keyframe trajectories: a mocap body's path through its keyframe poses, parameterized by path length.

A scene's object moves along ``<key mpos=".." mquat=".."/>`` keyframes of its mocap body; between
keyframes the position is linear and the orientation slerped. Quaternions are (w, x, y, z).
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from simfab.errors import InputError
from simfab.io.mjcf_load import Scene, mujoco_module
from simfab.rotations import quat_slerp, quat_to_matrix

__all__ = ["Trajectory", "body_radius"]


@dataclasses.dataclass(frozen=True)
class Trajectory:
    """Piecewise path through keyframe poses, parameterized by path length.

    Between keyframes the position is linear and the orientation is slerped with the same
    parameter. The length of a segment is ``sqrt(|Δp|² + (ρ θ)²)`` where θ is the rotation
    angle and ρ = ``rot_length_scale`` [m/rad] (the object's bounding radius when built from a
    scene): a pure rotation advances the path by the distance its farthest point travels,
    and a pure translation by its length, so that insertion steps of size h make sense for
    both.

    Args:
        positions: (k, 3) keyframe positions [m].
        quats: (k, 4) keyframe orientations (w, x, y, z).
        rot_length_scale: ρ [m/rad].
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
        s = min(max(float(s), 0.0), float(cum[-1]))  # (scalar clamps: np.clip costs microseconds per call)
        i = min(max(int(np.searchsorted(cum, s, side="right")) - 1, 0), len(seg) - 1)
        return i, (0.0 if seg[i] <= 0 else (s - cum[i]) / seg[i])

    def sampled_positions(self, samples: int) -> np.ndarray:
        """Positions at evenly spaced path lengths from 0 to the end (computed once per count).

        Args:
            samples: how many.

        Returns:
            (samples, 3) positions [m].
        """
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
        """Pose at a keyframe parameter.

        Args:
            u: in [0, k-1] (u = 1.5: halfway between keys 1 and 2).

        Returns:
            (pos (3,) [m], quat (4,)).
        """
        k = len(self.positions)
        u = min(max(float(u), 0.0), float(k - 1))
        i = min(int(np.floor(u)), k - 2)
        return self._pose(i, u - i)

    def _pose(self, i: int, f: float):
        """(pos, quat) a fraction f of the way along segment i."""
        return self._position(i, f), quat_slerp(self.quats[i], self.quats[i + 1], f)

    def _position(self, i: int, f: float) -> np.ndarray:
        """The position a fraction f of the way along segment i."""
        return (1 - f) * self.positions[i] + f * self.positions[i + 1]

    def pose_at(self, s: float):
        """Pose at a path length.

        Args:
            s: path length [m], clamped to [0, length].

        Returns:
            (pos (3,) [m], quat (4,)).
        """
        return self._pose(*self._locate(s))

    def position_at(self, s: float) -> np.ndarray:
        """Position at a path length (:meth:`pose_at`'s, without the orientation's slerp).

        Args:
            s: path length [m], clamped to [0, length].

        Returns:
            (3,) position [m].
        """
        return self._position(*self._locate(s))

    @functools.cached_property
    def segment_turns(self) -> np.ndarray:
        """(k-1,) bool: whether each segment changes the orientation (|q_i . q_(i+1)| below 1 - 1e-12)."""
        q = self.quats
        return np.abs(np.abs((q[:-1] * q[1:]).sum(axis=1)) - 1.0) > 1e-12

    def turns_between(self, s0: float, s1: float) -> bool:
        """Whether the orientation changes anywhere between two path lengths.

        Args:
            s0, s1: path lengths [m], s0 <= s1 (clamped to the path).

        Returns:
            True when a segment overlapping [s0, s1] turns.
        """
        return bool(self.segment_turns[self._locate(s0)[0]: self._locate(s1)[0] + 1].any())

    def direction_at(self, s: float) -> np.ndarray:
        """Translation direction of the segment containing a path length.

        Args:
            s: path length [m].

        Returns:
            Unit vector (3,) (zero for a pure rotation).
        """
        i, _ = self._locate(s)
        d = self.positions[i + 1] - self.positions[i]
        n = np.linalg.norm(d)
        return d / n if n > 0 else np.zeros(3)

    def sample(self, h: float, *, length: float | None = None):
        """Poses every h [m] from 0 to ``length``, end included.

        Args:
            h: the step [m].
            length: where to end [m] (None: the whole path).

        Returns:
            A list of ``(s, pos (3,), quat (4,))``; insertion step k is entry k.
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
        """Trajectory of a mocap body through the model's keyframes, in keyframe order.

        Args:
            model: ``mujoco.MjModel``.
            body: the mocap body's name.
            rot_length_scale: ρ [m/rad]; None: the body's bounding radius (:func:`body_radius`).

        Returns:
            The trajectory; InputError when the body is not a mocap body or the keys are too few.
        """
        mj = mujoco_module()
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
            rot_length_scale = body_radius(model, bid)
        return cls(pos, quat, float(rot_length_scale))

    @classmethod
    def from_scene(cls, scene: Scene, body: str = "object", **kw) -> "Trajectory":
        """Trajectory of a mocap body in a loaded scene.

        Args:
            scene: the :class:`~simfab.io.mjcf_load.Scene`.
            body: the mocap body's name.
            **kw: as :meth:`from_model`.

        Returns:
            The trajectory (an InputError names the scene's file).
        """
        try:
            return cls.from_model(scene.model, body, **kw)
        except InputError as e:
            raise e.in_file(scene.path) from None


def body_radius(model, bid: int) -> float:
    """Largest distance of a body's geometry from the body frame origin [m].

    Exact for meshes (an SDF geom: its MuJoCo mesh) and for primitives centred on the body's origin
    (MuJoCo's bounding radius ``geom_rbound``); |geom pos| + that radius (an upper bound) for an
    offset primitive. No meshing (the scene loads without trimesh).

    Args:
        model: ``mujoco.MjModel``.
        bid: the body's index.

    Returns:
        The radius [m].
    """
    mj = mujoco_module()
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
