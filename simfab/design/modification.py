"""Modification energy: the Laplacian editing energy of the part's boundary.

With v_s (b, d) the displacement of the b boundary vertices from the initial rest shape,

    E_L = sum_axes v_s^T L^T L v_s / l^2      [-]

L (b, b) the uniform (umbrella) graph Laplacian of the boundary: (L v)_i = v_i - mean of v over
the boundary neighbours of i (the boundary polyline's two neighbours in 2D, the one-ring on the
boundary surface in 3D; Sorkine et al. 2004, "Laplacian surface editing"). L annihilates
constant vectors, so a rigid translation of the whole boundary costs nothing, while any change
of the boundary's shape (a bump, a thinned arm) does. l is the mean boundary edge length of the
initial shape, which makes E_L dimensionless and independent of the part's size: a
displacement that varies by one edge length between neighbours costs about 1 per vertex.
M_L = L^T L / l^2 is built once per mesh (:class:`ModificationEnergy`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


class ModificationEnergy:
    """E_L of rest shapes relative to ``rest`` (n, d) [m] with boundary facets ``facets``
    (f, d) (2D edges, 3D triangles; :attr:`simfab.fem.model.FemModel.boundary_facets`)."""

    def __init__(self, rest: np.ndarray, facets: np.ndarray):
        facets = np.asarray(facets, dtype=np.int64)
        self.rest = np.asarray(rest, dtype=np.float64)
        self.vertices = np.unique(facets)
        local = np.searchsorted(self.vertices, facets)
        k = facets.shape[1]
        i, j = np.triu_indices(k, 1)
        e = np.vstack([local[:, [a, b]] for a, b in zip(i, j)])
        e = np.unique(np.sort(e, axis=1), axis=0)
        b = len(self.vertices)
        A = sp.coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
                          shape=(b, b)).tocsr()
        deg = np.asarray(A.sum(axis=1)).ravel()
        L = sp.identity(b, format="csr") - sp.diags(1.0 / deg) @ A
        edge_len = np.linalg.norm(self.rest[self.vertices[e[:, 0]]] - self.rest[self.vertices[e[:, 1]]], axis=1)
        self.length = float(edge_len.mean())
        self.L = L.tocsr()
        self.M = (L.T @ L).tocsr() / self.length**2

    def __call__(self, X: np.ndarray) -> float:
        """E_L [-] of the rest shape X (n, d) [m]."""
        v = np.asarray(X, float)[self.vertices] - self.rest[self.vertices]
        Lv = self.L @ v
        return float(np.sum(Lv * Lv)) / self.length**2
