"""Files of a surface deployment: flattening / pattern / deviation PNGs and the USD stage.

- flattening PNG: the target (3D, coloured by the log scale factor u) and its flattening
  (u as colour, boundary in black), colour bar in u [-];
- pattern PNG: the laser-cut outlines (black) with each insert gap coloured by r - g [mm]
  (> 0: the insert pushes, dome; < 0: pulls, saddle), unreachable gaps crossed, the seams of a
  cut flattening (green), a 50 mm bar;
- deviation PNG: the deployed quad mesh after the best rigid alignment, coloured by the
  distance of each vertex to the target [mm], the target as grey wireframe;
- USD: rods as curves with widths (one time code per quasi-static increment, 0 = flat), the
  inserts as animated box meshes, the target surface as a translucent reference mesh placed by
  the inverse of the deviation's alignment (so it overlays the deployed state).
"""

from __future__ import annotations

import numpy as np

from simfab.deploy.export import bending_strain, rod_polylines
from simfab.deploy.lasercut import SCALE_BAR_MM
from simfab.io.atomic import save_figure
from simfab.io.usd import StageWriter
from simfab.rotations import matrix_to_quat


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def write_flattening_png(path, res) -> None:
    """The flattening PNG (see the module doc).

    Args:
        path: the image file.
        res: the :class:`simfab.deploy.pipeline.SurfaceRun`.
    """
    plt = _plt()
    tgt, f, cf = res.scene.target, res.flat, getattr(res, "cuts", None)
    V, F = (tgt.V, tgt.F) if cf is None else (cf.V, cf.F)  # with cuts: the cut mesh (its flattening)
    fig = plt.figure(figsize=(11, 5))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    vmin, vmax = float(min(f.u.min(), -1e-6)), float(max(f.u.max(), 1e-6))
    lim = max(-vmin, vmax)
    tri = ax.plot_trisurf(V[:, 0], V[:, 1], V[:, 2], triangles=F, cmap="coolwarm",
                          linewidth=0.0, antialiased=False)
    tri.set_array(f.u[F].mean(axis=1))
    tri.set_clim(-lim, lim)
    ax.set_box_aspect(np.ptp(tgt.V, axis=0) + 1e-9)
    ax.set_title(f"target ({len(tgt.V)} vertices), colour: u")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax2 = fig.add_subplot(1, 2, 2)
    tp = ax2.tripcolor(f.uv[:, 0] * 1e3, f.uv[:, 1] * 1e3, F, f.u, cmap="coolwarm", vmin=-lim, vmax=lim,
                       shading="gouraud")
    b = np.r_[f.boundary, f.boundary[0]]
    ax2.plot(f.uv[b, 0] * 1e3, f.uv[b, 1] * 1e3, "k-", lw=1.2,
             label="boundary (lengths kept, u = 0)" if cf is None else "boundary and seams (u = 0 on the rim)")
    if cf is not None and len(cf.cones):
        for k, s in enumerate(cf.seams):
            for j, side in enumerate(s.sides):
                ax2.plot(f.uv[side, 0] * 1e3, f.uv[side, 1] * 1e3, "-", color="tab:green", lw=1.5,
                         label="seams (both sides of each cut)" if k == 0 and j == 0 else None)
        tip = [int(np.flatnonzero(cf.orig == c)[0]) for c in cf.cones]
        ax2.scatter(f.uv[tip, 0] * 1e3, f.uv[tip, 1] * 1e3, marker="*", s=80, c="k", zorder=4,
                    label=f"{len(tip)} cones ({np.degrees(cf.cone_defect.min()):.0f}-"
                          f"{np.degrees(cf.cone_defect.max()):.0f} deg)")
        ax.scatter(*tgt.V[cf.cones].T, marker="*", s=60, c="k")
    ax2.set_aspect("equal")
    ax2.set_xlabel("x [mm]")
    ax2.set_ylabel("y [mm]")
    ax2.set_title(f"BFF flattening: u in [{f.u.min():.3f}, {f.u.max():.3f}]\n"
                  f"area ratio in [{np.exp(2 * f.sigma.min()):.3f}, {np.exp(2 * f.sigma.max()):.3f}]")
    ax2.legend(loc="lower right", fontsize=7)
    fig.colorbar(tp, ax=ax2, label="log scale factor u [-] (< 0 shrunk, > 0 grown)")
    fig.tight_layout()
    save_figure(fig, path)


def write_pattern_png(path, res) -> None:
    """The pattern PNG (see the module doc).

    Args:
        path: the image file.
        res: the :class:`simfab.deploy.pipeline.SurfaceRun`.
    """
    from matplotlib.collections import LineCollection


    plt = _plt()
    p, cut = res.pattern, res.cut
    fig, ax = plt.subplots(figsize=(8, 8))
    segs = [np.vstack([r, r[:1]]) for r in cut.rings]
    ax.add_collection(LineCollection(segs, colors="k", linewidths=0.5, label="cut"))
    if cut.seams:
        ax.add_collection(LineCollection([pts for _, pts in cut.seams], colors="tab:green", linewidths=1.2,
                                         label="seams (cut paths: edges that meet on the target)"))
    ins = np.flatnonzero(p.interior)
    d = (p.insert_size[ins] - p.gap[ins]) * 1e3
    lim = float(np.max(np.abs(d))) if len(d) else 1.0
    sc = ax.scatter(p.P[ins, 0] * 1e3, p.P[ins, 1] * 1e3, c=d, cmap="coolwarm", vmin=-lim, vmax=lim, s=40,
                    zorder=3, label="insert gap")
    if len(p.unreachable):
        ax.scatter(p.P[p.unreachable, 0] * 1e3, p.P[p.unreachable, 1] * 1e3, marker="x", c="k", s=60, zorder=4,
                   label="unreachable gap")
    x0, y0, x1, y1 = cut.extent
    yb = min(r[:, 1].min() for r in cut.rings) - 6
    ax.plot([x0, x0 + SCALE_BAR_MM], [yb, yb], "k-", lw=3)
    # the label's offset in points and the margin as a fraction of the span: clear of the frame at any extent
    ax.annotate(f"{SCALE_BAR_MM:.0f} mm", (x0 + SCALE_BAR_MM / 2, yb), xytext=(0, -4), textcoords="offset points",
                ha="center", va="top")
    ax.set_xlim(x0 - 5, x1 + 5)
    ax.set_ylim(yb - 6 - 0.06 * (y1 - yb), y1 + 5)
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    sizes = ", ".join(f"{b['count']} x {b['half_size_mm']:.3g}" for b in p.bill_of_materials())
    ax.set_title(f"flat pattern: {p.n_inserts} inserts (r [mm]: {sizes}),\n"
                 f"{cut.parts} parts, cut length {cut.cut_length / 1e3:.2f} m")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=2, fontsize=8)  # (below: off the pattern)
    fig.colorbar(sc, ax=ax, shrink=0.7, label="r - g [mm] (> 0 insert pushes: dome; < 0 pulls: saddle)")
    fig.tight_layout()
    save_figure(fig, path)


def write_deviation_png(path, res) -> None:
    """The deviation PNG (see the module doc).

    Args:
        path: the image file.
        res: the :class:`simfab.deploy.pipeline.SurfaceRun`.
    """
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection


    plt = _plt()
    dv, p, tgt = res.deviation, res.pattern, res.scene.target
    A = dv.aligned * 1e3
    dev = dv.per_vertex * 1e3
    fig = plt.figure(figsize=(9, 7))
    ax = fig.add_subplot(1, 1, 1, projection="3d")
    cmap = plt.get_cmap("viridis")
    vmax = float(dev.max()) or 1.0
    fc = cmap(dev[p.quads].mean(axis=1) / vmax)
    ax.add_collection3d(Poly3DCollection(A[p.quads], facecolors=fc, edgecolors="k", linewidths=0.3))
    V = tgt.V * 1e3
    E = np.concatenate([tgt.F[:, [0, 1]], tgt.F[:, [1, 2]]])[:: max(1, len(tgt.F) // 800)]
    ax.add_collection3d(Line3DCollection(V[E], colors="0.6", linewidths=0.3))  # one artist for the wireframe
    allp = np.vstack([A, V])
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(hi - lo + 1e-9)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_zlabel("z [mm]")
    ax.set_title(f"deployed (aligned) vs target (grey): RMS {dv.rms * 100:.2f} %, Hausdorff {dv.hausdorff * 100:.2f} % "
                 f"of D = {dv.diameter * 1e3:.0f} mm\n{res.shape['kind']} (K_fit = "
                 f"{res.shape['quadric_gaussian_curvature']:.3g} 1/m^2)")
    sm = plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(0, vmax))
    fig.colorbar(sm, ax=ax, shrink=0.6, label="distance to target [mm]")
    fig.tight_layout()
    save_figure(fig, path)


def write_usd(path, res) -> None:
    """The USD stage of the deployment (see the module doc).

    Args:
        path: the ``.usda`` file.
        res: the :class:`simfab.deploy.pipeline.SurfaceRun`.
    """
    import trimesh
    from pxr import UsdGeom, Vt


    net, dep, p = res.network, res.deployment, res.pattern
    model = net.model
    w = StageWriter(path, up_axis="Z", meters_per_unit=1.0)
    w.add_curves("deploy/rods", color=(0.9, 0.85, 0.7))
    widths = [np.full(len(r.nodes), r.section.draw_width()) for r in model.rods]
    ins = np.flatnonzero(p.interior)
    names = []
    for v in ins:
        s = float(p.insert_size[v]) + p.config.beam_width
        box = trimesh.creation.box(extents=[2 * s, 2 * s, 2 * p.config.beam_thickness])
        nm = f"deploy/inserts/insert_{p.insert_ids[v]}"
        w.add_rigid(nm, box.vertices, box.faces, color=(0.85, 0.45, 0.2))
        names.append((nm, net.vertex_body[v]))
    strains = [bending_strain(model, st) for st in dep.states]
    smax = max(float(np.max(e)) for e in strains) or 1.0
    for t, st in enumerate(dep.states):
        w.set_curves("deploy/rods", rod_polylines(model, st), widths, t)
        w.set_scalar("deploy/rods", "bending_strain", strains[t], t, vmin=0.0, vmax=smax, units="-")
        for nm, b in names:
            w.set_pose(nm, st.body_pos[b], matrix_to_quat(st.body_rot[b]), t)
    # the target, moved onto the deployed state: x_target_frame = R x_dep + t  =>  x_dep = R^T (y - t)
    dv = res.deviation
    Vt_ = (res.scene.target.V - dv.t) @ dv.R
    w.add_mesh("deploy/target", res.scene.target.F, Vt_, color=(0.3, 0.5, 0.9))
    mesh = UsdGeom.Mesh(w.stage.GetPrimAtPath("/World/deploy/target"))
    mesh.CreateDisplayOpacityAttr(Vt.FloatArray([0.35]))
    w.save()


def write_bom_csv(path, res) -> None:
    """Bill of materials of the inserts: one row per catalogue size (class, half-size r [mm], plate side
    [mm], count, insert numbers separated by spaces).

    Args:
        path: the CSV file.
        res: the :class:`simfab.deploy.pipeline.SurfaceRun`.
    """
    import csv

    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["size_class", "half_size_mm", "plate_side_mm", "count", "inserts"])
        for b in res.pattern.bill_of_materials():
            w.writerow([b["size_class"], f"{b['half_size_mm']:.4g}", f"{b['plate_side_mm']:.4g}", b["count"],
                        " ".join(str(i) for i in b["inserts"])])
