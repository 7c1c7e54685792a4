"""Rotations: unit quaternions (w, x, y, z, MuJoCo's order), rotation matrices and rotation vectors.

Conventions: a quaternion q and -q are the same rotation; matrices act on column vectors
(world = R body); rotation vectors w are axis times angle [rad] (the exponential map).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def quat_to_matrix(q) -> np.ndarray:
    """(w, x, y, z) -> (3, 3) rotation matrix (q is normalized first)."""
    w, x, y, z = (np.asarray(q, dtype=np.float64) / np.linalg.norm(q)).tolist()  # (Python floats: the same
    # IEEE arithmetic as NumPy's scalars, a fraction of their overhead)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z), w >= 0, of a (3, 3) rotation matrix."""
    x, y, z, w = Rotation.from_matrix(R).as_quat()
    q = np.array([w, x, y, z])
    return q if q[0] >= 0 else -q


def quat_slerp(q0, q1, u: float) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions (w, x, y, z) at u in [0, 1], shortest arc."""
    q0 = np.asarray(q0, dtype=np.float64)
    same = q1 is q0 or (np.shape(q1) == q0.shape and np.asarray(q1, dtype=np.float64).tobytes() == q0.tobytes())
    q0 = q0 / np.sqrt(q0.dot(q0))  # (np.linalg.norm's sum for a vector, without its dispatch)
    if same:  # (two keyframes with the same rotation: the nlerp below of q0 with itself)
        q = q0 + u * (q0 - q0)
        return q / np.sqrt(q.dot(q))
    q1 = np.asarray(q1, dtype=np.float64)
    q1 = q1 / np.sqrt(q1.dot(q1))
    dot = float(np.dot(q0, q1))
    if dot < 0.0:  # q and -q are the same rotation; take the short way round
        q1, dot = -q1, -dot
    if dot > 1.0 - 1e-12:
        q = q0 + u * (q1 - q0)
        return q / np.sqrt(q.dot(q))
    theta = np.arccos(min(dot, 1.0))
    s = np.sin(theta)
    return (np.sin((1 - u) * theta) * q0 + np.sin(u * theta) * q1) / s


def quat_angle(q0, q1) -> float:
    """Rotation angle [rad] between two unit quaternions."""
    d = abs(float(np.dot(np.asarray(q0) / np.linalg.norm(q0), np.asarray(q1) / np.linalg.norm(q1))))
    return 2.0 * np.arccos(min(d, 1.0))


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices (k, 3, 3) of rows ``v`` (k, 3): ``skew(v) @ w == v x w``."""
    v = np.atleast_2d(v)
    S = np.zeros(v.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2] = -v[..., 2], v[..., 1]
    S[..., 1, 0], S[..., 1, 2] = v[..., 2], -v[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -v[..., 1], v[..., 0]
    return S


def expmap(w: np.ndarray) -> np.ndarray:
    """Rotation matrices (k, 3, 3) of rotation vectors ``w`` (k, 3) [rad] (Rodrigues' formula, its
    Taylor series below 1e-8 rad)."""
    w = np.atleast_2d(w)
    a = np.linalg.norm(w, axis=-1)
    K = skew(w)
    small = a < 1e-8
    a_safe = np.where(small, 1.0, a)
    s = np.where(small, 1.0 - a**2 / 6.0, np.sin(a_safe) / a_safe)
    c = np.where(small, 0.5 - a**2 / 24.0, (1.0 - np.cos(a_safe)) / a_safe**2)
    return np.eye(3) + s[:, None, None] * K + c[:, None, None] * (K @ K)


def pose_matrix(pose) -> tuple[np.ndarray, np.ndarray]:
    """(R (3, 3), p (3,)) from ``pose``: None (identity), (R, p) or (pos (3,), quat_wxyz (4,));
    a 2D position is padded with z = 0."""
    if pose is None:
        return np.eye(3), np.zeros(3)
    a, b = pose
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    if a.shape == (3, 3):
        R, p = a, b
    else:
        R, p = quat_to_matrix(b), a
    p = np.resize(p, 3) if p.size < 3 else p
    return R, p
