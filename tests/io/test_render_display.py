"""Rendering draws display geometry: flat meshes without MuJoCo inertia checks, USD basis curves
(with their widths) and points, a camera a stroke can be drawn against; time codes are checked."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from simfab.cli import main
from simfab.io import render
from simfab.io.usd import StageWriter


def _red_pixels(png) -> int:
    a = np.asarray(Image.open(png).convert("RGB")).astype(int)
    return int(np.sum((a[..., 0] > 150) & (a[..., 1] < 80) & (a[..., 2] < 80)))


def test_display_geometry_has_no_bodies(monkeypatch, tmp_path):
    # a flat, thin 2D strip (the kind whose shell inertia MuJoCo rejected): static world geoms only
    seen = {}
    orig = render.render_model

    def spy(model, png, **kw):
        seen["nbody"] = model.nbody
        return orig(model, png, **kw)

    monkeypatch.setattr(render, "render_model", spy)
    t = np.linspace(0, 1, 40)
    V = np.r_[np.c_[t, 0.001 * np.sin(9 * t)], np.c_[t[::-1], 0.001 * np.sin(9 * t[::-1]) + 1e-4]]
    F = np.array([[i, i + 1, 79 - i] for i in range(39)] + [[i + 1, 78 - i, 79 - i] for i in range(39)])
    render.render_meshes([(V, F, None)], tmp_path / "flat.png", width=80, height=60)
    assert seen["nbody"] == 1  # the world body only: nothing has mass, nothing is checked


def test_usd_curves_and_points_are_drawn(tmp_path):
    w = StageWriter(tmp_path / "c.usda")
    w.add_curves("rods", color=(1.0, 0.0, 0.0))
    w.set_curves("rods", [np.array([[0, 0, 0], [0.1, 0, 0.05], [0.2, 0, 0]])], widths=[np.full(3, 0.02)], t=0)
    w.add_points("pts", color=(1.0, 0.0, 0.0))
    w.set_points("pts", np.array([[0.1, 0.1, 0.0]]), 0, widths=np.array([0.03]))
    w.save()
    png = render.render_file(tmp_path / "c.usda", tmp_path / "c.png", width=160, height=120)
    assert _red_pixels(png) > 200  # a stage of curves and points alone is drawn, not "no visible mesh"


def test_time_out_of_range_is_clamped_with_a_warning(tmp_path, capsys):
    w = StageWriter(tmp_path / "m.usda")
    w.add_mesh("m", np.array([[0, 1, 2], [0, 2, 3]]), np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]]))
    for t in range(3):
        w.set_points("m", np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.1 * t]]), t)
    w.save()
    assert main(["render", str(tmp_path / "m.usda"), "-o", str(tmp_path / "m.png"), "--time", "50", "--json",
                 "--width", "64", "--height", "48"]) == 0
    cap = capsys.readouterr()
    assert json.loads(cap.out)["time"] == 2.0
    assert "outside the stage's range [0, 2]" in cap.err and len(cap.err.strip().splitlines()) == 1


def test_render_camera_projects_onto_the_image(tmp_path):
    # the camera saved with a render (grow's preview camera) maps 3D points to the pixels where they appear
    from simfab.growth.sketch import load_camera
    from simfab.io.mjcf import MJCFBuilder

    b = MJCFBuilder("cam")
    b.geom(b.worldbody, type="box", size=[0.1, 0.1, 0.01], rgba=[0.8, 0.8, 0.8, 1])
    p = np.array([0.06, -0.04, 0.03])
    b.geom(b.worldbody, type="sphere", size=0.01, pos=p, rgba=[1, 0, 0, 1])
    cam: dict = {}
    png = render.render_model(b.compile(), tmp_path / "cam.png", width=320, height=240, camera=cam)
    x, y = load_camera(json.dumps(cam)).project(p[None])[0]
    a = np.asarray(Image.open(png).convert("RGB")).astype(int)
    r = a[int(round(y)), int(round(x))]
    assert r[0] > 150 and r[1] < 80 and r[2] < 80, (x, y, r)


def test_skins_keep_no_zero_area_faces():
    # a closed box with a zero-area face (a vertex on an edge): split into its neighbour, still closed
    import trimesh

    from simfab.growth.skinning import split_degenerate

    box = trimesh.creation.box()
    V, F = np.asarray(box.vertices), np.asarray(box.faces)
    f = F[0]
    a, c, x = int(f[0]), int(f[1]), int(f[2])
    V = np.vstack([V, 0.5 * (V[a] + V[c])])
    m = len(V) - 1
    F = np.vstack([F[1:], [[a, m, x], [m, c, x], [a, c, m]]])  # (a, c, m) has zero area
    assert trimesh.Trimesh(V, F, process=False).is_watertight
    F2 = split_degenerate(V, F)
    out = trimesh.Trimesh(V, F2, process=False)
    area = out.area_faces
    assert out.is_watertight and out.is_winding_consistent and area.min() > 1e-6
    assert out.volume == pytest.approx(box.volume, rel=1e-12)


def test_scalar_field_gets_a_colour_bar(tmp_path):
    w = StageWriter(tmp_path / "s.usda")
    P = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]])
    w.add_mesh("m", np.array([[0, 1, 2], [0, 2, 3]]), P)
    w.set_points("m", P, 0)
    w.set_scalar("m", "stress", [0.0, 1.0, 2.0, 3.0], 0, vmin=0.0, vmax=5.0, units="Pa")
    w.save()
    info: dict = {}
    png = render.render_file(tmp_path / "s.usda", tmp_path / "s.png", width=320, height=240, info=info)
    assert info["colorbar"] == {"label": "stress [Pa]", "cmap": "viridis", "min": 0.0, "max": 5.0, "clipped": False}
    a = np.asarray(Image.open(png).convert("RGB")).astype(int)
    right = a[:, 200:]
    yellow = (right[..., 0] > 200) & (right[..., 1] > 200) & (right[..., 2] < 80)  # the bar's top (viridis max)
    assert yellow.sum() > 20


def _unclipped(tmp_path):
    w = StageWriter(tmp_path / "u.usda")
    P = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0.0]])
    w.add_mesh("m", np.array([[0, 1, 2]]), P)
    w.set_points("m", P, 0)
    w.set_scalar("m", "stress", [0.0, 1.0, 5.0], 0, vmin=0.0, vmax=5.0)  # (at the top, not above)
    return w.save()


def test_a_scale_below_some_values_is_marked_clipped(tmp_path):
    # one sample of the timeline above the fixed range: that vertex takes the top colour, and the
    # stage says so for the whole timeline (a colour bar then reads ">= max")
    w = StageWriter(tmp_path / "s.usda")
    P = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]])
    w.add_mesh("m", np.array([[0, 1, 2], [0, 2, 3]]), P)
    for t, top in enumerate((3.0, 9.0, 1.0)):
        w.set_points("m", P, t)
        w.set_scalar("m", "stress", [0.0, 1.0, 2.0, top], t, vmin=0.0, vmax=5.0, units="Pa")
    w.save()
    from simfab.io.usd_read import open_stage, read_scalar_at

    sc = read_scalar_at(open_stage(tmp_path / "s.usda"), 0)
    assert sc.range == (0.0, 5.0) and sc.clipped
    assert not read_scalar_at(open_stage(_unclipped(tmp_path)), 0).clipped
    info: dict = {}
    render.render_file(tmp_path / "s.usda", tmp_path / "s.png", width=320, height=240, info=info, time=1)
    assert info["colorbar"]["clipped"] and info["colorbar"]["max"] == 5.0
