"""Deviation of a deployed surface from its target after the best rigid alignment.

The deployed surface is the pattern's quad mesh with the deployed vertex positions X (n,3) [m]
(insert centres, boundary junctions), split into triangles. Each vertex's counterpart on the
target, Y (n,3), is the target point its flat position maps to (barycentric on the flattening).

Alignment: Kabsch (least-squares rotation + translation of X onto Y, no scaling: the pattern is
cut at the target's size), refined by point-to-surface ICP on the target mesh until the RMS
changes by less than 1e-9 relative.

Reported (lengths relative to the target's diameter D = bounding-box diagonal):
- ``rms``: sqrt(mean_i d(x_i, target)^2) over the deployed vertices;
- ``hausdorff``: max(max_i d(x_i, target), max_j d(y_j, deployed)) with y_j the target's
  vertices that lie under the pattern (their flat positions inside the quad mesh);
- per-vertex deviation d(x_i, target) [m] for the colour map.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Deviation:
    """aligned (n,3) [m]: deployed vertices after alignment; per_vertex (n,) [m]; rms, hausdorff [-]
    (relative to diameter [m]); rms_m, hausdorff_m [m]; R (3,3), t (3,) the alignment."""

    aligned: np.ndarray
    per_vertex: np.ndarray
    rms: float
    hausdorff: float
    rms_m: float
    hausdorff_m: float
    diameter: float
    R: np.ndarray
    t: np.ndarray


def kabsch(X: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R (3,3) and translation t (3,) minimising sum |R x_i + t - y_i|^2."""
    cx, cy = X.mean(axis=0), Y.mean(axis=0)
    U, _, Wt = np.linalg.svd((X - cx).T @ (Y - cy))
    d = np.sign(np.linalg.det(Wt.T @ U.T))
    R = Wt.T @ np.diag([1.0, 1.0, d]) @ U.T
    return R, cy - R @ cx


def quad_triangles(quads: np.ndarray) -> np.ndarray:
    """(2q,3) triangles of a quad mesh (q,4)."""
    return np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])


def deviation(X, Y, quads, target, *, target_under=None, icp_iters: int = 30) -> Deviation:
    """Align X (n,3) to the target (:class:`simfab.deploy.surface.Target`) with correspondences
    Y (n,3) and measure (see module doc). ``target_under``: target vertices (k,3) under the pattern
    for the Hausdorff distance's second half (default: Y)."""
    import trimesh

    tm = trimesh.Trimesh(target.V, target.F, process=False)
    R, t = kabsch(X, Y)
    prev = np.inf
    for _ in range(icp_iters):
        A = X @ R.T + t
        C, dist, _ = trimesh.proximity.closest_point(tm, A)
        rms = float(np.sqrt(np.mean(dist**2)))
        if abs(prev - rms) <= 1e-9 * max(rms, 1e-300):
            break
        prev = rms
        R, t = kabsch(X, C)
    A = X @ R.T + t
    _, dist, _ = trimesh.proximity.closest_point(tm, A)
    dep = trimesh.Trimesh(A, quad_triangles(quads), process=False)
    under = Y if target_under is None else target_under
    _, back, _ = trimesh.proximity.closest_point(dep, under)
    D = target.diameter
    rms = float(np.sqrt(np.mean(dist**2)))
    hd = float(max(np.max(dist), np.max(back)))
    return Deviation(aligned=A, per_vertex=dist, rms=rms / D, hausdorff=hd / D, rms_m=rms, hausdorff_m=hd,
                     diameter=D, R=R, t=t)
