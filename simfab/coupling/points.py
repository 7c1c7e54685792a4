"""Constraint points: mesh vertices and points interpolated on boundary edges (2D) / faces (3D).

A point is y_j = sum_a w_ja x_{v_ja}; all points of a set carry the same number of parents
``nv`` (= dim: an edge has 2 vertices, a face 3); a plain vertex repeats its index with weights
(1, 0[, 0]). Because parents of a point share an element, the contact Hessian blocks land inside
the FEM sparsity pattern (:meth:`HessianPattern.block_slots`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from simfab._sparse import csr_times


def row_norms(v: np.ndarray) -> np.ndarray:
    """(k,) row norms of (k, dim) v: ``np.linalg.norm(v, axis=1)``, its sums without its dispatch
    (called on every evaluation of the insertion loop)."""
    return np.sqrt(np.add.reduce(v * v, axis=1))


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
    def interpolation(self):
        """(P, P^T): the (k, n_max) CSR interpolation matrix, y = P x (n_max: the largest parent
        index + 1), and its transpose, built once per set: one sparse product instead of gathers
        and a weighted sum per call (the insertion loop reads positions several times per Newton
        iteration)."""
        P = self.cache.get("interpolation")
        if P is None:
            import scipy.sparse as sp

            k, nv = self.verts.shape  # (a plain vertex repeats its index with weights 1, 0[, 0])
            P = sp.csr_matrix((self.weights.ravel().copy(), self.verts.ravel().copy(), np.arange(0, k * nv + 1, nv)),
                              shape=(k, int(self.verts.max()) + 1 if k else 0))
            P.sum_duplicates()
            P.eliminate_zeros()
            P = self.cache["interpolation"] = (P, P.T.tocsr())
        return P

    def positions(self, x: np.ndarray) -> np.ndarray:
        """(k, dim) point positions (or displacements when ``x`` is a displacement field)."""
        P = self.interpolation[0]
        return csr_times(P, x[: P.shape[1]])

    def scatter(self, g_points: np.ndarray, n_vertices: int, rows: np.ndarray | None = None) -> np.ndarray:
        """Vertex vectors (n, dim) = sum_j w_ja g_j (transpose of :meth:`positions`). With ``rows``
        (a,) int, ``g_points`` (a, dim) is given at those points only (the others are zero)."""
        dim = g_points.shape[1]
        out = np.zeros((n_vertices, dim))
        if rows is not None:  # a few points (e.g. those in contact): accumulate them in place
            contrib = self.weights[rows, :, None] * g_points[:, None, :]  # (a, nv, dim)
            np.add.at(out, self.verts[rows].ravel(), contrib.reshape(-1, dim))
            return out
        PT = self.interpolation[1]
        out[: PT.shape[0]] = csr_times(PT, g_points)
        return out

    def concat(self, other: "ContactPoints") -> "ContactPoints":
        return ContactPoints(verts=np.vstack([self.verts, other.verts]),
                             weights=np.vstack([self.weights, other.weights]),
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
