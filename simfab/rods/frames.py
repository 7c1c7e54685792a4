"""Frames of discrete elastic rods (vectorized NumPy, float64).

Conventions (Bergou et al. 2008):

- edge ``e`` runs from node ``edges[e, 0]`` to ``edges[e, 1]``; tangent ``t_e = e / |e|``;
- each edge carries a *reference* frame ``(t, d1, d2 = t x d1)`` that is updated by
  **time-parallel transport** whenever the tangent changes, and a twist angle ``theta_e``;
  the *material* frame is the reference frame rotated by ``theta_e`` about ``t``:
  ``m1 = cos(theta) d1 + sin(theta) d2``, ``m2 = -sin(theta) d1 + cos(theta) d2``;
- at an interior vertex between edges ``e`` (incoming) and ``f`` (outgoing) the
  **reference twist** is the angle from ``d1_f`` ... precisely: the signed angle, about
  ``t_f``, from the space-parallel transport of ``d1_e`` onto ``t_f`` to ``d1_f``; it is
  tracked continuously (no 2 pi wrapping) by adding the change since the last update.
"""

from __future__ import annotations

import numpy as np


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (k,3) arrays (np.cross has a large fixed overhead)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot product (k,) of (k,3) arrays."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def normalize(v: np.ndarray) -> np.ndarray:
    """Rows of ``v`` (..., 3) scaled to unit length."""
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def parallel_transport(v: np.ndarray, t1: np.ndarray, t2: np.ndarray) -> np.ndarray:
    """Transport vectors ``v`` (k,3) from unit tangents ``t1`` to ``t2`` by the minimal rotation.

    Uses the rotation about ``b = t1 x t2`` written without trigonometry:
    ``P v = (t1.t2) v + b x v + (b.v) b / (1 + t1.t2)`` (exact for ``t1.t2 > -1``).
    """
    b = cross(t1, t2)
    c = dot(t1, t2)[:, None]
    bv = dot(b, v)[:, None]
    return c * v + cross(b, v) + bv * b / (1.0 + c)


def signed_angle(u: np.ndarray, v: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Signed angle (k,) from ``u`` to ``v`` about the axis ``n`` (rows; u, v orthogonal to n)."""
    w = cross(u, v)
    return np.arctan2(dot(w, n), dot(u, v))


def rotate_about(v: np.ndarray, axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotate rows of ``v`` about unit ``axis`` rows by ``angle`` (Rodrigues)."""
    c = np.cos(angle)[:, None]
    s = np.sin(angle)[:, None]
    ad = dot(axis, v)[:, None]
    return v * c + cross(axis, v) * s + axis * ad * (1.0 - c)


def tangents(x: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Unit tangents (E,3) of the edges (E,2) of node positions ``x`` (N,3)."""
    return normalize(x[edges[:, 1]] - x[edges[:, 0]])


def material_frames(d1: np.ndarray, t: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Material directors ``(m1, m2)`` (E,3) from reference ``d1``, tangent ``t`` and ``theta`` (E,)."""
    d2 = cross(t, d1)
    c = np.cos(theta)[:, None]
    s = np.sin(theta)[:, None]
    return c * d1 + s * d2, -s * d1 + c * d2


def space_parallel_frames(t: np.ndarray, d1_first: np.ndarray) -> np.ndarray:
    """Reference directors along one chain of tangents ``t`` (k,3) by space-parallel transport.

    ``d1_first`` (3,) is projected onto the plane normal to ``t[0]``. Frames built this way
    have zero reference twist.
    """
    d = np.empty_like(t)
    v = d1_first - np.dot(d1_first, t[0]) * t[0]
    n = np.linalg.norm(v)
    if n < 1e-12:
        raise ValueError("the first director is parallel to the first tangent")
    d[0] = v / n
    for i in range(1, len(t)):
        d[i] = parallel_transport(d[i - 1 : i], t[i - 1 : i], t[i : i + 1])[0]
        d[i] -= np.dot(d[i], t[i]) * t[i]
        d[i] /= np.linalg.norm(d[i])
    return d


def reference_twist(d1: np.ndarray, t: np.ndarray, hinge_edges: np.ndarray, previous: np.ndarray) -> np.ndarray:
    """Reference twist (H,) at each hinge, continuous with ``previous`` (H,).

    ``hinge_edges`` (H,2): (incoming edge e, outgoing edge f). The result differs from
    ``previous`` by the signed angle between ``P_e^f(d1_e)`` rotated by ``previous`` and
    ``d1_f``, so that no 2 pi jumps occur between nearby configurations.
    """
    e, f = hinge_edges[:, 0], hinge_edges[:, 1]
    u = parallel_transport(d1[e], t[e], t[f])
    u = rotate_about(u, t[f], previous)
    return previous + signed_angle(u, d1[f], t[f])


def transport_directors(d1: np.ndarray, t_old: np.ndarray, t_new: np.ndarray) -> np.ndarray:
    """Time-parallel transport of reference directors (E,3) from old to new tangents (re-orthonormalized)."""
    d = parallel_transport(d1, t_old, t_new)
    d -= dot(d, t_new)[:, None] * t_new
    return normalize(d)
