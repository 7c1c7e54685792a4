"""Constraint points: mesh vertices and points interpolated on boundary edges (2D) / faces (3D).

A point is y_j = sum_a w_ja x_{v_ja}; all points of a set carry the same number of parents
``nv`` (= dim: an edge has 2 vertices, a face 3); a plain vertex repeats its index with weights
(1, 0[, 0]). Because parents of a point share an element, the contact Hessian blocks land inside
the FEM sparsity pattern (:meth:`HessianPattern.block_slots`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True, kw_only=True, eq=False)
class ContactPoints:
    """verts : (k, nv) int parent vertices; weights : (k, nv) barycentric weights (rows sum to 1);
    facet : (k,) int boundary facet a sample belongs to, -1 for plain vertices."""

    verts: np.ndarray
    weights: np.ndarray
    facet: np.ndarray
    cache: dict = field(default_factory=dict, repr=False)  # derived data (e.g. Hessian slots) of this set

    def __len__(self) -> int:
        return len(self.verts)

    @property
    def n_plain(self) -> int:
        """Number of leading plain-vertex points (facet -1): sets list vertices first, and these
        are read and scattered directly instead of through their (1, 0[, 0]) weights."""
        n = self.cache.get("n_plain")
        if n is None:
            interp = np.flatnonzero(self.facet >= 0)
            n = self.cache["n_plain"] = int(interp[0]) if len(interp) else len(self.facet)
        return n

    def positions(self, x: np.ndarray) -> np.ndarray:
        """(k, dim) point positions (or displacements when ``x`` is a displacement field)."""
        nb = self.n_plain
        if nb == len(self):
            return x[self.verts[:, 0]]
        out = np.empty((len(self), x.shape[1]))
        out[:nb] = x[self.verts[:nb, 0]]
        out[nb:] = np.einsum("km,kmd->kd", self.weights[nb:], x[self.verts[nb:]])
        return out

    def scatter(self, g_points: np.ndarray, n_vertices: int, rows: np.ndarray | None = None) -> np.ndarray:
        """Vertex vectors (n, dim) = sum_j w_ja g_j (transpose of :meth:`positions`). With ``rows``
        (a,) int, ``g_points`` (a, dim) is given at those points only (the others are zero)."""
        dim = g_points.shape[1]
        nb = self.n_plain
        if rows is not None:  # a few points (e.g. those in contact): accumulate them in place
            out = np.zeros((n_vertices, dim))
            plain = rows < nb
            np.add.at(out, self.verts[rows[plain], 0], g_points[plain])
            if not plain.all():
                inner = rows[~plain]
                contrib = self.weights[inner, :, None] * g_points[~plain, None, :]  # (i, nv, dim)
                np.add.at(out, self.verts[inner].ravel(), contrib.reshape(-1, dim))
            return out
        idx = self.cache.get("scatter_idx")
        if idx is None:
            idx = self.cache["scatter_idx"] = np.concatenate([self.verts[:nb, 0], self.verts[nb:].ravel()])
        c = np.concatenate([g_points[:nb], (self.weights[nb:, :, None] * g_points[nb:, None, :]).reshape(-1, dim)])
        out = np.empty((n_vertices, dim))
        for a in range(dim):  # every point: one pass per axis
            out[:, a] = np.bincount(idx, weights=c[:, a], minlength=n_vertices)
        return out

    def concat(self, other: "ContactPoints") -> "ContactPoints":
        return ContactPoints(verts=np.vstack([self.verts, other.verts]), weights=np.vstack([self.weights, other.weights]),
                             facet=np.concatenate([self.facet, other.facet]))


def vertex_points(vertices: np.ndarray, dim: int) -> ContactPoints:
    """Plain vertex points for ``vertices`` (b,)."""
    v = np.asarray(vertices, dtype=np.int64)
    w = np.zeros((len(v), dim))
    w[:, 0] = 1.0
    return ContactPoints(verts=np.repeat(v[:, None], dim, axis=1), weights=w, facet=np.full(len(v), -1))


def edge_weights(samples: int) -> np.ndarray:
    """(s, 2) weights of ``samples`` points evenly spaced strictly inside an edge."""
    t = np.arange(1, samples + 1) / (samples + 1)
    return np.c_[1 - t, t]


def face_weights(order: int) -> np.ndarray:
    """(p, 3) barycentric lattice of ``order`` on a triangle, corners excluded."""
    out = []
    for i in range(order + 1):
        for j in range(order + 1 - i):
            k = order - i - j
            if max(i, j, k) == order:
                continue
            out.append((i / order, j / order, k / order))
    return np.array(out)


def facet_weights(dim: int, order: int) -> np.ndarray:
    """Refinement points on one boundary facet: ``order`` points inside an edge (2D) or the
    barycentric lattice of ``order`` on a face (3D)."""
    return edge_weights(order) if dim == 2 else face_weights(order)


def check_weights(dim: int, order: int) -> np.ndarray:
    """Denser check points of a facet: they contain the refinement points of ``order`` and the
    midpoints between them."""
    return edge_weights(2 * order + 1) if dim == 2 else face_weights(2 * order)


def facet_points(facets: np.ndarray, facet_ids: np.ndarray, weights: np.ndarray) -> ContactPoints:
    """Points with ``weights`` (p, nv) on each facet ``facets[facet_ids]``."""
    ids = np.asarray(facet_ids, dtype=np.int64)
    p = len(weights)
    verts = np.repeat(facets[ids], p, axis=0)
    w = np.tile(weights, (len(ids), 1))
    return ContactPoints(verts=verts.astype(np.int64), weights=w, facet=np.repeat(ids, p))
