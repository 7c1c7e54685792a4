"""FemModel construction (validation, orientation, boundary) and fixed-pattern assembly."""

import numpy as np
import pytest
from _fem_meshes import box_tet, rect_tri

from simfab.errors import InputError
from simfab.fem.assembly import HessianPattern
from simfab.fem.materials import PLA, VEROWHITE, Material, material_by_name
from simfab.fem.model import make_model


def test_materials_lame_and_lookup():
    mu, lam = PLA.lame()
    E, nu = PLA.youngs_modulus, PLA.poisson_ratio
    # inverse relations: E = mu (3 lam + 2 mu) / (lam + mu), nu = lam / (2 (lam + mu))
    assert mu * (3 * lam + 2 * mu) / (lam + mu) == pytest.approx(E, rel=1e-14)
    assert lam / (2 * (lam + mu)) == pytest.approx(nu, rel=1e-14)
    assert material_by_name("verowhite") is VEROWHITE
    assert VEROWHITE.yield_stress == pytest.approx(60e6, rel=0.2)
    with pytest.raises(InputError, match="unknown material 'steel'"):
        material_by_name("steel")
    with pytest.raises(InputError, match="poisson_ratio"):
        Material(name="x", youngs_modulus=1.0, poisson_ratio=0.5, yield_stress=1.0, density=1.0)
    with pytest.raises(InputError, match="youngs_modulus"):
        Material(name="x", youngs_modulus=-1.0, poisson_ratio=0.3, yield_stress=1.0, density=1.0)


def test_model_2d_reorients_and_computes_volumes():
    P, T = rect_tri(2.0, 1.0, 4, 2)
    T = T.copy()
    T[::3] = T[::3][:, [0, 2, 1]]  # flip a third of them
    m = make_model(P, T, PLA, thickness=0.01)
    assert m.dim == 2 and m.elements.dtype == np.int32
    e = m.rest[m.elements]
    cross = (e[:, 1, 0] - e[:, 0, 0]) * (e[:, 2, 1] - e[:, 0, 1]) - (e[:, 1, 1] - e[:, 0, 1]) * (e[:, 2, 0] - e[:, 0, 0])
    assert np.all(cross > 0)
    assert m.volume.sum() == pytest.approx(2.0 * 1.0 * 0.01, rel=1e-12)
    np.testing.assert_allclose(np.linalg.inv(m.Dm_inv) @ m.Dm_inv, np.broadcast_to(np.eye(2), m.Dm_inv.shape),
                               atol=1e-12)
    mu, lam = PLA.lame()
    assert np.all(m.mu == mu) and np.all(m.lam == lam)


def test_boundary_2d_outward_and_closed():
    P, T = rect_tri(2.0, 1.0, 4, 3)
    m = make_model(P, T, PLA)
    a, b = m.rest[m.boundary_facets[:, 0]], m.rest[m.boundary_facets[:, 1]]
    # every boundary edge lies on the rectangle's outline; outward normal (dy, -dx) points away
    mid = (a + b) / 2
    normal = np.c_[b[:, 1] - a[:, 1], -(b[:, 0] - a[:, 0])]
    assert np.all(np.einsum("ij,ij->i", normal, mid - [1.0, 0.5]) > 0)
    # perimeter, and area by the shoelace formula over the oriented boundary
    assert np.linalg.norm(b - a, axis=1).sum() == pytest.approx(6.0, rel=1e-12)
    assert 0.5 * np.sum(a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]) == pytest.approx(2.0, rel=1e-12)
    on_outline = (np.isclose(m.rest[:, 0], 0) | np.isclose(m.rest[:, 0], 2) | np.isclose(m.rest[:, 1], 0)
                  | np.isclose(m.rest[:, 1], 1))
    np.testing.assert_array_equal(m.boundary_vertices, np.flatnonzero(on_outline))


def test_boundary_3d_outward_closed_surface():
    P, T = box_tet(1.0, 0.5, 0.25, 3, 2, 2)
    m = make_model(P, T, PLA)
    f = m.rest[m.boundary_facets]
    area_vec = 0.5 * np.cross(f[:, 1] - f[:, 0], f[:, 2] - f[:, 0])
    np.testing.assert_allclose(area_vec.sum(0), 0, atol=1e-14)  # closed surface
    # divergence theorem: enclosed volume from the outward surface equals the sum of tet volumes
    vol = np.einsum("ij,ij->i", f[:, 0], np.cross(f[:, 1], f[:, 2])).sum() / 6
    assert vol == pytest.approx(m.volume.sum(), rel=1e-12)
    assert m.volume.sum() == pytest.approx(0.125, rel=1e-12)
    assert np.abs(area_vec).sum() == pytest.approx(2 * (0.5 + 0.25 + 0.125), rel=1e-12)


@pytest.mark.parametrize(
    "points, elements, match",
    [
        (np.eye(3)[:, :2], [[0, 1, 3]], "out of range"),
        (np.r_[np.eye(3)[:, :2], [[5.0, 5.0]]], [[0, 1, 2]], "not used"),
        (np.array([[0, 0], [1, 0], [2, 0.0]]), [[0, 1, 2]], "degenerate"),
        (np.array([[0, 0], [1, 0], [0, np.nan]]), [[0, 1, 2]], "NaN"),
        (np.array([[0, 0], [1, 0], [0, 1.0]]), [[0, 1, 1]], "repeats"),
        (np.array([[0, 0], [1, 0], [0, 1.0]]), [[0, 1, 2, 0]], r"\(m, 3\)"),
        (np.zeros((3, 4)), [[0, 1, 2]], "points must be"),
    ],
)
def test_make_model_rejects_bad_meshes(points, elements, match):
    with pytest.raises(InputError, match=match):
        make_model(points, elements, PLA)


def test_pattern_assembles_like_dense_scatter_and_block_slots():
    rng = np.random.default_rng(0)
    P, T = box_tet(1, 1, 1, 2, 1, 1)
    pat = HessianPattern(T, len(P), 3)
    blocks = rng.standard_normal((len(T), 12, 12))
    H = pat.assemble(blocks)
    ref = np.zeros(pat.shape)
    for e, el in enumerate(T):
        dofs = (el[:, None] * 3 + np.arange(3)).ravel()
        ref[np.ix_(dofs, dofs)] += blocks[e]
    np.testing.assert_allclose(H.toarray(), ref, atol=1e-12)
    assert H.nnz == pat.nnz
    # the structure is exactly the nonzero block pattern (no dense fill)
    assert pat.nnz == np.count_nonzero(np.abs(ref) > 0)
    # slots address entries of the data array
    rows, cols = T[0, [0, 1, 2]], T[0, [3, 3, 0]]
    slots = pat.block_slots(rows, cols)
    data = H.data
    for i in range(3):
        np.testing.assert_array_equal(data[slots[i]], ref[rows[i] * 3:rows[i] * 3 + 3, cols[i] * 3:cols[i] * 3 + 3])
    # a pair that shares no element is not in the pattern
    far = [int(np.argmin(P.sum(1))), int(np.argmax(P.sum(1)))]
    with pytest.raises(ValueError, match="not in the Hessian pattern"):
        pat.block_slots([far[0]], [far[1]])
    # diagonal blocks always exist
    assert pat.block_slots(np.arange(len(P)), np.arange(len(P))).shape == (len(P), 3, 3)


def test_make_model_accepts_material_names():
    m = make_model(np.vstack([np.zeros(2), np.eye(2)]), [[0, 1, 2]], "pla")
    assert m.material is PLA
    with pytest.raises(InputError, match="unknown material"):
        make_model(np.vstack([np.zeros(2), np.eye(2)]), [[0, 1, 2]], "unobtainium")


def test_model_pickles_without_device_cache():
    import pickle

    from simfab.fem import elastic as nh

    P, T = box_tet(1.0, 0.5, 0.5, 2, 1, 1)
    m = make_model(P, T, PLA)
    x = m.rest * 1.01
    E, g, H = nh.energy_gradient_hessian(m, x)  # fills the cache with Warp buffers
    m2 = pickle.loads(pickle.dumps(m))
    E2, g2, H2 = nh.energy_gradient_hessian(m2, x)
    assert E2 == E
    np.testing.assert_array_equal(g2, g)
    np.testing.assert_array_equal(H2.toarray(), H.toarray())
    assert not m2.rest.flags.writeable
