"""IMLS field: accuracy against exact signed distances, derivatives against finite differences,
Warp kernel against a brute-force NumPy evaluation, pose handling and kernel truncation."""

import numpy as np
import pytest
import trimesh

from simfab.contact.imls import build_imls, curve_normals, evaluate_imls, imls_reference
from simfab.rotations import pose_matrix


def _sphere_field(R=0.01):
    m = trimesh.creation.icosphere(subdivisions=4, radius=R)
    v = np.asarray(m.vertices)
    return build_imls(v, v / np.linalg.norm(v, axis=1, keepdims=True), spacing=float(m.edges_unique_length.mean()))


def _random_dirs(rng, k, dim=3):
    d = rng.normal(size=(k, dim))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_sphere_matches_exact_signed_distance():
    # Kolluri's IMLS of a sphere is biased by its curvature: |psi - sdf| = O(sigma^2 / R) near the
    # surface (plus the polyhedral sampling). Bound: sigma^2 / R within 2 sigma of the surface.
    R = 0.01
    f = _sphere_field(R)
    rng = np.random.default_rng(0)
    r = R + rng.uniform(-2, 2, 4000) * f.sigma
    q = _random_dirs(rng, 4000) * r[:, None]
    e = evaluate_imls(f, q)
    assert e.near.all()
    sdf = R - r  # > 0 inside
    assert np.abs(e.psi - sdf).max() <= f.sigma**2 / R
    # sign convention: inside positive, outside negative (beyond the bias)
    far = np.abs(sdf) > f.sigma**2 / R
    assert np.all(np.sign(e.psi[far]) == np.sign(sdf[far]))
    # gradient of a distance: unit length, pointing inward (toward increasing psi)
    g = e.grad / np.linalg.norm(e.grad, axis=1, keepdims=True)
    assert np.all(np.einsum("ij,ij->i", g, -q / r[:, None]) > 0.99)


def test_box_matches_exact_signed_distance():
    # Flat faces are reproduced exactly up to sampling irregularity; edges and corners are rounded
    # over about one kernel width: bounds 0.01 sigma on faces (3 sigma from edges), 1.5 sigma anywhere.
    a = 0.01
    b = trimesh.creation.box([2 * a] * 3)
    pts, fid = trimesh.sample.sample_surface_even(b, 6000, seed=0)
    f = build_imls(pts, b.face_normals[fid])
    rng = np.random.default_rng(1)
    q = rng.uniform(-a - f.sigma, a + f.sigma, (30000, 3))
    qq = np.abs(q) - a
    sdf = -(np.linalg.norm(np.maximum(qq, 0), axis=1) + np.minimum(qq.max(1), 0))
    e = evaluate_imls(f, q)
    near = np.abs(sdf) < f.sigma
    srt = np.sort(np.abs(q), axis=1)
    on_face = srt[:, 1] < a - 3 * f.sigma
    err = np.abs(e.psi - sdf)
    assert near.sum() > 1000 and (near & on_face).sum() > 300
    assert err[near & on_face].max() <= 0.01 * f.sigma
    assert err[near].max() <= 1.5 * f.sigma


def test_circle_2d_matches_exact_distance():
    R = 0.01
    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    v = R * np.c_[np.cos(t), np.sin(t)]
    f = build_imls(v, curve_normals(v))
    rng = np.random.default_rng(2)
    r = R + rng.uniform(-2, 2, 2000) * f.sigma
    q = _random_dirs(rng, 2000, 2) * r[:, None]
    e = evaluate_imls(f, q)
    assert e.grad.shape == (2000, 2) and e.hess.shape == (2000, 2, 2)
    assert np.abs(e.psi - (R - r)).max() <= f.sigma**2 / R


@pytest.mark.parametrize("dim", [2, 3])
def test_gradient_and_hessian_match_finite_differences(dim):
    rng = np.random.default_rng(3 + dim)
    if dim == 3:
        f = _sphere_field()
        ang = rng.uniform(0, 2 * np.pi, 3)
        from scipy.spatial.transform import Rotation

        R = Rotation.from_euler("xyz", ang).as_matrix()
        p = rng.normal(size=3) * 0.01
    else:
        t = np.linspace(0, 2 * np.pi, 60, endpoint=False)
        v = 0.01 * np.c_[np.cos(t), 0.6 * np.sin(t)]
        f = build_imls(v, curve_normals(v))
        a = rng.uniform(0, 2 * np.pi)
        R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
        p = np.r_[rng.normal(size=2) * 0.01, 0]
    # query points near the (posed) surface
    body = f.vertices[rng.integers(0, len(f.vertices), 40)] + rng.normal(size=(40, dim)) * f.sigma
    q = (body @ R[:dim, :dim].T) + p[:dim]
    e = evaluate_imls(f, q, (R, p))
    h = 1e-7
    for a in range(dim):
        dq = np.zeros(dim)
        dq[a] = h
        ep, em = evaluate_imls(f, q + dq, (R, p)), evaluate_imls(f, q - dq, (R, p))
        fd_g = (ep.psi - em.psi) / (2 * h)
        fd_h = (ep.grad - em.grad) / (2 * h)
        assert np.allclose(e.grad[:, a], fd_g, rtol=1e-5, atol=1e-6)
        assert np.allclose(e.hess[:, :, a], fd_h, rtol=1e-4, atol=1e-4 * np.abs(e.hess).max())
    assert np.allclose(e.hess, np.swapaxes(e.hess, 1, 2))


def test_warp_kernel_matches_numpy_reference():
    f = _sphere_field()
    rng = np.random.default_rng(7)
    q = f.vertices[rng.integers(0, len(f.vertices), 300)] + rng.normal(size=(300, 3)) * 2 * f.sigma
    e = evaluate_imls(f, q)
    psi, grad = imls_reference(q, f.vertices, f.normals, f.sigma, f.radius, f.weights)
    assert np.allclose(e.psi[e.near], psi[e.near], rtol=1e-10, atol=1e-14)
    assert np.allclose(e.grad[e.near], grad[e.near], rtol=1e-9, atol=1e-12)
    # within a kernel width of the surface (where contact happens, d_hat << sigma) truncating at
    # 4 sigma is negligible: compare with the untruncated sum
    psi_full, _ = imls_reference(q, f.vertices, f.normals, f.sigma, None, f.weights)
    band = e.near & (np.abs(psi_full) < f.sigma)
    assert band.sum() > 50
    assert np.abs(e.psi[band] - psi_full[band]).max() < 1e-6 * f.sigma


@pytest.mark.parametrize("dim,max_cells", [(3, None), (3, 64), (2, None), (2, 16)])
def test_neighbour_lists_find_every_sample_within_the_radius(monkeypatch, dim, max_cells):
    # The kernel reads only its query point's cell list: every sample within the radius must be in
    # it (psi equal to the brute-force truncated sum) and a point is far exactly when no sample is
    # that close, also beyond the grid and with cells grown past sigma (max_cells).
    import simfab.contact.imls as imls

    if max_cells is not None:
        monkeypatch.setattr(imls, "MAX_CELLS", max_cells)
    rng = np.random.default_rng(11 + dim)
    if dim == 3:  # an elongated box's surface samples: cells differ per axis
        m = trimesh.creation.box(extents=(0.03, 0.01, 0.006)).subdivide().subdivide().subdivide()
        v, n = np.asarray(m.vertices), np.asarray(m.vertex_normals)
    else:
        t = np.linspace(0, 2 * np.pi, 90, endpoint=False)
        v = np.c_[0.02 * np.cos(t), 0.008 * np.sin(t)]
        n = curve_normals(v)
    f = build_imls(v, n)
    lo, hi = v.min(0) - 1.5 * f.radius, v.max(0) + 1.5 * f.radius
    q = np.vstack([rng.uniform(lo, hi, size=(3000, dim)),
                   v[rng.integers(0, len(v), 1000)] + rng.normal(size=(1000, dim)) * f.radius])
    e = evaluate_imls(f, q, hessian=False)
    dist = np.linalg.norm(q[:, None, :] - v[None], axis=2).min(axis=1)
    clear = np.abs(dist - f.radius) > 1e-12 * f.radius  # not on the cut itself
    assert np.array_equal(e.near[clear], dist[clear] < f.radius)
    assert e.near.sum() > 1000 and (~e.near).sum() > 500
    psi, grad = imls_reference(q[e.near], v, n, f.sigma, f.radius, f.weights)
    assert np.allclose(e.psi[e.near], psi, rtol=1e-10, atol=1e-14)
    assert np.allclose(e.grad[e.near], grad, rtol=1e-9, atol=1e-12)


def test_pose_is_a_rigid_transform_of_the_field():
    f = _sphere_field()
    rng = np.random.default_rng(8)
    q = rng.normal(size=(50, 3)) * 0.006
    pos, quat = np.array([0.01, -0.02, 0.005]), np.array([0.9, 0.1, -0.3, 0.2])
    R, p = pose_matrix((pos, quat / np.linalg.norm(quat)))
    e0 = evaluate_imls(f, q)
    e1 = evaluate_imls(f, q @ R.T + p, (pos, quat / np.linalg.norm(quat)))
    assert np.allclose(e1.psi, e0.psi, atol=1e-15)
    assert np.allclose(e1.grad, e0.grad @ R.T, atol=1e-12)


def test_far_points_report_no_neighbours_and_a_safe_distance():
    f = _sphere_field()
    q = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]])  # centre (deep inside) and far outside
    e = evaluate_imls(f, q)
    assert not e.near.any()
    assert np.all(e.psi == -f.far_distance) and np.all(e.grad == 0)
    assert f.far_distance >= 0.5 * f.radius


def test_far_lower_bound_is_a_lower_bound_of_the_distance_outside():
    # Far points outside the sphere (|x| - R = exact distance): the nearest-sample bound never
    # exceeds the true distance, never drops below far_distance, and is sharp far away (within
    # the 2 sigma allowance plus the sample spacing of the exact distance).
    R = 0.01
    f = _sphere_field(R)
    rng = np.random.default_rng(3)
    dirs = _random_dirs(rng, 200)
    r = R + f.radius + rng.uniform(0.0, 5 * R, size=200)
    q = dirs * r[:, None]
    pose = (np.array([0.02, -0.01, 0.005]), np.array([np.cos(0.3), 0.0, np.sin(0.3), 0.0]))
    Rm, p = pose_matrix(pose)
    qw = q @ Rm.T + p  # the same body-frame points seen through O's pose
    e = evaluate_imls(f, qw, pose, hessian=False)
    far = ~e.near
    assert far.sum() > 100
    lb = f.far_lower_bound(qw[far], pose)
    exact = r[far] - R
    assert np.all(lb <= exact + 1e-12)
    assert np.all(lb >= f.far_distance)
    assert np.all(lb >= exact - 2.0 * f.sigma - 1e-12)  # samples lie on the sphere: nearest >= exact


def test_large_evaluations_split_over_two_threads_give_the_same_values(monkeypatch):
    # At PARALLEL_MIN_POINTS points or more the CPU evaluation runs as two launches on two threads
    # (own buffers each); the values must equal the single launch's exactly, with and without
    # Hessians, and a worker-side evaluation (as the coupling objective does) must too.
    import simfab.contact.imls as imls
    from simfab._parallel import submit

    f = _sphere_field()
    rng = np.random.default_rng(3)
    q = _random_dirs(rng, 3000) * (0.01 + rng.uniform(-3, 3, 3000) * f.sigma)[:, None]
    runs = []
    for n_min in (10**9, 1024):
        monkeypatch.setattr(imls, "PARALLEL_MIN_POINTS", n_min)
        runs.append([evaluate_imls(f, q, hessian=h, hessian_band=2 * f.sigma) for h in (True, False)])
        runs.append([submit(evaluate_imls, f, q, hessian=h, hessian_band=2 * f.sigma).result() for h in (True, False)])
    for run in runs[1:]:
        for a, b in zip(runs[0], run):
            for name in ("psi", "grad", "hess", "near"):
                assert np.array_equal(getattr(a, name), getattr(b, name))


@pytest.mark.parametrize("sampling", ["random", "uv-sphere vertices"])
def test_uneven_samples_keep_the_curvature_bound(sampling):
    # Random samples and the vertices of a UV sphere (dense at the poles) are unevenly spread: with
    # the default width (2 mean spacings for uneven samples) and density weights the field keeps
    # the sigma^2 / R bound of even samples within 2 sigma of the surface (at the mean
    # nearest-neighbour distance the random case is 5.9x over it)
    R = 0.01
    rng = np.random.default_rng(11)
    if sampling == "random":
        v = _random_dirs(rng, 3000) * R
    else:
        v = np.asarray(trimesh.creation.uv_sphere(radius=R, count=[40, 40]).vertices)
    f = build_imls(v, v / R)
    assert np.ptp(f.weights) > 0.1  # the samples really are uneven: their weights differ
    r = R + rng.uniform(-2, 2, 4000) * f.sigma
    q = _random_dirs(rng, 4000) * r[:, None]
    e = evaluate_imls(f, q)
    assert e.near.all() and np.abs(e.psi - (R - r)).max() <= f.sigma**2 / R


@pytest.mark.parametrize("dim", [2, 3])
def test_points_beyond_the_kernel_radius_get_the_side_of_the_winding_number(dim):
    # Deep inside a large object (farther from every sample than the kernel radius) a point is
    # inside (psi > 0); as far outside it is outside; both are 'far' (no kernel value)
    R = 0.05
    if dim == 3:
        m = trimesh.creation.icosphere(subdivisions=4, radius=R)
        v = np.asarray(m.vertices)
        f = build_imls(v, v / R, spacing=float(m.edges_unique_length.mean()), area=float(m.area))
    else:
        t = np.linspace(0, 2 * np.pi, 400, endpoint=False)
        v = R * np.c_[np.cos(t), np.sin(t)]
        f = build_imls(v, curve_normals(v))
    rng = np.random.default_rng(5)
    inner = _random_dirs(rng, 200, dim) * rng.uniform(0, R - 2 * f.radius, 200)[:, None]
    outer = _random_dirs(rng, 200, dim) * rng.uniform(R + 2 * f.radius, 3 * R, 200)[:, None]
    e_in, e_out = evaluate_imls(f, inner), evaluate_imls(f, outer)
    assert not e_in.near.any() and not e_out.near.any()
    assert np.all(e_in.psi > 0) and np.all(e_out.psi < 0)
    assert np.all(e_in.psi <= R - np.linalg.norm(inner, axis=1))  # a lower bound of the depth
