"""Uniform refinement of simplex meshes (red refinement): every edge is split at its midpoint.

- triangles: each into 4 (three corner triangles and the middle one), h -> h/2, 4x elements;
- tetrahedra: each into 8 (four corner tetrahedra and the inner octahedron cut along its
  shortest diagonal, Bey's rule, which keeps the children's shape quality bounded), 8x elements.

The refined mesh covers exactly the same piecewise-linear domain (the boundary is not smoothed),
so a mesh-convergence study of a given shape - an optimized rest shape that exists only as a
mesh - can be run on it. Vertices 0..n-1 are the old ones; vertex n + e is the midpoint of edge
e of :func:`unique_edges`. Orientation is kept (children of a positive simplex are positive).
"""

from __future__ import annotations

import numpy as np


def unique_edges(elements: np.ndarray) -> np.ndarray:
    """(E, 2) sorted vertex pairs of every edge of the simplices, in lexicographic order."""
    el = np.asarray(elements, dtype=np.int64)
    k = el.shape[1]
    i, j = np.triu_indices(k, 1)
    e = np.sort(np.stack([el[:, i].ravel(), el[:, j].ravel()], axis=1), axis=1)
    return np.unique(e, axis=0)


def subdivide(X: np.ndarray, elements: np.ndarray):
    """Refine (n, d) vertices ``X`` and (m, d+1) simplices once.

    Returns ``(X2 (n + E, d), elements2 (4m | 8m, d+1), edges (E, 2))``: vertex n + e is the
    midpoint of ``edges[e]``.
    """
    X = np.asarray(X, dtype=np.float64)
    el = np.asarray(elements, dtype=np.int64)
    n, k = len(X), el.shape[1]
    edges = unique_edges(el)
    key = edges[:, 0] * n + edges[:, 1]

    def mid(a, b):
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        return n + np.searchsorted(key, lo * n + hi)

    X2 = np.vstack([X, 0.5 * (X[edges[:, 0]] + X[edges[:, 1]])])
    if k == 3:
        a, b, c = el.T
        ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
        children = [(a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)]
    elif k == 4:
        a, b, c, d = el.T
        ab, ac, ad, bc, bd, cd = mid(a, b), mid(a, c), mid(a, d), mid(b, c), mid(b, d), mid(c, d)
        children = [(a, ab, ac, ad), (ab, b, bc, bd), (ac, bc, c, cd), (ad, bd, cd, d)]
        # the octahedron ab ac ad bc bd cd: cut along the shortest of its three diagonals
        diag = np.stack([np.linalg.norm(X2[p] - X2[q], axis=1) for p, q in ((ab, cd), (ac, bd), (ad, bc))], axis=1)
        pick = np.argmin(diag, axis=1)
        # the four tetrahedra around each diagonal (p, q), the ring of the other four vertices in order
        rings = {0: (ab, cd, (ac, ad, bd, bc)), 1: (ac, bd, (ab, ad, cd, bc)), 2: (ad, bc, (ab, ac, cd, bd))}
        inner = [np.empty((len(el), 4), np.int64) for _ in range(4)]
        for c_, (p, q, ring) in rings.items():
            sel = pick == c_
            for t in range(4):
                inner[t][sel] = np.stack([p, q, ring[t], ring[(t + 1) % 4]], axis=1)[sel]
        children += [tuple(x.T) for x in inner]
    else:
        raise ValueError(f"simplices with {k} vertices: expected triangles (3) or tetrahedra (4)")
    el2 = np.concatenate([np.stack(ch, axis=1) for ch in children])
    _orient(X2, el2)
    return X2, el2, edges


def _orient(X: np.ndarray, el: np.ndarray) -> None:
    """Swap two vertices of every negatively oriented simplex in place."""
    p = X[el]
    D = p[:, 1:, :] - p[:, :1, :]
    neg = np.linalg.det(np.swapaxes(D, 1, 2)) < 0
    el[neg, 1], el[neg, 2] = el[neg, 2], el[neg, 1].copy()


def midpoint_mask(mask: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Extend a per-vertex boolean ``mask`` (n,) to the refined mesh: a midpoint is in it when both
    ends of its edge are (n + E,)."""
    mask = np.asarray(mask, bool)
    return np.concatenate([mask, mask[edges[:, 0]] & mask[edges[:, 1]]])
