"""USD stages: round trip of a deforming mesh with a scalar primvar, compliance, atomicity."""

import numpy as np
import pytest
import trimesh
from pxr import Usd, UsdGeom

from simfab.io.usd import StageWriter, check_compliance, read_mesh_at, scalar_colors


def _write_deforming(path, frames=10):
    m = trimesh.creation.icosphere(subdivisions=1)
    w = StageWriter(path, time_codes_per_second=30.0)
    w.add_mesh("part", m.faces, m.vertices)
    w.add_rigid("object", m.vertices * 0.1, m.faces)
    w.add_curves("skeleton")
    for k in range(frames):
        x = m.vertices * (1.0 + 0.05 * k)
        w.set_points("part", x, k)
        w.set_scalar("part", "stress", np.full(len(m.faces), float(k)), k, interpolation="uniform", vmin=0, vmax=frames)
        w.set_pose("object", [0, 0, 0.1 * k], [np.cos(0.1 * k), 0, 0, np.sin(0.1 * k)], k)
        w.set_curves("skeleton", [np.array([[0, 0, 0], [0, 0, 1.0 + k]])], [np.array([0.1, 0.05])], k)
    return w.save(), m


def test_round_trip_deforming_mesh(tmp_path):
    path, m = _write_deforming(tmp_path / "deform.usda")
    stage = Usd.Stage.Open(str(path))
    assert stage.GetDefaultPrim().GetPath() == "/World"
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetTimeCodesPerSecond() == 30.0
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0.0, 9.0)
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/part"))
    assert mesh.GetPointsAttr().GetTimeSamples() == list(range(10))
    p7 = np.asarray(mesh.GetPointsAttr().Get(7))
    np.testing.assert_allclose(p7, m.vertices * 1.35, rtol=1e-6, atol=1e-6)
    pv = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("stress")
    assert pv.GetInterpolation() == "uniform"
    assert len(pv.GetAttr().GetTimeSamples()) == 10
    np.testing.assert_allclose(np.asarray(pv.Get(4)), 4.0)
    xf = UsdGeom.Xformable(stage.GetPrimAtPath("/World/object"))
    assert len(xf.GetOrderedXformOps()[0].GetAttr().GetTimeSamples()) == 10
    # world transform at t=3 moves the object's mesh up by 0.3
    got = [v for n, v, _, _ in read_mesh_at(path, 3) if n == "/World/object/geom"][0]
    assert abs(got[:, 2].mean() - 0.3) < 1e-5


def test_stage_is_compliant(tmp_path):
    path, _ = _write_deforming(tmp_path / "c.usda")
    assert check_compliance(path) == []


def test_checker_flags_a_broken_stage(tmp_path):
    # a stage without the required metadata must not pass: the checker is not a no-op
    bad = tmp_path / "bad.usda"
    st = Usd.Stage.CreateNew(str(bad))
    UsdGeom.Mesh.Define(st, "/m")
    st.GetRootLayer().Save()
    assert check_compliance(bad) != []


def test_failed_write_leaves_no_file(tmp_path):
    w = StageWriter(tmp_path / "x.usda")
    w.add_mesh("part", [[0, 1, 2]], np.eye(3))
    with pytest.raises(ValueError):
        w.set_points("part", np.full((3, 3), np.nan), 0)
    assert not (tmp_path / "x.usda").exists()
    w.save()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.usda"]


def test_invalid_names_rejected(tmp_path):
    w = StageWriter(tmp_path / "x.usda")
    with pytest.raises(ValueError):
        w.add_mesh("1bad name", [[0, 1, 2]])


def test_colormap_range():
    rgb = scalar_colors([0.0, 1.0, np.nan], vmin=0, vmax=1)
    assert rgb.shape == (3, 3) and np.all((rgb >= 0) & (rgb <= 1))
    assert not np.allclose(rgb[0], rgb[1])
    np.testing.assert_allclose(rgb[2], 0.5)


def test_atomic_outputs_have_default_permissions(tmp_path):
    import os

    from simfab.io.atomic import write_text

    p = write_text(tmp_path / "a.txt", "x")
    mask = os.umask(0)
    os.umask(mask)
    assert (p.stat().st_mode & 0o777) == (0o666 & ~mask)
