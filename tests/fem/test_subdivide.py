"""Uniform (red) refinement of triangle and tetrahedron meshes (simfab.fem.subdivide)."""

import numpy as np
import pytest

from simfab.fem.subdivide import midpoint_mask, subdivide


def _measure(X, el):
    p = X[el]
    D = np.swapaxes(p[:, 1:, :] - p[:, :1, :], 1, 2)
    return np.linalg.det(D) / (2.0 if el.shape[1] == 3 else 6.0)


def _boundary_facets(el):
    k = el.shape[1]
    f = np.sort(np.concatenate([np.delete(el, i, axis=1) for i in range(k)]), axis=1)
    u, c = np.unique(f, axis=0, return_counts=True)
    assert c.max() <= 2  # conforming: an interior facet has exactly two simplices
    return u[c == 1]


@pytest.mark.parametrize("dim", [2, 3])
def test_refinement_conforms_keeps_the_domain_and_bounds_quality(dim):
    from scipy.spatial import Delaunay

    P = np.random.default_rng(0).random((40, dim))
    el = Delaunay(P).simplices
    vol = _measure(P, el)
    el[vol < 0, 1], el[vol < 0, 2] = el[vol < 0, 2], el[vol < 0, 1].copy()
    X2, el2, edges = subdivide(P, el)
    ratio = 4 if dim == 2 else 8
    assert len(el2) == ratio * len(el)
    assert np.array_equal(X2[: len(P)], P)  # old vertices first, unchanged
    assert np.allclose(X2[len(P) + 3], P[edges[3]].mean(axis=0))
    v2 = _measure(X2, el2)
    assert v2.min() > 0  # orientation kept
    assert np.isclose(v2.sum(), np.abs(_measure(P, el)).sum(), rtol=1e-12)  # same domain
    # each boundary facet becomes 2^(dim-1) facets: the boundary is split, not changed
    assert len(_boundary_facets(el2)) == 2 ** (dim - 1) * len(_boundary_facets(el))
    if dim == 3:  # corner children are similar to the parent (1/8 of its volume)
        assert np.allclose(v2[: len(el)], np.abs(_measure(P, el)) / 8)


def test_midpoint_mask():
    edges = np.array([[0, 1], [1, 2], [0, 2]])
    m = midpoint_mask(np.array([True, True, False]), edges)
    assert m.tolist() == [True, True, False, True, False, False]
