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
    """A deployed shape's deviation from the target (:func:`deviation`).

    Args:
        aligned: (n,3) [m] the deployed vertices after alignment.
        per_vertex: (n,) [m] each one's distance to the target.
        rms: RMS distance over the diameter [-].
        hausdorff: Hausdorff distance over the diameter [-].
        rms_m: RMS distance [m].
        hausdorff_m: Hausdorff distance [m].
        diameter: the target's diameter [m].
        R: (3,3) the alignment's rotation.
        t: (3,) [m] its translation.
    """

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
    """The rigid motion minimising sum |R x_i + t - y_i|^2.

    Args:
        X: (n,3) points.
        Y: (n,3) their targets.

    Returns:
        (R (3,3), t (3,)).
    """
    cx, cy = X.mean(axis=0), Y.mean(axis=0)
    U, _, Wt = np.linalg.svd((X - cx).T @ (Y - cy))
    d = np.sign(np.linalg.det(Wt.T @ U.T))
    R = Wt.T @ np.diag([1.0, 1.0, d]) @ U.T
    return R, cy - R @ cx


def quad_triangles(quads: np.ndarray) -> np.ndarray:
    """Triangles of a quad mesh.

    Args:
        quads: (q,4).

    Returns:
        (2q,3).
    """
    return np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])


def deviation(X, Y, quads, target, *, target_under=None, icp_iters: int = 30) -> Deviation:
    """Align deployed points to the target and measure (see the module doc).

    Args:
        X: (n,3) [m] deployed vertices.
        Y: (n,3) [m] their target points (the correspondences the alignment starts from).
        quads: (q,4) the pattern's quads (X's surface).
        target: the :class:`simfab.deploy.surface.Target`.
        target_under: (k,3) [m] target vertices under the pattern, for the Hausdorff distance's second
            half (None: Y).
        icp_iters: closest-point alignment iterations.

    Returns:
        The :class:`Deviation`.
    """
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


def out_of_plane_extent(X: np.ndarray) -> float:
    """Extent of points along the normal of their best-fit plane.

    Args:
        X: (n,3) [m] points.

    Returns:
        The extent [m].
    """
    return float(np.ptp((X - X.mean(axis=0)) @ np.linalg.svd(X - X.mean(axis=0))[2][2]))


def height_error(aligned: np.ndarray, target_points: np.ndarray) -> float:
    """The deployed height against the target's: out-of-plane extents' ratio minus one.

    Args:
        aligned: (n,3) [m] deployed vertices after the alignment.
        target_points: (n,3) [m] their target points.

    Returns:
        The relative height error [-] (0 for a flat target).
    """
    th = out_of_plane_extent(target_points)
    return out_of_plane_extent(aligned) / th - 1.0 if th > 0 else 0.0
