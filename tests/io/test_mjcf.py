"""MJCF scenes: keyframe trajectories against analytic interpolation, builder round trip."""

import numpy as np
import pytest
import trimesh

from simfab.errors import InputError
from simfab.io.mjcf import MJCFBuilder, Trajectory, load_scene, quat_slerp, quat_to_matrix


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
    s = load_scene(scene_path)
    np.testing.assert_allclose(s.sites["fixed"], [0, 0, 0.03])
    assert s.custom_numeric["h_in"][0] == pytest.approx(0.01)
    assert s.custom_text["material"] == "PLA"
    meshes = s.body_meshes()
    # the box body: extents equal 2 x half sizes
    np.testing.assert_allclose(meshes["part"].extents, [0.2, 0.2, 0.04], atol=1e-9)
    assert meshes["object"].is_watertight


def test_trajectory_matches_analytic_interpolation(scene_path):
    traj = Trajectory.from_scene(load_scene(scene_path))
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
        Trajectory.from_scene(load_scene(p))
    with pytest.raises(InputError, match="no body named"):
        Trajectory.from_scene(load_scene(p), body="nope")


def test_invalid_mjcf_is_an_input_error_and_builder_refuses_to_save(tmp_path):
    bad = tmp_path / "bad.xml"
    bad.write_text("<mujoco><worldbody><geom type='sphere'/></worldbody>")
    with pytest.raises(InputError, match="bad.xml"):
        load_scene(bad)
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
    kw = numeric_config(load_scene(b.save(tmp_path / "ok.xml")), "cell_", Cfg)
    assert kw == {"width": 0.25, "segments": 7} and isinstance(kw["segments"], int)
    b.custom_numeric("cell_widht", 0.3)
    with pytest.raises(InputError, match="unknown parameter <numeric name='cell_widht'>"):
        numeric_config(load_scene(b.save(tmp_path / "typo.xml")), "cell_", Cfg)
