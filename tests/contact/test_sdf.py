"""Exact signed distance of primitive objects: each primitive's field against an independent
distance (to 400k points on its exact surface) and an independent inside test, derivatives
against finite differences, and the union of several."""

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from simfab.contact.sdf import (
    Primitive,
    PrimitiveField,
    build_primitive_field,
    primitive_surface_samples,
    section_primitives,
)

SIZES = {"sphere": (0.01,), "capsule": (0.004, 0.01), "cylinder": (0.01, 0.006), "box": (0.01, 0.004, 0.007),
         "torus": (0.01, 0.003)}


def _inside_local(kind, size, q):
    if kind == "sphere":
        return np.linalg.norm(q, axis=1) < size[0]
    if kind == "capsule":
        p = q.copy()
        p[:, 2] -= np.clip(q[:, 2], -size[1], size[1])
        return np.linalg.norm(p, axis=1) < size[0]
    if kind == "cylinder":
        return (np.hypot(q[:, 0], q[:, 1]) < size[0]) & (np.abs(q[:, 2]) < size[1])
    if kind == "torus":
        return np.hypot(np.hypot(q[:, 0], q[:, 1]) - size[0], q[:, 2]) < size[1]
    return np.all(np.abs(q) < np.asarray(size), axis=1)


@pytest.mark.parametrize("kind", sorted(SIZES))
def test_primitive_field_is_its_exact_signed_distance(kind):
    rng = np.random.default_rng(hash(kind) % 2**32)
    Q = Rotation.from_euler("xyz", rng.uniform(0, 3, 3)).as_matrix()
    prim = Primitive(kind=kind, size=SIZES[kind], centre=np.array([0.002, -0.001, 0.003]), rotation=Q)
    f = build_primitive_field((prim,), 3, 500)
    dense, _ = primitive_surface_samples((prim,), 400_000, 3)
    spacing = np.sqrt(prim.area() / len(dense))
    q = prim.centre + rng.uniform(-1.6, 1.6, (3000, 3)) * max(SIZES[kind])
    e = f.evaluate(q)
    ref = cKDTree(dense).query(q)[0]
    inside = _inside_local(kind, SIZES[kind], (q - prim.centre) @ Q)
    # |psi| is the distance to the surface: within the dense samples' spacing of the distance to
    # the nearest of them (which can only overestimate it); the sign is the side
    assert np.all(np.abs(e.psi) <= ref + 1e-12) and np.all(ref - np.abs(e.psi) <= spacing)
    assert np.array_equal(e.psi > 0, inside)
    # derivatives against central differences
    h = 1e-7
    for a in range(3):
        d = np.zeros(3)
        d[a] = h
        ep, em = f.evaluate(q + d), f.evaluate(q - d)
        smooth = np.abs(ep.psi - em.psi - 2 * h * e.grad[:, a]) < 1e-3 * h  # skip points on kinks
        assert smooth.mean() > 0.97
        fd_h = (ep.grad - em.grad) / (2 * h)  # (k, 3): column a of the Hessian
        # (the Hessian jumps where the nearest feature changes, e.g. a capsule's cylinder to its cap)
        ok = np.all(np.abs(fd_h - e.hess[:, :, a]) <= 1e-3 / min(SIZES[kind]), axis=1)
        assert ok[smooth].mean() > 0.97
    # surface samples: on the surface with exact normals
    es = f.evaluate(f.vertices)
    assert np.abs(es.psi).max() < 1e-15 and np.allclose(-es.grad, f.normals, atol=1e-12)


def test_union_and_2d_section():
    a = Primitive(kind="sphere", size=(0.01,), centre=np.zeros(3), rotation=np.eye(3))
    b = Primitive(kind="box", size=(0.02, 0.003, 0.003), centre=np.zeros(3), rotation=np.eye(3))
    f = PrimitiveField(primitives=(a, b), dim=3, vertices=np.zeros((1, 3)), normals=np.zeros((1, 3)), sigma=1e-3)
    q = np.array([[0.015, 0, 0], [0, 0.015, 0], [0.0, 0.0, 0.0]])
    assert np.allclose(f.evaluate(q).psi, [0.003, -0.005, 0.01])  # the box is the shallower inside at x = 15 mm
    # a cylinder along z crossing z = 0 is a circle of its radius in 2D
    cyl = Primitive(kind="cylinder", size=(0.01, 0.01), centre=np.zeros(3), rotation=np.eye(3))
    f2 = build_primitive_field(section_primitives((cyl,)), 2, 50)
    x = np.array([[0.012, 0.0], [0.0, 0.005]])
    e = f2.evaluate(x)
    assert np.allclose(e.psi, [-0.002, 0.005]) and e.grad.shape == (2, 2)
    tilted = Primitive(kind="cylinder", size=(0.01, 0.01), centre=np.zeros(3),
                       rotation=Rotation.from_euler("x", 0.3).as_matrix())
    assert section_primitives((tilted,)) is None  # its section is an ellipse: sampled instead


def test_bundled_cylinder_scenes_use_the_exact_distance():
    from simfab.contact.sdf import PrimitiveField as PF
    from simfab.coupling.scene import load_coupling_scene

    cm = load_coupling_scene("cclamp2d")
    assert isinstance(cm.field, PF)
    R, p = cm.pose(0.0)
    y = np.array([[p[0] + 0.01, 0.0]])  # on the 10 mm cylinder's surface
    assert abs(cm.field.evaluate(y, (R, p)).psi[0]) < 1e-15



def test_torus_plugin_geom_is_an_exact_torus(tmp_path):
    """An SDF geom of MuJoCo's torus plugin (MJCF has no torus geom) is read as an exact torus,
    posed by its geom pos/quat, and meshed for display on its surface."""
    import mujoco

    from simfab.contact.sdf import primitives_of_body
    from simfab.io.mjcf import MJCFBuilder, load_mjcf

    R, r = 0.02, 0.003
    b = MJCFBuilder("ring")
    b.sdf_asset("ring", "mujoco.sdf.torus", radius1=R, radius2=r)
    o = b.body("object", pos=[0.001, 0, 0], mocap=True)
    b.geom(o, sdf="ring", pos=[R, 0, 0], quat=[np.sqrt(0.5), np.sqrt(0.5), 0, 0], contype=0, conaffinity=0)
    sc = load_mjcf(b.save(tmp_path / "ring.xml"))
    bid = mujoco.mj_name2id(sc.model, mujoco.mjtObj.mjOBJ_BODY, "object")
    (prim,) = primitives_of_body(sc.model, bid, sc.sdf_plugins)
    assert prim.kind == "torus" and prim.size == (R, r)
    f = build_primitive_field((prim,), 3, 500)
    # body frame: the ring lies in the x-z plane (axis y) around (R, 0, 0); its bar crosses the origin
    q = np.array([[0.0, 0.0, 0.0], [-r, 0.0, 0.0], [R, 0.0, 0.0], [2 * R + r + 0.001, 0.0, 0.0], [R, 0.0, R]])
    assert np.allclose(f.evaluate(q).psi, [r, 0.0, r - R, -0.001, r], atol=1e-15)
    mesh = sc.body_meshes()["object"]  # world frame: the body sits at x = 1 mm
    v = mesh.vertices - [0.001 + R, 0, 0]
    assert np.allclose(np.hypot(np.hypot(v[:, 0], v[:, 2]) - R, v[:, 1]), r, atol=1e-9)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("turned", [False, True])
def test_single_primitive_evaluation_matches_the_union_route(dim, turned):
    """A field of one primitive takes its own route (the pose as given, the body frame padded in
    place, no world rotation for an unrotated O, the box's sign and inside tests in one call each);
    the union route transforms every frame separately. A second box far away (never the largest
    psi) makes the same field go through the union route: both give the same psi, gradient and
    Hessian, at points outside, on the faces and inside the box, for an unrotated and a turned O."""
    rng = np.random.default_rng(7 + dim + 2 * turned)
    Q = Rotation.from_euler("z", 0.52).as_matrix()  # (a 2D section needs the box's z axis kept)
    box = Primitive(kind="box", size=(0.01, 0.004, 0.007 if dim == 3 else np.inf),
                    centre=np.array([0.001, -0.002, 0.0]), rotation=Q)
    far = Primitive(kind="box", size=(0.001, 0.001, 0.001), centre=np.array([5.0, 5.0, 0.0]), rotation=np.eye(3))
    one = PrimitiveField(primitives=(box,), dim=dim, vertices=np.zeros((1, dim)), normals=np.zeros((1, dim)),
                         sigma=1e-4)
    two = PrimitiveField(primitives=(box, far), dim=dim, vertices=np.zeros((1, dim)), normals=np.zeros((1, dim)),
                         sigma=1e-4)
    R = Rotation.from_euler("z", 0.3).as_matrix() if turned else np.eye(3)
    pose = (R, np.array([0.003, 0.001, 0.0]))
    # world points: around the box, inside it, and on its faces (local |q_x| = e_x)
    local = rng.uniform(-0.02, 0.02, (200, 3)) * np.array([1, 1, dim == 3])
    local = np.vstack([local, rng.uniform(-0.003, 0.003, (20, 3)) * np.array([1, 1, dim == 3]),
                       np.c_[np.full(10, 0.01), rng.uniform(-0.003, 0.003, (10, 2)) * np.array([1, dim == 3])]])
    world = ((local @ Q.T + box.centre) @ R.T + pose[1])[:, :dim]
    for hessian in (False, True):
        a = one.evaluate(world, pose, hessian=hessian, hessian_band=0.004)
        b = two.evaluate(world, pose, hessian=hessian, hessian_band=0.004)
        assert (a.psi > 0).sum() >= 20  # points inside are tested
        np.testing.assert_allclose(a.psi, b.psi, rtol=0, atol=1e-15)
        np.testing.assert_allclose(a.grad, b.grad, rtol=0, atol=1e-13)
        np.testing.assert_allclose(a.hess, b.hess, rtol=0, atol=1e-9)  # [1/m]: |hess| up to ~1e3
        assert a.near.all() and a.grad.shape == (len(world), dim) and a.hess.shape == (len(world), dim, dim)
