"""Rigid motions of the compliant part A that neither the supports nor the contact resist.

The fixed region holds A only along some axes, and frictionless contact pushes only along O's
normals. A rigid motion of A that moves no held dof and no contact point along its normal costs
no energy: the equilibrium is then not unique along it (a clip on a frictionless cylinder can
slide along the cylinder's axis, a claw on a sphere can turn about the axis through the sphere's
centre), and where A ends up along it, and with it the forces, depends on solver details. This
module finds such motions so that a run can say so.

A rigid motion is q = (t, w): translation t and rotation w (about A's rest centroid c), moving a
point y by u(y) = t + w x (y - c) (2D: w is a scalar, w x r = w (-r_y, r_x)).
"""

from __future__ import annotations

import numpy as np

#: A rigid motion whose contact stiffness is below this fraction of the stiffness it would have if
#: every contact normal were aligned with the motion counts as unresisted.
UNRESISTED_REL = 1e-3


def motion_basis(cm) -> tuple[np.ndarray, np.ndarray]:
    """(Q (r, k), c (dim,)): a basis of the rigid motions (columns, r = 3 in 2D, 6 in 3D) that move
    no dof held by the supports, and the centre the rotations are about. k = 0: the supports hold
    every rigid motion."""
    fem, dim = cm.fem, cm.dim
    c = fem.rest.mean(axis=0)
    verts, axes = np.nonzero(~cm.free.reshape(-1, dim))  # the held dofs
    r = 3 if dim == 2 else 6
    if not len(verts):
        return np.eye(r), c
    rows = _rows(fem.rest[verts] - c, dim)[np.arange(len(verts)), axes]  # (held dofs, r)
    _, s, Vt = np.linalg.svd(rows, full_matrices=True)
    rank = int(np.sum(s > 1e-9 * s.max()))
    return Vt[rank:].T, c


def _rows(rel: np.ndarray, dim: int) -> np.ndarray:
    """(p, dim, r): d u / d q at points with positions ``rel`` (p, dim) relative to the centre."""
    p = len(rel)
    if dim == 2:
        out = np.zeros((p, 2, 3))
        out[:, 0, 0] = out[:, 1, 1] = 1.0
        out[:, 0, 2], out[:, 1, 2] = -rel[:, 1], rel[:, 0]
        return out
    out = np.zeros((p, 3, 6))
    out[:, [0, 1, 2], [0, 1, 2]] = 1.0
    x, y, z = rel[:, 0], rel[:, 1], rel[:, 2]
    # w x r = (w_y z - w_z y, w_z x - w_x z, w_x y - w_y x)
    out[:, 0, 4], out[:, 0, 5] = z, -y
    out[:, 1, 3], out[:, 1, 5] = -z, x
    out[:, 2, 3], out[:, 2, 4] = y, -x
    return out


def weakest_motion(Q: np.ndarray, c: np.ndarray, y: np.ndarray, normals: np.ndarray, weights: np.ndarray):
    """(ratio, q) for the rigid motion in span(Q) that contact resists least.

    y (p, dim) contact points, normals (p, dim) O's unit normals there, weights (p,) >= 0 their
    contact stiffness (e.g. kappa b''(d)). ratio = sum w (n . u)^2 / sum w |u|^2 over the points
    for the minimizing motion (0: unresisted); None when there is no contact or no free motion.
    """
    if Q.shape[1] == 0 or not np.any(weights > 0):
        return None
    J = _rows(y - c, y.shape[1]) @ Q  # (p, dim, k): point motion per basis motion
    nJ = np.einsum("pd,pdk->pk", normals, J)
    K = np.einsum("p,pk,pl->kl", weights, nJ, nJ)
    M = np.einsum("p,pdk,pdl->kl", weights, J, J)
    from scipy.linalg import eigh

    lam, V = eigh(K, M + 1e-300 * np.eye(len(M)))
    return float(max(lam[0], 0.0)), Q @ V[:, 0]


def describe(q: np.ndarray, dim: int, radius: float) -> str:
    """Words for a rigid motion q: its dominant translation axis or rotation axis (the rotation
    compared with the translation by the motion it gives at ``radius`` [m] from the centre)."""
    axes = "xyz"
    t, w = (q[:2], q[2:]) if dim == 2 else (q[:3], q[3:])
    if np.linalg.norm(t) >= radius * np.linalg.norm(w):
        return f"translation along {axes[int(np.argmax(np.abs(t)))]}"
    if dim == 2:
        return "rotation in the plane"
    return f"rotation about {axes[int(np.argmax(np.abs(w)))]}"
