"""Mesh loading/validation and offscreen rendering."""

import warnings

import numpy as np
import pytest
import trimesh
from PIL import Image

from simfab.errors import InputError
from simfab.io.mesh import MeshWarning, load_mesh, save_mesh
from simfab.io.render import render_file, render_mesh


def test_mm_units_and_round_trip(tmp_path):
    box = trimesh.creation.box(extents=(10.0, 20.0, 30.0))
    p = save_mesh(box, tmp_path / "box.stl")
    m = load_mesh(p, units="mm", require_watertight=True)
    np.testing.assert_allclose(sorted(m.extents), [0.01, 0.02, 0.03], rtol=1e-6)
    assert m.volume == pytest.approx(6e-6, rel=1e-6)


def test_open_mesh_rejected_when_watertight_required(tmp_path):
    box = trimesh.creation.box()
    open_box = trimesh.Trimesh(box.vertices, box.faces[:-2])
    p = save_mesh(open_box, tmp_path / "open.ply")
    with pytest.raises(InputError, match=r"open.ply: mesh is not watertight"):
        load_mesh(p, require_watertight=True)
    assert len(load_mesh(p).faces) == 10  # usable where closedness is not needed


def test_repairable_problems_warn(tmp_path):
    box = trimesh.creation.box()
    F = box.faces.copy()
    F[0] = F[0][::-1]  # one flipped face
    F = np.vstack([F, F[3:4], [[0, 0, 1]]])  # a duplicate and a degenerate face
    p = tmp_path / "broken.obj"
    trimesh.Trimesh(box.vertices, F, process=False).export(p)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        m = load_mesh(p, require_watertight=True)
    assert any(issubclass(x.category, MeshWarning) for x in w)
    assert m.is_watertight and m.is_winding_consistent and m.volume == pytest.approx(1.0)


@pytest.mark.parametrize("content,match", [(None, "file not found"),
                                           (b"solid x\nendsolid x\n", "no triangles|cannot read"),
                                           (b"\x00\x01garbage", "cannot read|no triangles")])
def test_unusable_files(tmp_path, content, match):
    p = tmp_path / "m.stl"
    if content is not None:
        p.write_bytes(content)
    with pytest.raises(InputError, match=match):
        load_mesh(p)


def test_render_mesh_png_not_empty(tmp_path):
    m = trimesh.creation.icosphere(subdivisions=2)
    png = render_mesh(m.vertices, m.faces, tmp_path / "s.png", colors=np.tile([0.9, 0.1, 0.1], (len(m.faces), 1)),
                      width=160, height=120)
    img = np.asarray(Image.open(png))
    assert img.shape == (120, 160, 3)
    # the red sphere is in the middle of the view
    centre = img[40:80, 60:100].reshape(-1, 3).astype(int)
    assert np.mean((centre[:, 0] > 120) & (centre[:, 1] < 80)) > 0.5


def test_render_file_rejects_unknown(tmp_path):
    p = tmp_path / "a.txt"
    p.write_text("x")
    with pytest.raises(InputError, match="cannot render"):
        render_file(p, tmp_path / "a.png")


def test_render_usd_flat_2d_mesh_with_per_face_colors(tmp_path):
    # 2D FEM results are flat meshes with a scalar per face: colour groups can be tiny.
    from simfab.io.render import render_usd
    from simfab.io.usd import StageWriter

    xs, ys = np.meshgrid(np.linspace(0, 1, 6), np.linspace(0, 0.3, 3))
    P = np.column_stack([xs.ravel(), ys.ravel()])
    F = []
    for j in range(2):
        for i in range(5):
            a = j * 6 + i
            F += [[a, a + 1, a + 7], [a, a + 7, a + 6]]
    w = StageWriter(tmp_path / "flat.usda")
    w.add_mesh("part", F, P)
    w.set_scalar("part", "von_mises", np.arange(len(F), dtype=float), 0, interpolation="uniform")
    w.save()
    png = render_usd(tmp_path / "flat.usda", tmp_path / "flat.png", width=120, height=90)
    assert np.asarray(Image.open(png)).std() > 1.0


def test_matplotlib_fallback_without_opengl(tmp_path, monkeypatch):
    # a machine without OpenGL still gets a PNG: the GL failure is caught and matplotlib draws
    import simfab.io.render as render

    def no_gl(*a, **k):
        raise RuntimeError("Failed to initialize OpenGL (EGL) context")

    monkeypatch.setattr(render, "render_model", no_gl)
    m = trimesh.creation.box()
    png = render.render_mesh(m.vertices[:, :3], m.faces, tmp_path / "fb.png", width=120, height=90)
    img = np.asarray(Image.open(png).convert("RGB"))
    assert img.shape == (90, 120, 3) and img.std() > 1.0
    # a non-GL error is not swallowed
    monkeypatch.setattr(render, "render_model", lambda *a, **k: (_ for _ in ()).throw(ValueError("bad mesh")))
    with pytest.raises(ValueError, match="bad mesh"):
        render.render_mesh(m.vertices, m.faces, tmp_path / "x.png")
