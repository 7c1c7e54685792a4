"""Bounded biharmonic weights and linear blend skinning (simfab.design.handles)."""

import numpy as np
import pytest

from simfab.design.handles import make_handles
from simfab.fem.meshing import triangulate_polygon


@pytest.fixture(scope="module")
def plate():
    outline = np.array([[0, 0], [0.04, 0], [0.04, 0.01], [0, 0.01]], float)
    V, F = triangulate_polygon(outline, max_area=4e-6)
    fixed = np.flatnonzero(V[:, 0] < 1e-9)
    far = [int(np.argmin(np.sum((V - p) ** 2, axis=1))) for p in ([0.02, 0.005], [0.04, 0.0], [0.04, 0.01])]
    return V, F, fixed, far


def test_weights_partition_of_unity_bounds_and_interpolation(plate):
    V, F, fixed, hv = plate
    H = make_handles(V, F, hv, [fixed])
    W = H.weights
    assert W.shape == (len(V), 4)
    np.testing.assert_allclose(W.sum(axis=1), 1.0, atol=1e-12)
    assert W.min() >= 0.0 and W.max() <= 1.0
    np.testing.assert_allclose(W[hv, :3], np.eye(3), atol=1e-12)  # w_j = 1 at handle j, 0 at the others
    np.testing.assert_allclose(W[fixed, 3], 1.0, atol=1e-12)  # the kept region belongs to its inactive handle
    # smooth and local: handle 0's weight decays away from it (far end vs handle)
    assert W[hv[1], 0] == 0.0 and 0.0 < np.median(W[:, 0]) < 1.0


def test_identity_reproduces_mesh_exactly_and_matrix_form_agrees(plate):
    V, F, fixed, hv = plate
    H = make_handles(V, F, hv, [fixed])
    h0 = H.identity()
    assert np.abs(H.apply(h0) - V).max() < 1e-15
    rng = np.random.default_rng(3)
    h = h0 + rng.normal(scale=[1e-3, 1e-3, 0.1, 0.1] * 3)
    # X' = M_LBS T (thesis form) equals the factored evaluation
    np.testing.assert_allclose(H.lbs_matrix() @ H.transform_stack(h), H.apply(h), atol=1e-15)
    X = H.apply(h)
    assert np.abs(X[fixed] - V[fixed]).max() < 1e-15  # inactive handles never move their region
    t, s = H.split(h)
    np.testing.assert_allclose(X[hv], V[hv] + t, atol=1e-15)  # handle vertices follow their translation


def test_handle_in_kept_region_is_refused(plate):
    from simfab.errors import InputError

    V, F, fixed, hv = plate
    with pytest.raises(InputError):
        make_handles(V, F, [int(fixed[0])], [fixed])


def test_tetrahedral_weights():
    import trimesh

    from simfab.fem.meshing import tetrahedralize

    box = trimesh.creation.box(extents=[0.03, 0.01, 0.01])
    V, T = tetrahedralize(np.asarray(box.vertices), np.asarray(box.faces), target_tets=800)
    fixed = np.flatnonzero(V[:, 0] < V[:, 0].min() + 1e-9)
    hv = [int(np.argmax(V[:, 0])), int(np.argmin(np.sum((V - [0.0, 0.005, 0.005]) ** 2, axis=1)))]
    H = make_handles(V, T, hv, [fixed])
    np.testing.assert_allclose(H.weights.sum(axis=1), 1.0, atol=1e-12)
    assert H.weights.min() >= 0 and H.weights.max() <= 1
    assert np.abs(H.apply(H.identity()) - V).max() < 1e-15


def test_overlapping_kept_regions_are_merged(plate):
    """The fixed support and a keep site may share vertices; each vertex is constrained once."""
    V, F, fixed, hv = plate
    keep = np.flatnonzero(V[:, 0] < 0.008)  # contains the fixed edge x = 0
    H = make_handles(V, F, hv, [fixed, keep])
    np.testing.assert_allclose(H.weights.sum(axis=1), 1.0, atol=1e-12)
    X = H.apply(H.identity() + 0.001)
    assert np.abs(X[keep] - V[keep]).max() < 1e-15
