"""Shape modification handles: bounded biharmonic weights + linear blend skinning.

A rest shape X (n, d) is edited by m handles. Handle j sits at c_j (d,) and carries a
translation t_j (d,) [m] and a per-axis scale s_j (d,) [-] about c_j:

    T_j(x) = c_j + s_j * (x - c_j) + t_j                    (elementwise product)
    x'_i   = sum_j w_ij T_j(x_i)                             (linear blend skinning)

With the weights summing to one at every vertex (sum_j w_ij = 1) the identity transforms
(s = 1, t = 0) reproduce X exactly. Written as one matrix product (thesis: X' = M_LBS T)

    X' = M_LBS T,   M_LBS (n, (d+1) m) = [w_ij (x_i - c_j)^T, w_ij]_j,
                    T ((d+1) m, d) = [diag(s_j); (c_j + t_j)^T]_j ,

M_LBS is computed once per mesh; a new design only rebuilds T. Here the product is evaluated
without forming T's zero blocks: X' = W (C + Tr) + sum_j (W_j (X - c_j)) * s_j.

Weights: bounded biharmonic weights (Jacobson et al. 2011, libigl ``bbw``): w_j minimizes the
Laplacian energy int (Delta w_j)^2 subject to 0 <= w_j <= 1, w_j = 1 at handle j and 0 at the
other handles; the rows are then normalized to sum to one. **Inactive handles** keep regions
unchanged: every vertex of an inactive region (the fixed support, named ``keep`` sites) is
constrained to weight 1 on that region's handle, whose transform is the identity forever, so the
region does not move and its influence fades smoothly into the active handles' regions.
"""

from __future__ import annotations

from dataclasses import dataclass

import igl
import numpy as np

from simfab.errors import InputError


@dataclass(frozen=True, kw_only=True, eq=False)
class Handles:
    """Modification handles of one mesh (immutable).

    centers : (m, d) [m] handle positions c_j (inactive handles: centroid of their region)
    vertex : (m,) int vertex of each active handle, -1 for inactive handles
    active : (m,) bool; inactive handles always carry the identity transform
    weights : (n, m) [-] normalized bounded biharmonic weights (rows sum to 1)
    rest : (n, d) [m] the rest shape the handles edit
    """

    centers: np.ndarray
    vertex: np.ndarray
    active: np.ndarray
    weights: np.ndarray
    rest: np.ndarray

    @property
    def dim(self) -> int:
        return self.rest.shape[1]

    @property
    def n_active(self) -> int:
        return int(self.active.sum())

    @property
    def n_vars(self) -> int:
        """Design variables: a translation and a scale per axis for every active handle."""
        return 2 * self.dim * self.n_active

    def identity(self) -> np.ndarray:
        """(n_vars,) design vector of the unmodified shape: translations 0, scales 1."""
        t = np.zeros((self.n_active, self.dim))
        s = np.ones((self.n_active, self.dim))
        return pack(t, s)

    def split(self, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(translations (m_active, d) [m], scales (m_active, d)) of a design vector."""
        return unpack(h, self.n_active, self.dim)

    def transforms(self, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(translations (m, d) [m], scales (m, d)) of every handle, inactive ones the identity."""
        t, s = self.split(h)
        m, d = len(self.centers), self.dim
        T = np.zeros((m, d))
        S = np.ones((m, d))
        T[self.active] = t
        S[self.active] = s
        return T, S

    def apply(self, h: np.ndarray) -> np.ndarray:
        """(n, d) modified rest shape X' = M_LBS T(h)."""
        T, S = self.transforms(h)
        W = self.weights
        # sum_j w_ij (c_j + s_j (x_i - c_j) + t_j), with sum_j w_ij = 1
        local = (self.rest[:, None, :] - self.centers[None]) * S[None]  # s_j * (x_i - c_j)
        return W @ (self.centers + T) + np.einsum("ij,ijd->id", W, local)

    def lbs_matrix(self) -> np.ndarray:
        """(n, (d+1) m) M_LBS of the thesis (documentation and tests; :meth:`apply` avoids it)."""
        n, d = self.rest.shape
        m = len(self.centers)
        blocks = []
        for j in range(m):
            w = self.weights[:, j:j + 1]
            blocks.append(np.hstack([w * (self.rest - self.centers[j]), w]))
        return np.hstack(blocks).reshape(n, (d + 1) * m)

    def transform_stack(self, h: np.ndarray) -> np.ndarray:
        """((d+1) m, d) T of the thesis for design h (pairs with :meth:`lbs_matrix`)."""
        T, S = self.transforms(h)
        m, d = len(self.centers), self.dim
        out = np.zeros(((d + 1) * m, d))
        for j in range(m):
            out[(d + 1) * j:(d + 1) * j + d] = np.diag(S[j])
            out[(d + 1) * j + d] = self.centers[j] + T[j]
        return out


def pack(t: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Design vector [t_1, s_1, t_2, s_2, ...] from translations and scales (m, d) each."""
    return np.hstack([np.asarray(t, float), np.asarray(s, float)]).ravel()


def unpack(h: np.ndarray, m: int, d: int) -> tuple[np.ndarray, np.ndarray]:
    h = np.asarray(h, float).reshape(m, 2 * d)
    return h[:, :d], h[:, d:]


def make_handles(rest: np.ndarray, elements: np.ndarray, handle_vertices, inactive_regions=()) -> Handles:
    """Bounded biharmonic weights for point handles at ``handle_vertices`` plus one inactive handle
    per region in ``inactive_regions`` (each an array of vertex indices held unchanged).

    rest : (n, d) [m]; elements : (m, d+1) triangles (2D) or tetrahedra (3D)
    Raises InputError if a handle vertex lies in an inactive region or the weights cannot be
    computed.
    """
    X = np.ascontiguousarray(rest, dtype=np.float64)
    T = np.ascontiguousarray(elements, dtype=np.int64)
    hv = np.asarray(handle_vertices, dtype=np.int64).ravel()
    # a vertex in several kept regions belongs to the first one only (every constraint row of the
    # weights' quadratic program must be unique: libigl's active set corrupts memory otherwise)
    regions, taken = [], np.zeros(len(X), bool)
    for r in inactive_regions:
        r = np.unique(np.asarray(r, dtype=np.int64))
        r = r[~taken[r]]
        if len(r):
            regions.append(r)
            taken[r] = True
    if len(np.unique(hv)) != len(hv):
        raise InputError("two handles on the same vertex", where="[design] handles")
    held = np.concatenate(regions) if regions else np.zeros(0, np.int64)
    if np.isin(hv, held).any():
        raise InputError("a handle lies in a region kept unchanged (fixed support or keep site)",
                         where="[design] handles")
    m = len(hv) + len(regions)
    if len(hv) == 0:
        raise InputError("no active handle to modify the shape with", where="[design] handles")
    b = [hv]
    bc = [np.eye(m)[: len(hv)]]
    for k, r in enumerate(regions):
        b.append(r)
        bc.append(np.tile(np.eye(m)[len(hv) + k], (len(r), 1)))
    b = np.concatenate(b)
    bc = np.vstack(bc)
    if m == 1:
        W = np.ones((len(X), 1))
    else:
        W = np.asarray(igl.bbw(X, T, b, bc, partition_unity=True, max_iter=200))
    if W.shape != (len(X), m) or not np.all(np.isfinite(W)):
        raise InputError("bounded biharmonic weights failed on this mesh", where="[design] handles")
    W = np.clip(W, 0.0, 1.0)
    W[b] = bc  # exact at the constrained vertices
    W /= W.sum(axis=1, keepdims=True)
    centers = np.vstack([X[hv]] + [X[r].mean(axis=0, keepdims=True) for r in regions])
    active = np.r_[np.ones(len(hv), bool), np.zeros(len(regions), bool)]
    vertex = np.r_[hv, -np.ones(len(regions), np.int64)]
    for a in (centers, active, vertex, W, X):
        a.flags.writeable = False
    return Handles(centers=centers, vertex=vertex, active=active, weights=W, rest=X)
