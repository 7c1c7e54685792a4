"""Every bundled scene, five seeds: all targets reached, no segment inside an object or sphere."""

import pathlib

import numpy as np
import pytest

from simfab.growth import grow, load_growth_scene

SCENES = pathlib.Path(__file__).resolve().parents[2] / "scenes" / "growth"
SCENE_NAMES = sorted(p.stem for p in SCENES.glob("*.xml"))

SEEDS = range(5)


def test_bundled_scene_list():
    # the examples: phone stand, egg (volume + surface), watch + obstacle, table legs,
    # symmetric, projection (profile), guided progressive
    assert set(SCENE_NAMES) >= {"phone_stand", "egg_holder_volume", "egg_holder_surface", "watch_stand",
                                "table_legs", "symmetric_stand", "projection_stand", "guided_shelf"}


@pytest.mark.parametrize("name", SCENE_NAMES)
def test_targets_reached_and_no_collisions(name, penetrations):
    scene = load_growth_scene(SCENES / f"{name}.xml")
    for seed in SEEDS:
        r = grow(scene, seed=seed)
        s = r.summary()
        assert s["targets_reached"] == s["targets_total"] == len(scene.targets), (seed, s["targets_unreached"])
        assert s["segments"] > 0
        sk = r.skeleton
        # every target has a node exactly on it (v' = t, mirrored targets included)
        for i, t in enumerate(scene.targets):
            on = sk.nodes[sk.target == i]
            assert len(on) and np.min(np.linalg.norm(on - t, axis=1)) < 1e-12, (seed, i)
        # pruning: every leaf is a target (volume/profile) -- no dangling branches
        leaves = np.nonzero((sk.degree() == 1) & (sk.parent >= 0))[0]
        if scene.params.mode != "surface":
            assert np.all(sk.target[leaves] >= 0), seed
        n_bad = penetrations(sk.nodes, sk.edges, sk.on_surface_mask(), list(scene.objects.values()),
                                     scene.sphere_centers, scene.sphere_radii)
        assert n_bad == 0, (seed, n_bad)


def test_same_seed_same_skeleton(scenes_dir):
    a = grow(scenes_dir / "watch_stand.xml", seed=3)
    b = grow(scenes_dir / "watch_stand.xml", seed=3)
    c = grow(scenes_dir / "watch_stand.xml", seed=4)
    for f in ("nodes", "parent", "birth", "target", "radius"):
        assert np.array_equal(getattr(a.skeleton, f), getattr(b.skeleton, f)), f
    assert np.array_equal(a.attractors, b.attractors)
    assert not (len(a.skeleton.nodes) == len(c.skeleton.nodes) and np.allclose(a.skeleton.nodes, c.skeleton.nodes))


def test_obstacle_sphere_is_avoided(scenes_dir):
    """The watch stand's sphere sits where straight growth would go: growth must bend round it."""
    scene = load_growth_scene(scenes_dir / "watch_stand.xml")
    assert len(scene.sphere_radii) == 1
    r = grow(scene, seed=0)
    c, rad = scene.sphere_centers[0], scene.sphere_radii[0]
    h = r.history
    child = np.nonzero(h.parent >= 0)[0]
    p, q = h.nodes[h.parent[child]], h.nodes[child]
    # closest distance of every grown segment (pruned or not) to the centre
    d = q - p
    t = np.clip(np.einsum("ij,ij->i", c - p, d) / np.einsum("ij,ij->i", d, d), 0, 1)
    dist = np.linalg.norm(p + t[:, None] * d - c, axis=1)
    assert dist.min() >= rad * (1 - 1e-9)
    assert sum(rep.collisions_resolved for rep in r.reports) > 0  # avoidance actually happened


def test_surface_mode_touches_the_egg(scenes_dir):
    scene = load_growth_scene(scenes_dir / "egg_holder_surface.xml")
    assert len(scene.targets) == 0  # surface growth needs no targets
    r = grow(scene, seed=1)
    sk = r.skeleton
    egg = scene.objects["egg"]
    leaves = np.nonzero((sk.degree() == 1) & (sk.parent >= 0))[0]
    _, d, _ = egg.nearest.on_surface(sk.nodes[leaves])
    # every kept branch ends on the egg (pruning removed the others)
    assert len(leaves) >= 3
    assert np.all(d < 1e-9)


def test_guided_stages_grow_in_order(scenes_dir):
    scene = load_growth_scene(scenes_dir / "guided_shelf.xml")
    r = grow(scene, seed=0)
    assert len(r.reports) == 3
    births = {}
    sk = r.skeleton
    for name, node in sk.target_nodes().items():
        births[name] = sk.birth[node]
    steps = np.cumsum([rep.steps for rep in r.reports])
    stage_of = {"target_0": 0, "target_1": 0, "target_2": 1, "target_3": 1, "target_4": 2}
    for name, b in births.items():
        st = stage_of[name]
        lo = 0 if st == 0 else steps[st - 1]
        assert lo < b <= steps[st], (name, b, steps)
    # later stages continue from the existing tree: one root, one tree
    assert np.sum(sk.parent < 0) == 1


def test_profile_attractors_lie_on_the_swept_profile(scenes_dir):
    scene = load_growth_scene(scenes_dir / "projection_stand.xml")
    r = grow(scene, seed=0)
    pr = scene.params.profile
    u, v, o = (np.asarray(a) for a in (pr.u, pr.v, pr.origin))
    view = np.cross(u, v)
    A = r.attractors
    depth = (A - o) @ view
    assert np.all(depth >= pr.depth[0] - 1e-12) and np.all(depth <= pr.depth[1] + 1e-12)
    ab = np.column_stack([(A - o) @ u, (A - o) @ v])
    P = np.asarray(pr.points)
    Q = np.roll(P, -1, axis=0)
    # distance of each attractor to the closed profile polyline (in the profile plane)
    seg = Q - P
    t = np.clip(np.einsum("ksj,sj->ks", ab[:, None, :] - P[None], seg) / np.sum(seg * seg, axis=1), 0, 1)
    d = np.linalg.norm(P[None] + t[..., None] * seg[None] - ab[:, None, :], axis=2).min(axis=1)
    assert np.max(d) < 1e-12
    # and the grown structure stays close to that surface (within a couple of branch lengths)
    sk = r.skeleton
    assert np.all(np.abs((sk.nodes - o) @ view) < pr.depth[1] + 3 * r.resolved.branch_length)


def test_a_bundled_scene_loads_by_name_as_in_the_other_areas():
    by_name = load_growth_scene("phone_stand")
    by_path = load_growth_scene(SCENES / "phone_stand.xml")
    assert by_name.path.resolve() == by_path.path.resolve() and by_name.target_names == by_path.target_names
