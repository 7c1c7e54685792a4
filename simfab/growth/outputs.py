"""Files of a growth run: skin (STL, PLY), skeleton (JSON), growth replay (USD), MJCF, PNG; of a
sketch edit (:func:`write_edit`) and of a structural check.

Units: the skin STL/PLY are in **millimetres** (what slicers expect); everything else
(skeleton JSON, USD with metersPerUnit = 1, MJCF) is in metres.

Every file is written atomically (temporary name + rename). The USD stage replays the
growth: time code t (0..S) shows the branches grown up to step t (as polylines) with
widths 2 r (radius by age) and the attractors still alive, S+1 the pruned skeleton, S+2
the smoothed one, S+3 the skin (and the objects throughout as static meshes).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from simfab.growth.pipeline import node_radius
from simfab.growth.skeleton import chains, to_json_dict
from simfab.io.atomic import atomic_paths, save_figure, write_json
from simfab.io.mesh import save_mesh
from simfab.io.mjcf import MJCFBuilder, load_model
from simfab.io.outpaths import safe_name
from simfab.io.render import AZIMUTH, annotate_png, render_mjcf, render_model
from simfab.io.usd import StageWriter

OBJECT_RGBA = (0.62, 0.64, 0.68, 1.0)
SKIN_RGBA = (0.86, 0.52, 0.25, 1.0)


def _ident(name: str) -> str:
    s = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return s if re.match(r"^[A-Za-z_]", s) else "_" + s


def write_skeleton(result, path: Path, skeleton=None, **extra) -> Path:

    sk = skeleton if skeleton is not None else result.skeleton
    scene = result.scene
    return write_json(path, to_json_dict(sk, scene=str(scene.path.resolve()) if scene.path else None,
                                         seed=result.seed, **extra))


def write_usd(result, mesh, path: Path) -> Path:
    """Growth replay stage (see module docstring)."""

    w = StageWriter(path)
    for name, m in result.scene.objects.items():
        w.add_mesh(f"objects/{_ident(name)}", np.asarray(m.faces), np.asarray(m.vertices), color=OBJECT_RGBA[:3])
    if len(result.scene.sphere_radii):
        w.add_points("obstacles", color=(0.9, 0.6, 0.1))
        w.set_points("obstacles", result.scene.sphere_centers, 0.0, widths=2 * result.scene.sphere_radii)
    w.add_curves("growth/skeleton", color=SKIN_RGBA[:3])
    h = result.history
    res = result.resolved
    S = int(h.birth.max(initial=0))
    r = node_radius(h.birth, result.scene.params.radius_age, S, res)
    # replay as polylines: every chain of the final tree, cut to the nodes born so far
    # (births increase along a chain, so the visible part is a prefix)
    ch = chains(h.parent, np.zeros(len(h), bool))
    A, death = result.attractors, result.attractor_death_step
    w.add_points("growth/attractors", color=(0.3, 0.6, 0.3))
    for t in range(S + 1):
        live = (death < 0) | (death > t)
        if live.any():
            w.set_points("growth/attractors", A[live], t, widths=np.full(int(live.sum()), 0.15 * res.kill))
        elif t == 0 or ((death < 0) | (death > t - 1)).any():  # the last ones just died: hide
            w.set_visible("growth/attractors", False, t)
        cut = [(c, int(np.searchsorted(h.birth[c], t, side="right"))) for c in ch]
        _set_polylines(w, h.nodes, r, [c[:k] for c, k in cut if k >= 2], h.parent, t)
    for k, sk in enumerate((result.pruned, result.skeleton)):
        _set_polylines(w, sk.nodes, sk.radius, chains(sk.parent, np.zeros(len(sk.nodes), bool)), sk.parent, S + 1 + k)
    w.add_mesh("growth/skin", np.asarray(mesh.faces), np.asarray(mesh.vertices), color=SKIN_RGBA[:3])
    w.set_visible("growth/skin", False, 0.0)
    w.set_visible("growth/skin", True, S + 3)
    w.set_visible("growth/skeleton", True, 0.0)
    w.set_visible("growth/skeleton", False, S + 3)
    return w.save()


def _set_polylines(w, nodes, radius, polylines, parent, t):
    if not polylines:  # USD curves need >= 2 points: show a zero-length stub at the roots
        roots = np.nonzero(parent < 0)[0][:1]
        w.set_curves("growth/skeleton", [np.repeat(nodes[roots], 2, axis=0)], [np.repeat(2 * radius[roots], 2)], t)
        return
    w.set_curves("growth/skeleton", [nodes[c] for c in polylines], [2 * radius[c] for c in polylines], t)


def write_mjcf(result, mesh, path: Path) -> Path:
    """MJCF with the objects and the grown part as static mesh bodies (open it in the viewer)."""

    b = MJCFBuilder(f"{result.scene.name}_grown")
    for name, m in result.scene.objects.items():
        nm = _ident(name)
        b.mesh_asset(f"obj_{nm}", m.vertices, m.faces)
        body = b.body(f"obj_{nm}")
        b.geom(body, type="mesh", mesh=f"obj_{nm}", rgba=OBJECT_RGBA, contype=0, conaffinity=0)
    b.mesh_asset("grown", mesh.vertices, mesh.faces)
    body = b.body("grown")
    b.geom(body, type="mesh", mesh="grown", rgba=SKIN_RGBA)
    for name, x in zip(result.scene.target_names, result.scene.targets):
        b.site(body, name, x, size=0.6 * result.resolved.r_min, rgba=[0.2, 0.3, 0.9, 1])
    for name, x in zip(result.scene.root_names, result.scene.roots):
        b.site(body, name, x, size=0.6 * result.resolved.r_min, rgba=[0.9, 0.2, 0.2, 1])
    for name, c, r in zip(result.scene.sphere_names, result.scene.sphere_centers, result.scene.sphere_radii):
        b.geom(b.worldbody, name=_ident(name), type="sphere", size=[r], pos=c, rgba=[0.9, 0.6, 0.1, 0.3],
               contype=0, conaffinity=0)
    return b.save(path)


def preview_azimuth(result, mesh) -> float:
    """MuJoCo camera azimuth [deg] that looks at the grown part from its side of the objects
    (the part is often behind the object it supports, e.g. a phone stand)."""

    objs = [m.bounds.mean(axis=0) for m in result.scene.objects.values()]
    if not objs or len(mesh.vertices) == 0:
        return AZIMUTH
    v = (np.asarray(mesh.vertices).mean(axis=0) - np.mean(objs, axis=0))[:2]
    if np.linalg.norm(v) < 1e-3 * result.resolved.diag:
        return AZIMUTH
    # the free camera sits at -(cos a, sin a) from the look-at point: put it on the part's side,
    # turned 35 degrees for an oblique view
    return float(np.degrees(np.arctan2(-v[1], -v[0]))) + 35.0


#: The skin files are for slicers, which read STL/PLY in millimetres.
SKIN_FILE_UNITS = "mm"


def save_skin(mesh, path: Path) -> Path:
    """Write the skin for printing: STL/PLY in millimetres (simfab works in metres inside;
    read it back with ``simfab.io.mesh.load_mesh(path, units="mm")``)."""

    m = mesh.copy()
    m.apply_scale(1000.0)
    return save_mesh(m, path)


def write_all(result, mesh, out: Path, *, stem: str = "growth") -> dict:
    """Write every output of a run under ``out``; returns name -> path. The files appear
    together: a failure in any writer leaves none of them (``atomic_paths``)."""

    out = Path(out)
    stem = safe_name(stem)  # scene names come from files: no separators, no '..'
    paths = {"skin_stl": out / f"{stem}_skin.stl", "skin_ply": out / f"{stem}_skin.ply",
             "skeleton_json": out / f"{stem}_skeleton.json", "usd": out / f"{stem}.usdc",
             "mjcf": out / f"{stem}_grown.xml", "png": out / f"{stem}_preview.png",
             "camera_json": out / f"{stem}_preview_camera.json"}
    with atomic_paths(paths) as tmp:
        save_skin(mesh, tmp["skin_stl"])
        save_skin(mesh, tmp["skin_ply"])
        write_skeleton(result, tmp["skeleton_json"])
        write_usd(result, mesh, tmp["usd"])
        write_mjcf(result, mesh, tmp["mjcf"])
        render_preview(tmp["mjcf"], tmp["png"], preview_azimuth(result, mesh), tmp["camera_json"],
                       title=f"{stem}: grown support ({len(result.scene.target_names)} targets)")
    return {k: str(v) for k, v in paths.items()}


def render_preview(mjcf: Path, png: Path, azimuth: float, camera_json: Path | None = None, *,
                   title: str = "") -> Path:
    """PNG of the MJCF from ``azimuth`` with a title and a scale bar; ``camera_json`` receives the
    camera of the picture (the --camera of ``simfab grow edit``, so a stroke can be drawn over
    it). Falls back to the default view (and matplotlib without OpenGL) through
    :func:`simfab.io.render.render_mjcf`."""

    cam: dict = {}
    model = load_model(mjcf)
    try:
        render_model(model, png, azimuth=azimuth, camera=cam)
    except Exception:  # no usable OpenGL: render_mjcf knows the fallback
        render_mjcf(mjcf, png)
        cam = {}
    if cam:
        annotate_png(png, cam, title=title)
    if camera_json is not None:
        write_json(camera_json, cam or {"note": "no OpenGL: the matplotlib fallback has no pinhole camera"})
    return png


# --------------------------------------------------------------------------- structural check
def check_surface(check):
    """The loaded support's surface for display: (faces (f, 3) into the returned points, rest
    points (k, 3) [m], displacement (k, 3) [m], von Mises (k,) [Pa]: at each surface corner the
    largest critical-distance mean over the corners of the elements sharing it)."""
    m = check.model
    F = np.asarray(m.boundary_facets[:, :3])
    used, inv = np.unique(F, return_inverse=True)
    node_vm = np.zeros(m.n_vertices)
    np.maximum.at(node_vm, np.asarray(m.corner_elements).ravel(), check.point_von_mises)
    return inv.reshape(F.shape), m.rest[used], check.u[used], node_vm[used]


def write_check_usd(check, scene, path: Path) -> Path:
    """USD stage of the structural check: the objects (static), the support's surface at rest
    (time code 0) and loaded (time code 1, true displacement), with per-vertex primvars
    ``von_mises`` [Pa] (the critical-distance mean) and ``displacement`` [m] (magnitude)."""

    faces, X, u, vm = check_surface(check)
    w = StageWriter(path)
    for name, m in scene.objects.items():
        w.add_mesh(f"objects/{_ident(name)}", np.asarray(m.faces), np.asarray(m.vertices), color=OBJECT_RGBA[:3])
    w.add_mesh("support", faces, X)
    disp = np.linalg.norm(u, axis=1)
    for t, x in ((0, X), (1, X + u)):
        w.set_points("support", x, t)
        w.set_scalar("support", "displacement", disp, t, vmin=0.0, vmax=float(disp.max()) or 1.0, units="m")
        w.set_scalar("support", "von_mises", vm, t, vmin=0.0, vmax=float(vm.max()) or 1.0, units="Pa",
                     cmap="inferno")
    return w.save()


def write_check_png(check, path: Path, *, title: str) -> Path:
    """PNG of the support's surface coloured by the von Mises stress [MPa] (critical-distance mean),
    the peak marked, with a colour bar and the safety factor in the title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection


    faces, X, _, vm = check_surface(check)
    fig = plt.figure(figsize=(7.5, 6.5), dpi=120)
    ax = fig.add_subplot(projection="3d")
    mpa = vm / 1e6
    norm = matplotlib.colors.Normalize(vmin=0.0, vmax=float(mpa.max()) or 1.0)
    cmap = matplotlib.colormaps["inferno"]
    Xmm = X * 1e3
    poly = Poly3DCollection(Xmm[faces], facecolors=cmap(norm(mpa[faces].mean(axis=1))), edgecolors="none")
    ax.add_collection3d(poly)
    p = check.peak_point * 1e3
    ax.scatter(*p, s=80, marker="o", facecolors="none", edgecolors="cyan", linewidths=2,
               label=f"peak {check.max_von_mises_Pa / 1e6:.3g} MPa", depthshade=False)
    lo, hi = Xmm.min(axis=0), Xmm.max(axis=0)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(np.maximum(hi - lo, 1e-9))
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_zlabel("z [mm]")
    ax.view_init(elev=20, azim=-60)
    ax.legend(loc="upper left")
    sm = matplotlib.cm.ScalarMappable(norm=norm, cmap=cmap)
    fig.colorbar(sm, ax=ax, shrink=0.7, label=f"von Mises stress, {check.critical_distance_m * 1e3:.3g} mm "
                                                "critical-distance mean [MPa]")
    ax.set_title(title, fontsize=10)
    return save_figure(fig, path, close=True)


def write_check(check, scene, out: Path, *, stem: str) -> dict:
    """USD stage and PNG of a structural check under ``out`` (together or not at all)."""

    out = Path(out)
    stem = safe_name(stem)
    paths = {"check_usd": out / f"{stem}_check.usdc", "check_png": out / f"{stem}_check.png"}
    title = (f"{stem}: loaded support, safety factor {check.safety_factor:.3g} "
             f"(yield {check.yield_stress_Pa / 1e6:.3g} MPa, {check.material_name})\n"
             f"max deflection {max(check.deflection_m.values(), default=0.0) * 1e3:.3g} mm, "
             f"mass {check.mass_kg * 1e3:.3g} g")
    with atomic_paths(paths) as tmp:
        write_check_usd(check, scene, tmp["check_usd"])
        write_check_png(check, tmp["check_png"], title=title)
    return {k: str(v) for k, v in paths.items()}


def write_check_outputs(check, strengthened, scene, out: Path, *, stem: str) -> dict:
    """Write a check's USD/PNG (and, with ``strengthened``, a :class:`simfab.growth.structure.
    StrengthenResult`, the strengthened skeleton, skin and check) under ``out``.

    Returns:
        {"check": {label: path}, "strengthened": {label: path} or None}.
    """
    from simfab.growth.skeleton import to_json_dict
    from simfab.io.atomic import atomic_paths, write_json
    from simfab.io.outpaths import safe_name

    stem = safe_name(stem)
    out = Path(out)
    files = {"check": write_check(check, scene, out, stem=stem), "strengthened": None}
    if strengthened is not None:
        paths = {"skeleton_json": out / f"{stem}_strengthened_skeleton.json",
                 "skin_stl": out / f"{stem}_strengthened_skin.stl"}
        with atomic_paths(paths) as tmp:
            write_json(tmp["skeleton_json"], to_json_dict(strengthened.skeleton, scene=str(scene.path.resolve())
                                                          if scene.path else None, strengthen=strengthened.summary()))
            save_skin(strengthened.check.mesh, tmp["skin_stl"])
        st = {k: str(v) for k, v in paths.items()}
        st.update(write_check(strengthened.check, scene, out, stem=f"{stem}_strengthened"))
        files["strengthened"] = st
    return files


def edit_paths(out: Path, stem: str) -> dict:
    """Label -> path of the files of a sketch edit (``simfab grow edit``) with file stem ``stem``."""
    out = Path(out)
    return {"skeleton_json": out / f"{stem}_skeleton.json", "skin_stl": out / f"{stem}_skin.stl",
            "skin_ply": out / f"{stem}_skin.ply", "png": out / f"{stem}_preview.png"}


def write_edit(edited, mesh, objects: dict, camera, stroke, paths: dict, *, skeleton_extra: dict,
               title: str) -> dict:
    """Write a sketch edit's files together (none if any write fails).

    Args:
        edited: the edited :class:`simfab.growth.skeleton.Skeleton`.
        mesh: its skin (``trimesh.Trimesh``, metres).
        objects: the scene's object meshes (name -> mesh) drawn in the preview.
        camera: the edit's :class:`simfab.growth.sketch.Camera`; stroke: the stroke (m, 2) [px].
        paths: :func:`edit_paths`.
        skeleton_extra: extra keys of the skeleton JSON (scene, seed, edit report).
        title: the preview's title.

    Returns:
        Label -> path (strings) of the files written.
    """
    with atomic_paths(paths) as tmp:
        write_json(tmp["skeleton_json"], to_json_dict(edited, **skeleton_extra))
        save_skin(mesh, tmp["skin_stl"])
        save_skin(mesh, tmp["skin_ply"])
        edit_preview(tmp["png"], mesh, objects, camera, stroke, title=title)
    return {k: str(v) for k, v in paths.items()}


def edit_preview(png, mesh, objects: dict, camera, stroke, *, title: str):
    """The edited skin with the scene's objects, seen through the edit's camera, the stroke drawn
    over it in red, titled and with a scale bar."""
    import dataclasses

    from PIL import Image, ImageDraw

    from simfab.io.atomic import atomic_path
    from simfab.io.render import render_meshes

    cam = dataclasses.asdict(camera)
    items = [(m.vertices, m.faces, OBJECT_RGBA[:3]) for m in objects.values()] + [(mesh.vertices, mesh.faces,
                                                                                    SKIN_RGBA[:3])]
    got: dict = {}
    render_meshes(items, png, width=camera.width, height=camera.height, view=cam, camera=got, floor=False)
    img = Image.open(png).convert("RGB")
    d = ImageDraw.Draw(img)
    d.line([tuple(map(float, p)) for p in stroke], fill=(230, 30, 30), width=max(2, camera.height // 160))
    with atomic_path(png) as tmp:
        img.save(tmp, format="PNG")
    if got:
        annotate_png(png, got, title=title)
    return png
