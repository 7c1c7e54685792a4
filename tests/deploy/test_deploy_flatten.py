"""Boundary First Flattening against closed-form results (simfab.deploy.flatten)."""

import numpy as np
import pytest

from simfab.deploy import flatten, surface
from simfab.errors import InputError


def _cap_error(rings, R=1.0, theta0=np.radians(60)):
    t = surface.spherical_cap(R, theta0, rings)
    f = flatten.flatten(t.V, t.F)
    theta = np.arccos(np.clip((t.V[:, 2] + R) / R, -1, 1))
    # conformal map of the cap to a disk (stereographic projection, scaled so u = 0 on the rim):
    # e^u = cos^2(theta0/2) / cos^2(theta/2)
    exact = 2.0 * np.log(np.cos(theta0 / 2) / np.cos(theta / 2))
    h = theta0 * R / rings  # ring spacing [m]
    return t, f, float(np.max(np.abs(f.u - exact))), h


def test_spherical_cap_scale_factor_converges_second_order():
    errs = []
    for rings in (8, 16, 32):
        _, f, err, h = _cap_error(rings)
        # discretization-dependent tolerance: the cotan Laplacian is O(h^2) accurate
        assert err <= 0.5 * (h / 1.0) ** 2, (rings, err, h)
        errs.append(err)
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(orders > 1.8), orders


def test_cap_boundary_lengths_kept_and_flat_radius():
    R, th0 = 0.15, np.radians(50)
    t, f, _, _ = _cap_error(16, R, th0)
    Vb, Ub = t.V[f.boundary], f.uv[f.boundary]
    l3 = np.linalg.norm(np.roll(Vb, -1, axis=0) - Vb, axis=1)
    l2 = np.linalg.norm(np.roll(Ub, -1, axis=0) - Ub, axis=1)
    assert np.max(np.abs(l2 - l3)) <= 1e-12 * R  # round-off
    assert np.all(np.abs(f.u[f.boundary]) == 0.0)
    assert np.all(f.u[f.interior] < 0)  # a cap only shrinks
    # the flat disk's radius is R sin(theta0) (the rim circle is kept)
    r = np.linalg.norm(f.uv[f.boundary] - f.uv[f.boundary].mean(axis=0), axis=1)
    assert np.allclose(r, R * np.sin(th0), rtol=2e-3)
    assert np.all(flatten.face_areas(f.uv, t.F) > 0)  # no flipped triangles


def test_cylinder_patch_is_developable():
    t = surface.cylinder(0.1, np.radians(120), 0.2, 20)  # jittered Delaunay mesh, h ~ 0.01 m
    f = flatten.flatten(t.V, t.F)
    h = 0.2 / 20
    assert np.max(np.abs(f.u)) < 0.1 * (h / 0.1) ** 2  # O(h^2 / R^2) angle defects only
    assert np.max(np.abs(f.sigma)) < 1e-3
    # isometric: every edge keeps its length
    e = np.concatenate([t.F[:, [0, 1]], t.F[:, [1, 2]], t.F[:, [2, 0]]])
    l3 = np.linalg.norm(t.V[e[:, 0]] - t.V[e[:, 1]], axis=1)
    l2 = np.linalg.norm(f.uv[e[:, 0]] - f.uv[e[:, 1]], axis=1)
    assert np.max(np.abs(l2 / l3 - 1)) < 1e-3


def test_saddle_only_grows():
    t = surface.procedural("saddle", dict(disk_radius=0.1, curvature_radius=0.15, rings=12))
    f = flatten.flatten(t.V, t.F)
    assert np.all(f.u[f.interior] > 0)


def test_rejects_non_disk_meshes():
    import trimesh

    sph = trimesh.creation.icosphere(subdivisions=1)
    with pytest.raises(InputError, match="no boundary"):
        surface.validate(sph.vertices, sph.faces, where="sphere.obj")
    ann = trimesh.creation.annulus(r_min=0.5, r_max=1.0, height=0.1)
    top = ann.faces[np.all(ann.vertices[ann.faces][:, :, 2] > 0, axis=1)]
    with pytest.raises(InputError, match="boundary loop|not a disk"):
        surface.validate(ann.vertices, top, where="annulus.obj")
    P, F = surface.disk_mesh(1.0, 3)
    V = np.column_stack([P, np.zeros(len(P))])
    V[F[0, 1]] = V[F[0, 0]]  # collapse a triangle
    with pytest.raises(InputError, match="degenerate"):
        surface.validate(V, F, where="bad.obj")
