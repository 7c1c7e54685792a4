"""MJCF scenes: keyframe trajectories against analytic interpolation, builder round trip."""

import numpy as np
import pytest
import trimesh

from simfab.errors import InputError
from simfab.io.mjcf import MJCFBuilder, Trajectory, load_mjcf
from simfab.rotations import quat_angle, quat_slerp, quat_to_matrix


def _axis_angle_quat(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])


@pytest.fixture
def scene_path(tmp_path):
    b = MJCFBuilder("traj")
    b.floor()
    ball = trimesh.creation.icosphere(subdivisions=1, radius=0.05)
    b.mesh_asset("ball", ball.vertices, ball.faces)
    obj = b.body("object", pos=[0, 0, 0.3], mocap=True)
    b.geom(obj, type="mesh", mesh="ball", contype=0, conaffinity=0)
    part = b.body("part", pos=[0, 0, 0.05])
    b.geom(part, type="box", size=[0.1, 0.1, 0.02])
    b.site(part, "fixed", [0, 0, -0.02], size=0.01)
    # path: straight down 0.2 m, then a quarter turn about z while moving 0.1 m along x
    b.key("start", mpos=[0, 0, 0.3], mquat=[1, 0, 0, 0])
    b.key("down", mpos=[0, 0, 0.1], mquat=[1, 0, 0, 0])
    b.key("turn", mpos=[0.1, 0, 0.1], mquat=_axis_angle_quat([0, 0, 1], np.pi / 2))
    b.custom_numeric("h_in", 0.01)
    b.custom_text("material", "PLA")
    return b.save(tmp_path / "scene.xml")


def test_scene_loads_sites_and_custom(scene_path):
    s = load_mjcf(scene_path)
    np.testing.assert_allclose(s.sites["fixed"], [0, 0, 0.03])
    assert s.custom_numeric["h_in"][0] == pytest.approx(0.01)
    assert s.custom_text["material"] == "PLA"
    meshes = s.body_meshes()
    # the box body: extents equal 2 x half sizes
    np.testing.assert_allclose(meshes["part"].extents, [0.2, 0.2, 0.04], atol=1e-9)
    assert meshes["object"].is_watertight


def test_trajectory_matches_analytic_interpolation(scene_path):
    traj = Trajectory.from_scene(load_mjcf(scene_path))
    rho = traj.rot_length_scale
    assert rho == pytest.approx(0.05, rel=1e-6)  # icosphere radius: bounding radius of the object
    seg2 = np.hypot(0.1, rho * np.pi / 2)  # sqrt(|dp|^2 + (rho theta)^2)
    assert traj.length == pytest.approx(0.2 + seg2, rel=1e-12)
    # within the first segment: linear in position, identity orientation
    pos, q = traj.pose_at(0.05)
    np.testing.assert_allclose(pos, [0, 0, 0.25], atol=1e-12)
    np.testing.assert_allclose(q, [1, 0, 0, 0], atol=1e-12)
    # 30% into the second segment: 0.03 m along x and 0.3 of the quarter turn
    s = 0.2 + 0.3 * seg2
    pos, q = traj.pose_at(s)
    np.testing.assert_allclose(pos, [0.03, 0, 0.1], atol=1e-12)
    np.testing.assert_allclose(q, _axis_angle_quat([0, 0, 1], 0.3 * np.pi / 2), atol=1e-12)
    # sampling: steps of h, end included, monotone path length
    samples = traj.sample(0.01)
    assert samples[0][0] == 0 and samples[-1][0] == pytest.approx(traj.length)
    assert len(samples) == int(np.floor(traj.length / 0.01)) + 2
    np.testing.assert_allclose(samples[10][1], [0, 0, 0.2], atol=1e-12)
    # evenly sampled positions (vectorized) are pose_at's
    ss = np.linspace(0.0, traj.length, 101)
    np.testing.assert_allclose(traj.sampled_positions(101), [traj.pose_at(v)[0] for v in ss], rtol=0, atol=1e-15)


def test_slerp_constant_angular_speed():
    q0 = np.array([1.0, 0, 0, 0])
    q1 = _axis_angle_quat([1, 1, 0], 2.0)
    for u in (0.0, 0.25, 0.5, 1.0):
        np.testing.assert_allclose(quat_slerp(q0, q1, u), _axis_angle_quat([1, 1, 0], 2.0 * u), atol=1e-12)
    R = quat_to_matrix(_axis_angle_quat([0, 0, 1], np.pi / 2))
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-12)


def test_missing_mocap_and_keys(tmp_path):
    b = MJCFBuilder("nokeys")
    b.geom(b.body("object"), type="sphere", size=0.1)
    p = b.save(tmp_path / "s.xml")
    with pytest.raises(InputError, match="not a mocap body"):
        Trajectory.from_scene(load_mjcf(p))
    with pytest.raises(InputError, match="no body named"):
        Trajectory.from_scene(load_mjcf(p), body="nope")


def test_invalid_mjcf_is_an_input_error_and_builder_refuses_to_save(tmp_path):
    bad = tmp_path / "bad.xml"
    bad.write_text("<mujoco><worldbody><geom type='sphere'/></worldbody>")
    with pytest.raises(InputError, match="bad.xml"):
        load_mjcf(bad)
    b = MJCFBuilder("x")
    b.geom(b.body("a"), type="mesh", mesh="missing")
    with pytest.raises(ValueError):
        b.save(tmp_path / "never.xml")
    assert not (tmp_path / "never.xml").exists()
    assert not list(tmp_path.glob(".never*"))


def test_numeric_config_reads_prefixed_fields_and_rejects_typos(tmp_path):
    import dataclasses

    from simfab.io.mjcf import numeric_config

    @dataclasses.dataclass(frozen=True, kw_only=True)
    class Cfg:
        width: float = 1.0
        segments: int = 4

    b = MJCFBuilder("cfg")
    b.geom(b.body("a"), type="sphere", size=0.1)
    b.custom_numeric("cell_width", 0.25)
    b.custom_numeric("cell_segments", 7.0)
    b.custom_numeric("other_thing", 1.0)
    kw = numeric_config(load_mjcf(b.save(tmp_path / "ok.xml")), "cell_", Cfg)
    assert kw == {"width": 0.25, "segments": 7} and isinstance(kw["segments"], int)
    b.custom_numeric("cell_widht", 0.3)
    with pytest.raises(InputError, match="unknown parameter <numeric name='cell_widht'>"):
        numeric_config(load_mjcf(b.save(tmp_path / "typo.xml")), "cell_", Cfg)


def test_segment_lengths_are_each_segments_translation_and_rotation():
    # sqrt(|dp|^2 + (rho theta)^2) per segment, theta = quat_angle of its two keys, over a path that
    # translates, turns and does both (the vectorized lengths against the per-segment definition)

    rng = np.random.default_rng(3)
    P = np.cumsum(rng.normal(size=(40, 3)) * 0.01, axis=0)
    Q = np.array([_axis_angle_quat(rng.normal(size=3), a) for a in rng.uniform(0, np.pi, 40)])
    Q[5] = Q[4]  # a pure translation
    P[9] = P[8]  # a pure rotation
    tr = Trajectory(P, Q, rot_length_scale=0.02)
    want = [np.hypot(np.linalg.norm(P[i + 1] - P[i]), 0.02 * quat_angle(Q[i], Q[i + 1])) for i in range(39)]
    np.testing.assert_allclose(tr.segment_lengths, want, rtol=1e-12, atol=1e-15)
    assert tr.segment_lengths[4] == pytest.approx(np.linalg.norm(P[5] - P[4]), rel=1e-12)
    assert tr.segment_lengths[8] == pytest.approx(0.02 * quat_angle(Q[8], Q[9]), rel=1e-9)


def test_a_densely_keyed_straight_path_samples_like_its_two_ends(tmp_path):
    # the same straight push given as 2 and as 10,000 keyframes (the most a scene may hold) gives
    # the same length and the same poses at every insertion step
    from simfab.io.mjcf import MAX_KEYFRAMES

    a, b = np.array([0.02, 0.0, 0.0]), np.array([0.001, 0.0, 0.0])
    ends = Trajectory(np.array([a, b]), np.array([[1.0, 0, 0, 0]] * 2))
    x = np.linspace(0.0, 1.0, MAX_KEYFRAMES)[:, None]
    dense = Trajectory(a + x * (b - a), np.tile([1.0, 0, 0, 0], (MAX_KEYFRAMES, 1)))
    assert dense.length == pytest.approx(ends.length, rel=1e-12)
    for (s0, p0, q0), (s1, p1, q1) in zip(ends.sample(ends.length / 35), dense.sample(ends.length / 35)):
        assert s0 == s1
        np.testing.assert_allclose(p1, p0, atol=1e-15)
        np.testing.assert_allclose(q1, q0, atol=0)


@pytest.mark.parametrize("quat", [[0.0, 0, 0, 0], [np.nan, 0, 0, 1], [np.inf, 0, 0, 0]])
def test_a_zero_or_non_finite_keyframe_quaternion_is_an_input_error_without_warnings(quat):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a NumPy warning on the way would fail here
        with pytest.raises(InputError, match=r"mquat: keyframe 1: quaternion .* is zero or not finite"):
            Trajectory(np.zeros((3, 3)), np.array([[1.0, 0, 0, 0], quat, [1.0, 0, 0, 0]]))


def test_more_keyframes_than_the_limit_are_refused_before_mujoco_compiles(tmp_path):
    from simfab.io.mjcf import MAX_KEYFRAMES

    b = MJCFBuilder("many")
    b.body("object", pos=[0, 0, 0], mocap=True)
    for i in range(MAX_KEYFRAMES + 1):
        b.key(mpos=[i * 1e-6, 0, 0])
    path = tmp_path / "many.xml"
    path.write_text(b.to_xml())
    with pytest.raises(InputError, match=rf"many.xml: <keyframe> holds more than the {MAX_KEYFRAMES} keys"):
        load_mjcf(path)


@pytest.mark.parametrize("data, match", [([0.25, 0.5], "data must be one number, got 2"),
                                         (7.5, "data must be a whole number")])
def test_numeric_config_checks_count_and_type(tmp_path, data, match):
    import dataclasses

    from simfab.io.mjcf import numeric_config

    @dataclasses.dataclass(frozen=True, kw_only=True)
    class Cfg:
        width: float = 1.0
        segments: int = 4

    b = MJCFBuilder("cfg")
    b.geom(b.body("a"), type="sphere", size=0.1)
    name = "cell_segments" if match != "data must be one number, got 2" else "cell_width"
    b.custom_numeric(name, data)
    path = tmp_path / "cfg.xml"
    path.write_text(b.to_xml())
    with pytest.raises(InputError, match=rf"cfg.xml: <numeric name='{name}'>: {match}"):
        numeric_config(load_mjcf(path), "cell_", Cfg)
