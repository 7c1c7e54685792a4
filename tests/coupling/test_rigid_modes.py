"""Rigid motions of the compliant part that neither supports nor contact resist: found, named and
reported (a frictionless clip on a cylinder slides along its axis; a claw on a sphere turns)."""

from types import SimpleNamespace

import numpy as np

from simfab.coupling import rigid


def _held_part(dim, held_axes):
    # a block of vertices whose x = 0 face is held along ``held_axes``
    g = np.stack(np.meshgrid(*[np.linspace(0, 1, 3)] * dim, indexing="ij"), -1).reshape(-1, dim)
    free = np.ones((len(g), dim), bool)
    free[np.ix_(np.flatnonzero(g[:, 0] == 0), held_axes)] = False
    return SimpleNamespace(fem=SimpleNamespace(rest=g), dim=dim, free=free.ravel())


def test_motions_left_free_by_the_supports():
    # held along x on a face spanning y and z: free are the translations along y and z and the
    # rotation about x (3 of 6); held along x and z: translation along y only; 2D held along x:
    # translation along y
    for dim, held, k in ((3, [0], 3), (3, [0, 2], 1), (3, [0, 1, 2], 0), (2, [0], 1)):
        cm = _held_part(dim, held)
        Q, c = rigid.motion_basis(cm)
        assert Q.shape[1] == k
        if k:
            u = rigid.point_motions(cm.fem.rest - c, dim) @ Q  # (p, dim, k)
            held_mask = ~cm.free.reshape(-1, dim)
            assert np.abs(u[held_mask]).max() < 1e-12


def test_weakest_motion_of_contact_on_a_cylinder_and_a_sphere():
    rng = np.random.default_rng(0)
    Q, c = np.eye(6), np.zeros(3)
    # cylinder around z: radial normals resist everything but sliding along z and turning about z
    t = rng.uniform(0, 2 * np.pi, 200)
    y = np.c_[np.cos(t), np.sin(t), rng.uniform(-1, 1, 200)]
    n = np.c_[np.cos(t), np.sin(t), np.zeros(200)]
    ratio, q = rigid.weakest_motion(Q, c, y, n, np.ones(200))
    assert ratio < 1e-12 and np.linalg.norm(q[[0, 1, 3, 4]]) < 1e-9 * np.linalg.norm(q)
    # full sphere: radial normals do not resist rotations about its centre
    y = rng.normal(size=(300, 3))
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    ratio, q = rigid.weakest_motion(Q, c, y, y, np.ones(300))
    assert ratio < 1e-12 and rigid.describe(q, 3, 1.0).startswith("rotation")
    # half space below z = 0 pushing up: translations along x, y and rotation about z are free,
    # but with the supports holding x and y only the rotation about z remains to be flagged
    y = np.c_[rng.uniform(-1, 1, (100, 2)), np.zeros(100)]
    n = np.tile([0.0, 0.0, 1.0], (100, 1))
    Qz = np.zeros((6, 2))
    Qz[2, 0] = Qz[5, 1] = 1.0  # free: translation along z, rotation about z
    ratio, q = rigid.weakest_motion(Qz, c, y, n, np.ones(100))
    assert ratio < 1e-12 and rigid.describe(q, 3, 1.0) == "rotation about z"
    assert rigid.weakest_motion(Qz, c, y, n, np.zeros(100)) is None  # no contact, nothing to say
