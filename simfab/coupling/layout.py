"""Where the contact term of an insertion step lands on the compliant part A: the per-point barrier
activation distances, the Hessian slots of each constraint point's parent vertices, and the diagonal
regularization of the Hessian when the supports leave rigid motions free.

These depend only on the model and a point set, so they are memoized (on the point set's ``cache``
or the model's) and shared by the objective, the predictor, the facet check and the rigid-mode check.
"""

from __future__ import annotations

import numpy as np

from simfab.coupling import config as C
from simfab.coupling import rigid
from simfab.coupling.model import CouplingModel
from simfab.coupling.points import ContactPoints

#: The edges (a, c) of a boundary facet by the spatial dimension: one edge in 2D, three in 3D.
EDGE_PAIRS = {2: (np.array([0]), np.array([1])), 3: (np.array([0, 0, 1]), np.array([1, 2, 2]))}


def point_dhat(cm: CouplingModel, pts: ContactPoints) -> np.ndarray:
    """(k,) barrier activation distance of each constraint point [m]: ``dhat_rel`` times the local
    edge length there (the shortest boundary edge at a vertex, interpolated with the point's
    weights). The shortest edge, not the mean, keeps the standoff a fixed small fraction of the
    smallest local size on stretched meshes (an extrusion's long layer edges would otherwise set a
    standoff comparable to the interference)."""
    dh = pts.cache.get("dhat")
    if dh is None:
        hv = cm._cache.get("vertex_h")
        if hv is None:
            facets = cm.contact_facets
            a, c = EDGE_PAIRS[cm.dim]
            e = np.vstack([facets[:, [i, j]] for i, j in zip(a, c)])
            L = np.linalg.norm(cm.fem.rest[e[:, 0]] - cm.fem.rest[e[:, 1]], axis=1)
            hv = np.full(cm.fem.n_vertices, np.inf)
            np.minimum.at(hv, e.ravel(), np.repeat(L, 2))
            hv = cm._cache["vertex_h"] = np.where(np.isfinite(hv), hv, cm.h)
        dh = pts.cache["dhat"] = cm.options.dhat_rel * np.einsum("km,km->k", pts.weights, hv[pts.verts])
    return dh


def point_slots(cm: CouplingModel, pts: ContactPoints) -> np.ndarray:
    """(k, nv, nv, dim, dim) positions in the FEM Hessian's CSR data of the blocks coupling each
    point's parents (they share an element, so the blocks lie inside the fixed pattern)."""
    slots = pts.cache.get("slots")
    if slots is None:
        nv = pts.verts.shape[1]
        ia, ib = np.meshgrid(np.arange(nv), np.arange(nv), indexing="ij")
        rows = pts.verts[:, ia.ravel()].ravel()
        cols = pts.verts[:, ib.ravel()].ravel()
        slots = pts.cache["slots"] = cm.fem.pattern.block_slots(rows, cols).reshape(len(pts), nv, nv, cm.dim, cm.dim)
    return slots


def diag_slots(cm: CouplingModel) -> np.ndarray:
    """(n dim,) CSR slots of the Hessian's diagonal."""
    s = cm._cache.get("diag")
    if s is None:
        n, dim = cm.fem.n_vertices, cm.dim
        b = cm.fem.pattern.block_slots(np.arange(n), np.arange(n))
        s = cm._cache["diag"] = b[:, np.arange(dim), np.arange(dim)].ravel()
    return s


def add_point_blocks(cm: CouplingModel, pts: ContactPoints, H, rows: np.ndarray, blocks: np.ndarray) -> None:
    """H += sum_j w_ja w_jb blocks_j over the points ``rows`` (a,) with (a, dim, dim) blocks [N/m],
    in place on H's CSR data: the Hessian of a per-point term pulled back to the parent vertices."""
    if len(rows):
        w = pts.weights[rows]
        wpair = w[:, :, None, None, None] * w[:, None, :, None, None]
        np.add.at(H.data, point_slots(cm, pts)[rows].ravel(), (wpair * blocks[:, None, None, :, :]).ravel())


def regularize(cm: CouplingModel, H) -> None:
    """Add FACTOR_REG times A's mean diagonal stiffness to the diagonal of H in place when the
    supports leave rigid motions free: the sparse factorization then succeeds, and the Woodbury pin
    (:class:`simfab.coupling.rigid.PinnedSolver`) removes the near-null directions from the solve.
    The term is in the Hessian only, not in the energy."""
    if rigid.motion_basis(cm)[0].shape[1]:
        H.data[diag_slots(cm)] += C.FACTOR_REG * rigid.mean_stiffness(cm)
