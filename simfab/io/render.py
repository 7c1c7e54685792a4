"""Offscreen PNG rendering of MJCF scenes, meshes and USD stages.

MuJoCo's ``Renderer`` draws headless through EGL (``MUJOCO_GL=egl``, set by
:mod:`simfab.io` when no display is present). Where no OpenGL is available at all, the
same views are drawn with matplotlib's 3D polygons instead, so a PNG is always produced.

The camera looks at the bounding box of the visible geometry (planes excluded) from an
oblique view: azimuth 135°, elevation -25°, distance 1.3 x the box diagonal (the bounding
sphere just fits the 45° vertical field of view).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from simfab.errors import InputError
from simfab.io.annotate import annotate_png  # noqa: F401  (re-exported: titles, scale and colour bars)
from simfab.io.atomic import atomic_path, save_figure
from simfab.io.mesh import SUFFIXES, load_mesh, units_warning
from simfab.io.mjcf import MJCFBuilder, Scene, load_model
from simfab.io.usd import as_points3, open_stage, read_curves_at, read_mesh_at, read_scalar_at, stage_time
from simfab.progress import log

AZIMUTH, ELEVATION, DISTANCE_FACTOR = 135.0, -25.0, 1.3
COLOR_BINS = 24  # per-face colours are quantized into this many geoms for MuJoCo


def _write_png(rgb: np.ndarray, png: str | os.PathLike) -> Path:
    from PIL import Image

    png = Path(png)
    with atomic_path(png) as tmp:
        Image.fromarray(np.ascontiguousarray(rgb)).save(tmp, format="PNG")
    return png


def _scene_bounds(model, data):
    """Axis-aligned bounds (lo, hi) of all non-plane geoms at the current state."""
    import mujoco

    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for g in range(model.ngeom):
        gtype = int(model.geom_type[g])
        if gtype in (int(mujoco.mjtGeom.mjGEOM_PLANE), int(mujoco.mjtGeom.mjGEOM_HFIELD)):
            continue
        r = model.geom_rbound[g] if model.geom_rbound[g] > 0 else np.max(model.geom_size[g])
        c = data.geom_xpos[g]
        if gtype == int(mujoco.mjtGeom.mjGEOM_MESH):
            mid = model.geom_dataid[g]
            va, vn = model.mesh_vertadr[mid], model.mesh_vertnum[mid]
            V = model.mesh_vert[va:va + vn] @ data.geom_xmat[g].reshape(3, 3).T + c
            lo, hi = np.minimum(lo, V.min(0)), np.maximum(hi, V.max(0))
        else:
            lo, hi = np.minimum(lo, c - r), np.maximum(hi, c + r)
    for i in range(model.nflex):  # flex vertices (cables, deformables)
        va, vn = model.flex_vertadr[i], model.flex_vertnum[i]
        V = data.flexvert_xpos[va:va + vn]
        if len(V):
            lo, hi = np.minimum(lo, V.min(0)), np.maximum(hi, V.max(0))
    if not np.all(np.isfinite(lo)):
        lo, hi = -np.ones(3), np.ones(3)
    return lo, hi


def render_model(model, png, *, data=None, width: int = 640, height: int = 480,
                 azimuth: float = AZIMUTH, elevation: float = ELEVATION, camera: dict | None = None,
                 view: dict | None = None) -> Path:
    """Render a ``mujoco.MjModel`` (at ``data`` or ``qpos0``) to a PNG.

    ``camera`` (a dict) receives the pinhole camera of the image: eye, target, up (3,) [m],
    fovy_deg (vertical field of view), width, height [px] -- the format of
    :func:`simfab.growth.sketch.load_camera`, so strokes can be drawn over the PNG."""
    import mujoco

    if data is None:
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
    model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), width)
    model.vis.global_.offheight = max(int(model.vis.global_.offheight), height)
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    if view is not None:  # an explicit z-up pinhole camera (eye, target, fovy_deg): the same picture again
        f = np.subtract(view["target"], view["eye"], dtype=float)
        cam.lookat[:] = view["target"]
        cam.distance = float(np.linalg.norm(f))
        azimuth = float(np.degrees(np.arctan2(f[1], f[0])))
        elevation = float(np.degrees(np.arcsin(f[2] / cam.distance)))
        model.vis.global_.fovy = float(view.get("fovy_deg", model.vis.global_.fovy))
    else:
        lo, hi = _scene_bounds(model, data)
        cam.lookat[:] = (lo + hi) / 2
        cam.distance = DISTANCE_FACTOR * max(float(np.linalg.norm(hi - lo)), 1e-3)
    cam.azimuth, cam.elevation = azimuth, elevation
    if camera is not None:
        # MuJoCo's free camera: forward = (cos el cos az, cos el sin az, sin el), eye = lookat - distance forward
        a, e = np.radians(azimuth), np.radians(elevation)
        fwd = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
        camera.update(eye=(np.asarray(cam.lookat) - cam.distance * fwd).tolist(),
                      target=np.asarray(cam.lookat).tolist(), up=[0.0, 0.0, 1.0],
                      fovy_deg=float(model.vis.global_.fovy), width=int(width), height=int(height))
    renderer = mujoco.Renderer(model, height=height, width=width)
    try:
        renderer.update_scene(data, camera=cam)
        rgb = renderer.render()
    finally:
        renderer.close()
    return _write_png(rgb, png)


def render_mjcf(xml, png, *, width: int = 640, height: int = 480, camera: dict | None = None) -> Path:
    """Render an MJCF file (path) or a compiled ``MjModel`` to a PNG; matplotlib fallback without GL.
    ``camera`` receives the camera (see :func:`render_model`; left empty by the fallback)."""

    model = load_model(xml) if isinstance(xml, (str, os.PathLike)) else xml
    try:
        return render_model(model, png, width=width, height=height, camera=camera)
    except Exception as e:  # no usable OpenGL: draw the geometry with matplotlib instead
        if not _is_gl_error(e):
            raise

        meshes = Scene(path=Path("."), model=model, sites={}, site_size={}, custom_numeric={},
                       custom_text={}).body_meshes()
        return _render_matplotlib([(m.vertices, m.faces, None) for m in meshes.values()], png, width, height)


def render_meshes(items, png, *, width: int = 640, height: int = 480, floor: bool = True,
                  curves=(), points=(), camera: dict | None = None, view: dict | None = None) -> Path:
    """Render several meshes, polylines and point sets together.

    items : list of ``(vertices (n,3) [m], faces (m,3), colors)`` where colors is None, an
        RGB(A) triple for the whole mesh, or per-face RGB (m,3) in [0, 1].
    curves : list of ``(polylines [(k_i, 3)], widths [(k_i,) or None], rgb or None)``: drawn as
        capsules of diameter ``width`` (default 0.5 % of the scene's diagonal) per segment.
    points : list of ``(P (n, 3), widths (n,) or None, rgb or None)``: spheres of diameter ``width``.

    Display geometry only: everything is a static geom of the world body (no masses, so MuJoCo's
    inertia checks cannot reject a flat or thin mesh), and the floor casts no shadow specks.
    """

    items = [(as_points3(V), np.asarray(F, np.int64), c) for V, F, c in items]  # 2D meshes go to z = 0
    curves = [([as_points3(p) for p in pl], ws, c) for pl, ws, c in curves]
    points = [(as_points3(P), w, c) for P, w, c in points]
    allv = [V for V, _, _ in items] + [p for pl, _, _ in curves for p in pl] + [P for P, _, _ in points]
    allv = np.concatenate(allv) if allv else np.zeros((1, 3))
    diag = float(np.linalg.norm(np.ptp(allv, axis=0))) or 1.0
    b = MJCFBuilder("render")
    for light in b.worldbody.iter("light"):
        light.set("castshadow", "false")  # shadow-map aliasing showed as dark specks on the floor
    if floor:
        b.floor(z=float(allv[:, 2].min()) - 0.02 * diag, size=10.0 * diag)  # a little below: no z-fighting
    palette = np.array([[0.85, 0.55, 0.3], [0.35, 0.55, 0.85], [0.5, 0.75, 0.45], [0.8, 0.4, 0.6]])
    world = b.worldbody
    for i, (V, F, colors) in enumerate(items):
        groups = _color_groups(F, colors, palette[i % len(palette)])
        for j, (faces, rgb) in enumerate(groups):
            # Every colour group keeps the whole vertex array: MuJoCo needs >= 4 vertices per mesh.
            b.mesh_asset(f"m{i}_{j}", V, faces).set("inertia", "shell")
            b.geom(world, type="mesh", mesh=f"m{i}_{j}", rgba=[*rgb[:3], 1.0], contype=0, conaffinity=0, group=0)
    default_w = 0.005 * diag
    for i, (polylines, widths, rgb) in enumerate(curves):
        rgba = [*(np.asarray(rgb, float)[:3] if rgb is not None else (0.25, 0.3, 0.35)), 1.0]
        for pl, w in zip(polylines, widths if widths is not None else [None] * len(polylines)):
            r = np.full(len(pl), default_w / 2) if w is None else np.maximum(np.asarray(w, float) / 2, 1e-6 * diag)
            for a in range(len(pl) - 1):
                if np.linalg.norm(pl[a + 1] - pl[a]) < 1e-9 * diag:
                    continue
                b.geom(world, type="capsule", fromto=np.r_[pl[a], pl[a + 1]], size=0.5 * (r[a] + r[a + 1]),
                       rgba=rgba, contype=0, conaffinity=0)
    for P, w, rgb in points:
        rgba = [*(np.asarray(rgb, float)[:3] if rgb is not None else (0.8, 0.2, 0.2)), 1.0]
        r = np.full(len(P), default_w) if w is None else np.maximum(np.asarray(w, float) / 2, 1e-6 * diag)
        for p, ri in zip(P, r):
            b.geom(world, type="sphere", pos=p, size=ri, rgba=rgba, contype=0, conaffinity=0)
    try:
        return render_model(b.compile(), png, width=width, height=height, camera=camera, view=view)
    except Exception as e:
        if not _is_gl_error(e):
            raise
        return _render_matplotlib(items, png, width, height, curves=curves, points=points)


def render_mesh(vertices, faces, png, *, colors=None, width: int = 640, height: int = 480) -> Path:
    """Render one mesh (see :func:`render_meshes` for ``colors``)."""
    return render_meshes([(vertices, faces, colors)], png, width=width, height=height)


def render_usd(path, png, *, time: float | None = None, width: int = 640, height: int = 480,
               info: dict | None = None, camera: dict | None = None) -> Path:
    """Render the visible meshes (with their colours), basis curves (tubes of their widths) and
    points of a USD stage at a time code (default: the last; outside the stage's range it is
    clamped with a warning on stderr). ``info`` receives the time code drawn."""

    stage = open_stage(path)
    t, warning = stage_time(stage, time)
    if warning:
        log(f"simfab: warning: {path}: {warning}")
    if info is not None:

        info["time"] = t
        sc = read_scalar_at(stage, t)
        if sc is not None:
            info["colorbar"] = {"label": sc.name + (f" [{sc.units}]" if sc.units else ""), "cmap": sc.cmap,
                                "min": sc.range[0], "max": sc.range[1], "clipped": sc.clipped}
    items = [(V, F, rgb) for _, V, F, rgb in read_mesh_at(stage, t)]
    crv, pts = read_curves_at(stage, t)
    if not items and not crv and not pts:
        raise InputError(f"the stage has no visible mesh, curve or point at time code {t:g}", where=str(path))
    return render_meshes(items, png, width=width, height=height, curves=[(pl, w, c) for _, pl, w, c in crv],
                         points=[(P, w, c) for _, P, w, c in pts], camera=camera)


def render_file(src, png, *, time: float | None = None, width: int = 640, height: int = 480,
                info: dict | None = None, annotate: bool = True) -> Path:
    """Render an MJCF (.xml), USD (.usd/.usda/.usdc) or mesh file to a PNG, titled with the file
    name (and time code) and a scale bar unless ``annotate`` is False (or the image is tiny)."""
    src = Path(src)
    if not src.is_file():
        raise InputError("file not found", where=str(src))
    if width <= 0 or height <= 0 or width > 8192 or height > 8192:
        raise InputError(f"image size {width}x{height} is out of range (1..8192)", where="--width/--height")
    if time is not None and not np.isfinite(time):
        raise InputError(f"must be a finite time code, got {time}", where="--time")
    suf = src.suffix.lower()
    cam: dict = {}
    info = {} if info is None else info
    if suf == ".xml":
        out = render_mjcf(src, png, width=width, height=height, camera=cam)
    elif suf in (".usd", ".usda", ".usdc"):
        out = render_usd(src, png, time=time, width=width, height=height, info=info, camera=cam)
    else:

        if suf not in SUFFIXES:
            raise InputError(f"cannot render {suf!r} files (use .xml, .usd/.usda/.usdc or a mesh)", where=str(src))

        m = load_mesh(src)
        w = units_warning(m.extents, "m")
        if w:  # the scale bar assumes metres
            log(f"simfab: warning: {src}: {w.split(';')[0]} (drawn as metres)")
        out = render_meshes([(m.vertices, m.faces, None)], png, width=width, height=height, camera=cam)
    if cam and annotate and height >= 120:  # title, scale bar, colour bar: the picture reads on its own
        title = src.name + (f"  (time code {info['time']:g})" if "time" in info else "")
        annotate_png(out, cam, title=title, colorbar=info.get("colorbar"))
    return out


def _color_groups(F, colors, default):
    if colors is None:
        return [(F, np.asarray(default))]
    c = np.asarray(colors, np.float64)
    if c.ndim == 1:
        return [(F, c)]
    if len(c) != len(F):
        raise ValueError(f"per-face colors must be (m, 3) with m = {len(F)}, got {c.shape}")
    # Quantize the colours to a grid of COLOR_BINS levels per channel: a colormap survives as a
    # few dozen geoms (one per distinct quantized colour) instead of one per face.
    key = np.round(c[:, :3] * (COLOR_BINS - 1)).astype(np.int64)
    uniq, inv = np.unique(key, axis=0, return_inverse=True)
    inv = inv.ravel()
    return [(F[inv == k], uniq[k] / (COLOR_BINS - 1)) for k in range(len(uniq))]


def _is_gl_error(e: Exception) -> bool:
    """True when ``e`` says that no OpenGL context could be made (then matplotlib draws instead)."""
    import re

    text = f"{type(e).__name__} {e}".lower()
    return re.search(r"\b(e?gl|opengl|glfw|osmesa|pyopengl)\b|gl context|display", text) is not None


def _render_matplotlib(items, png, width, height, *, curves=(), points=()) -> Path:
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection


    fig = plt.figure(figsize=(width / 100, height / 100), dpi=100)
    ax = fig.add_subplot(projection="3d")
    allv = []
    for V, F, colors in items:  # vertices (n, 3)
        fc = colors if colors is not None else (0.85, 0.55, 0.3)
        ax.add_collection3d(Poly3DCollection(V[np.asarray(F)], facecolors=fc, edgecolors="none", alpha=1.0))
        allv.append(V)
    for polylines, _, rgb in curves:
        for pl in polylines:
            ax.plot(pl[:, 0], pl[:, 1], pl[:, 2], color=rgb if rgb is not None else (0.25, 0.3, 0.35), lw=1.5)
            allv.append(pl)
    for P, _, rgb in points:
        ax.scatter(P[:, 0], P[:, 1], P[:, 2], color=rgb if rgb is not None else (0.8, 0.2, 0.2), s=4)
        allv.append(P)
    V = np.concatenate(allv)
    c, r = (V.max(0) + V.min(0)) / 2, max(float(np.ptp(V, axis=0).max()) / 2, 1e-6)
    ax.set_xlim(c[0] - r, c[0] + r)
    ax.set_ylim(c[1] - r, c[1] + r)
    ax.set_zlim(c[2] - r, c[2] + r)
    ax.view_init(elev=-ELEVATION, azim=AZIMUTH - 90)
    ax.set_axis_off()
    path = save_figure(fig, png)
    plt.close(fig)
    return path
