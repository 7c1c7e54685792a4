"""Where the modification handles go.

- **displacement** (the thesis' choice): one insertion of the initial shape gives every vertex's
  largest displacement d_i = max_k |x_i(k) - X_i| [m]. The vertices are clustered by affinity
  propagation (Frey & Dueck 2007; scikit-learn ``AffinityPropagation``, precomputed similarity) on

      s_ij = -((d_i - d_j) / sd)^2 - (g_ij / sg)^2,

  g_ij the shortest-path distance along the mesh's edges (clusters are connected regions that
  deform alike), sd the standard deviation of d, sg the mesh graph's diameter / 4. A cluster's
  handle is its vertex nearest to the cluster's centroid.
- **spatial**: the same clustering with s_ij = -(|X_i - X_j| / sg)^2 (no simulation).
- **random**: ``count`` vertices drawn uniformly (seeded) outside the kept regions.

Clusters that contain a kept vertex (the fixed support, keep sites) get no active handle (the kept
vertices are inactive handles, :func:`simfab.design.handles.make_handles`). The shared preference
of affinity propagation is bisected until ``count`` clusters remain without a kept vertex (or the
closest count reachable).

The similarity matrix is dense (n, n): meshes larger than MAX_POINTS vertices are first reduced to
MAX_POINTS farthest-point samples on the geodesic distance, clustered, and the handles chosen
among them (its memory and time cost: docs/methods.md, "simfab.design.placement"; the choice of
MAX_POINTS: docs/decisions.md).
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from simfab.errors import InputError

MAX_POINTS = 1200
BISECTIONS = 30


def mesh_graph(rest: np.ndarray, elements: np.ndarray) -> sp.csr_matrix:
    """Symmetric (n, n) graph of the mesh's edges weighted by rest length [m]."""
    el = np.asarray(elements, dtype=np.int64)
    k = el.shape[1]
    i, j = np.triu_indices(k, 1)
    e = np.unique(np.sort(np.vstack([el[:, [a, b]] for a, b in zip(i, j)]), axis=1), axis=0)
    w = np.linalg.norm(rest[e[:, 0]] - rest[e[:, 1]], axis=1)
    n = len(rest)
    return sp.coo_matrix((np.r_[w, w], (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(n, n)).tocsr()


def _farthest_points(G, n: int, count: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    pick = [int(rng.integers(n))]
    dist = dijkstra(G, indices=pick[0])
    for _ in range(count - 1):
        nxt = int(np.argmax(dist))
        pick.append(nxt)
        dist = np.minimum(dist, dijkstra(G, indices=nxt))
    return np.array(pick)


def place_handles(rest: np.ndarray, elements: np.ndarray, count: int, kept: np.ndarray, *, method: str,
                  displacement: np.ndarray | None = None, seed: int = 0) -> np.ndarray:
    """(count',) vertex indices of the active handles (count' = count when reachable).

    rest : (n, d) [m]; elements : (m, d+1); kept : vertex indices that stay unchanged
    method : "displacement" (needs ``displacement`` (n,) [m]) | "spatial" | "random"
    """
    n = len(rest)
    kept = np.unique(np.asarray(kept, dtype=np.int64))
    free = np.setdiff1d(np.arange(n), kept)
    if count > len(free):
        raise InputError(f"{count} handles asked for but only {len(free)} vertices may move", where="[design] handles")
    if method == "random":
        rng = np.random.default_rng(seed)
        return np.sort(rng.choice(free, size=count, replace=False))
    G = mesh_graph(rest, elements)
    if n > MAX_POINTS:
        sample = _farthest_points(G, n, MAX_POINTS, seed)
    else:
        sample = np.arange(n)
    geo = dijkstra(G, indices=sample)[:, sample]
    if not np.all(np.isfinite(geo)):
        raise InputError("the part's mesh is not connected", where="mesh")
    sg = max(float(geo.max()) / 4.0, 1e-300)
    if method == "displacement":
        if displacement is None:
            raise ValueError("displacement placement needs the vertices' displacements")
        d = np.asarray(displacement, float)[sample]
        sd = max(float(np.std(d)), 1e-300)
        S = -((d[:, None] - d[None, :]) / sd) ** 2 - (geo / sg) ** 2
    elif method == "spatial":
        X = rest[sample]
        S = -np.sum(((X[:, None, :] - X[None, :, :]) / sg) ** 2, axis=-1)
    else:
        raise InputError(f"unknown placement {method!r}", where="[design] placement")
    is_kept = np.isin(sample, kept)
    labels = _cluster_to_count(S, count, is_kept, seed)
    handles = []
    for c in np.unique(labels):
        members = np.flatnonzero(labels == c)
        if is_kept[members].any():
            continue
        X = rest[sample[members]]
        centroid = X.mean(axis=0)
        handles.append(int(sample[members[np.argmin(np.sum((X - centroid) ** 2, axis=1))]]))
    return np.sort(np.array(handles, dtype=np.int64))


def _cluster_to_count(S: np.ndarray, count: int, is_kept: np.ndarray, seed: int) -> np.ndarray:
    """Affinity-propagation labels with the preference bisected so that ``count`` clusters contain
    no kept point (closest achievable count otherwise)."""
    # deferred: scikit-learn costs seconds of start-up (every worker process's) and only the
    # displacement placement needs it
    from sklearn.cluster import AffinityPropagation
    from sklearn.exceptions import ConvergenceWarning

    off = S[~np.eye(len(S), dtype=bool)]
    lo, hi = float(off.min()) * 2.0, float(np.median(off))  # few clusters .. many clusters
    best = None
    for _ in range(BISECTIONS):
        pref = 0.5 * (lo + hi)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            ap = AffinityPropagation(affinity="precomputed", preference=pref, damping=0.7, max_iter=400,
                                     convergence_iter=30, random_state=seed).fit(S)
        labels = ap.labels_
        if labels.min() < 0:  # did not converge: try more clusters
            lo = pref
            continue
        k = sum(1 for c in np.unique(labels) if not is_kept[labels == c].any())
        if best is None or abs(k - count) < abs(best[0] - count):
            best = (k, labels)
        if k == count:
            break
        if k < count:
            lo = pref
        else:
            hi = pref
    if best is None:
        raise InputError("affinity propagation did not converge on this mesh", where="[design] placement")
    return best[1]
