"""Outputs of a rest-shape optimization.

Written together into ``--out`` (temporaries renamed only when all succeeded):

- ``NAME_optimized_part.stl``: the optimized part in millimetres (2D: the section extruded by the
  scene's thickness; 3D: the boundary surface), 3D-printable (closed, outward normals);
  2D also ``NAME_optimized_outline.csv`` (loop, x_mm, y_mm: the boundary loops in order);
- the optimized scene ``NAME_optimized.xml`` + ``.toml`` + ``_part.npz`` (the optimized mesh,
  same connectivity): ``simfab couple simulate OUT/NAME_optimized.xml`` runs it unchanged;
- ``NAME_design_profile.png``: initial vs optimized energy and force profiles with the brief's
  bands; ``NAME_design_shape.png``: initial silhouette under the optimized shape, handles marked;
- ``NAME_design_history.csv``: one row per iteration (the annealer's temperature and sigma_rel
  columns under annealing only);
- ``NAME_design.usda``: time codes 0..A-1 replay the A accepted rest shapes (custom attribute
  ``simfab:objective`` per time code), then the final design's insertion (object animated);
- ``NAME_design_summary.json``: objective, E_L, each constraint's value/bounds/satisfied,
  iterations, simulations, rejected candidates by reason, seconds.
"""

from __future__ import annotations

import shutil
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import tomli_w

from simfab.coupling.outputs import display_faces, extruded_slab, object_display, stress_colour_top, vertex_von_mises
from simfab.coupling.scene import stored_part_table
from simfab.design import brief as B
from simfab.design.problem import lift_rest
from simfab.design.synthesis import boundary_loops
from simfab.io.atomic import atomic_paths, save_figure, write_csv, write_json, write_text
from simfab.io.mesh import save_mesh
from simfab.io.usd import StageWriter

HISTORY_HEADER = ["iteration", "status", "reason", "objective", "E_L", "rms_error_N", "accepted", "current_objective",
                  "best_objective", "temperature", "sigma_rel", "coupling_ratio_pct", "grip_force_N",
                  "insertion_force_N", "removal_force_N", "von_mises_avg_Pa", "max_von_mises_Pa", "seat_clearance_m",
                  "category",
                  "seconds"]


def output_paths(out: Path, stem: str, dim: int, *, target: bool = False) -> dict:
    out = Path(out)
    p = {"part_stl": out / f"{stem}_optimized_part.stl", "scene_xml": out / f"{stem}_optimized.xml",
         "scene_toml": out / f"{stem}_optimized.toml", "scene_mesh": out / f"{stem}_optimized_part.npz",
         "profile_png": out / f"{stem}_design_profile.png", "shape_png": out / f"{stem}_design_shape.png",
         "history_csv": out / f"{stem}_design_history.csv", "usd": out / f"{stem}_design.usda",
         "summary_json": out / f"{stem}_design_summary.json"}
    if dim == 2:
        p["outline_csv"] = out / f"{stem}_optimized_outline.csv"
    if target:
        p["scene_target"] = out / f"{stem}_optimized_target.csv"
    return p


def insertions(res) -> int:
    """Every insertion simulation an optimization ran: complete, stopped early, and (annealing on
    workers) run ahead and not needed; the mesh check's are not counted."""
    return int(res.simulations + res.stopped_simulations + res.speculative)


#: The annealing-only columns of the history CSV (left out under the gradient method).
ANNEAL_COLUMNS = ("temperature", "sigma_rel")


def history_table(rows) -> tuple[list[str], list[list]]:
    """The history CSV: (header, rows) of typed history rows (:func:`simfab.design.optimize.history_rows`);
    the annealing columns only when the rows carry them."""
    anneal = bool(rows) and all(hasattr(r, "sigma_rel") for r in rows)
    header = [h for h in HISTORY_HEADER if anneal or h not in ANNEAL_COLUMNS]
    table = []
    for r in rows:
        ev = r.evaluation
        f = ev.figures
        state = [r.temperature, r.sigma_rel] if anneal else []
        table.append([r.iteration, ev.status, ev.reason, ev.objective, ev.E_L, ev.rms_error, int(r.accepted),
                      r.current_objective, r.best_objective, *state, f.get("coupling_ratio"), f.get("grip_force"),
                      f.get("insertion_force"), f.get("removal_force"), f.get("von_mises"), f.get("von_mises_peak"),
                      f.get("seat_clearance"), f.get("category", ""), ev.seconds])
    return header, table


def part_mesh_mm(fem, X: np.ndarray):
    """trimesh of the part with rest shape X in millimetres (2D: extruded by the thickness)."""
    import trimesh  # deferred: about a second of start-up, for writing the part only

    if fem.dim == 2:
        V, F = extruded_slab(X, np.asarray(fem.elements), np.asarray(fem.boundary_facets), fem.thickness)
    else:
        V, F = X, np.asarray(fem.boundary_facets)
    m = trimesh.Trimesh(np.asarray(V) * 1e3, np.asarray(F), process=True)
    m.remove_unreferenced_vertices()
    return m


def write_outline_csv(fem, X: np.ndarray, path) -> Path:
    rows = []
    for k, loop in enumerate(boundary_loops(fem.boundary_facets)):
        rows += [[k, float(X[v, 0] * 1e3), float(X[v, 1] * 1e3)] for v in loop]
    return write_csv(path, ["loop", "x_mm", "y_mm"], rows)


def write_optimized_scene(res, scene_xml: Path, scene_toml: Path, paths: dict, tmp: dict, stem: str) -> None:
    """The optimized scene: the original MJCF with the part's display mesh replaced, the TOML with
    the optimized mesh as ``mesh_file`` (same material, object, path, fixed region, options; in 3D
    beside its surface, the printable STL: :func:`simfab.coupling.scene.stored_part_table`)."""
    fem = res.problem.mesh  # (the design's linear mesh: a P2 scene's TOML lifts it again)
    X = res.best.rest
    np.savez(tmp["scene_mesh"], points=X, elements=np.asarray(fem.elements))
    cfg = tomllib.loads(Path(scene_toml).read_text(encoding="utf-8"))
    cfg["name"] = f"{stem}_optimized"
    if fem.dim == 2:  # (beside the outline CSV its boundary loops: a convergence study meshes it again)
        comp = {"outline": paths["outline_csv"].name, "units": "mm", "thickness": float(fem.thickness),
                "target_elements": len(fem.elements), "mesh_file": paths["scene_mesh"].name}
    else:  # (the printable STL is the tets' surface: a convergence study meshes it again)
        comp = stored_part_table(paths["scene_mesh"].name, paths["part_stl"].name, "mm", len(fem.elements))
    cfg["compliant"] = comp
    # the insertion options the optimizer simulated with (command-line overrides included)
    opts = res.problem.base.options
    simc = dict(cfg.get("simulation", {}))
    for k in ("steps", "h_in", "L_max"):
        simc.pop(k, None)
        if getattr(opts, k) is not None:
            simc[k] = getattr(opts, k)
    cfg["simulation"] = simc
    mu = res.problem.base.contact.friction  # the friction it was designed with (--friction included)
    if mu > 0 or "contact" in cfg:
        cfg["contact"] = {**cfg.get("contact", {}), "friction": float(mu)}
    tgt = res.problem.target
    if tgt is not None:  # the optimized scene carries its own copy of the target profile
        shutil.copyfile(tgt.source, tmp["scene_target"])
        cfg.setdefault("design", {})["target_profile"] = paths["scene_target"].name
    write_text(tmp["scene_toml"], "# written by simfab couple optimize: the optimized rest shape of "
               f"{Path(scene_toml).name}\n" + tomli_w.dumps(cfg))
    tree = ET.parse(scene_xml)
    root = tree.getroot()
    root.set("model", f"{stem}_optimized")
    V, F = _display_mesh(fem, X)
    for m in root.iter("mesh"):
        if m.get("name") == "part":
            m.set("vertex", " ".join(f"{v:.9g}" for v in V.ravel()))
            m.set("face", " ".join(str(int(i)) for i in F.ravel()))
    write_text(tmp["scene_xml"], ET.tostring(root, encoding="unicode"))


def _display_mesh(fem, X):
    if fem.dim == 2:
        return extruded_slab(X, np.asarray(fem.elements), np.asarray(fem.boundary_facets), fem.thickness)
    F = np.asarray(fem.boundary_facets)
    used = np.unique(F)
    remap = np.full(len(X), -1)
    remap[used] = np.arange(len(used))
    return X[used], remap[F]


def plot_profiles(res, path, mesh_check=None) -> Path:
    """Energy and force profiles of the initial and the optimized design, with the brief's bands.
    The titles list the constraints: the mesh check's mesh-converged figures when ``mesh_check``
    (a :class:`simfab.design.verify.MeshCheck`) is given, which decide whether the design meets the brief, else the
    optimizer's own (coarse-mesh, mesh-corrected) figures."""
    import matplotlib  # deferred: pyplot costs about a second of start-up, and only plotting needs it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7.0, 6.4), dpi=120, sharex=True)
    lim = res.problem.limits
    for ev, style, label in ((res.initial, "--", "initial"), (res.best, "-", "optimized")):
        r = ev.result
        s = r.column("s") * 1e3
        ax1.plot(s, r.column("energy") * 1e3, style, lw=2, label=f"{label} ({ev.figures.get('category')})")
        ax2.plot(s, r.column("force"), style, lw=2, label=label)
    if "insertion_force" in lim:
        lo, hi = lim["insertion_force"]
        ax2.axhspan(-min(hi, 1e9), -lo, color="tab:orange", alpha=0.12, label="insertion force bounds (F < 0)")
    if "removal_force" in lim:
        lo, hi = lim["removal_force"]
        ax2.axhspan(lo, min(hi, 1e9), color="tab:green", alpha=0.12, label="removal force bounds (F > 0)")
    tgt = res.problem.target
    if tgt is not None:
        ax2.plot(tgt.s * 1e3, tgt.force, ":", color="k", lw=2, label="target profile")
        c = res.problem.settings.corrections.get("force_profile", 1.0)
        if c != 1.0:  # what the optimizer matched to the target: the coarse profile times its mesh correction
            r = res.best.result
            ax2.plot(r.column("s") * 1e3, c * r.column("force"), "-", color="tab:red", lw=1,
                     label=f"optimized x {c:.3g} (mesh-corrected, RMS {res.best.rms_error:.3g} N)")
    ax2.axhline(0.0, color="0.6", lw=0.8)
    yl = ax2.get_ylim()
    init_f = res.initial.result.column("force")
    best_f = res.best.result.column("force")
    span = max(np.abs(best_f).max(), np.abs(init_f).max() if np.abs(init_f).max() < 20 * np.abs(best_f).max() else 0)
    if tgt is not None:
        span = max(span, np.abs(tgt.force).max())
    ax2.set_ylim(max(yl[0], -1.3 * span), min(yl[1], 1.3 * span))
    e_init = float(res.initial.result.column("energy").max()) * 1e3
    e_best = float(res.best.result.column("energy").max()) * 1e3
    if e_best > 0 and e_init > 20 * e_best:  # energies orders of magnitude apart: both stay readable
        ax1.set_yscale("symlog", linthresh=0.1 * e_best)
        ax1.set_ylim(bottom=0.0)  # (elastic energy >= 0)
        ax1.set_ylabel(f"elastic energy [mJ]\n(log above {0.1 * e_best:.2g} mJ)")
    else:
        ax1.set_ylabel("elastic energy [mJ]")
    ax2.set_ylabel("force on the object [N]\n(resisting insertion < 0)")
    ax2.set_xlabel("insertion distance [mm]")
    ax1.legend(fontsize=8, loc="upper left")
    ax2.legend(fontsize=7, loc="lower left")
    if mesh_check is not None:
        cons = [(c.name, c.value, c.lo, c.hi, c.satisfied) for c in mesh_check.constraints]
        what = " (constraints: mesh-converged figures)"
    else:
        cons = [(c.name, c.value, c.lo, c.hi, c.satisfied) for c in res.best.constraints]
        what = " (constraints on mesh-corrected figures)" if res.problem.settings.corrections else ""
    lines = []
    for name, value, lo, hi, ok in cons:
        u = B.UNITS[name]
        k, uu = {"Pa": (1e-6, "MPa"), "m": (1e3, "mm")}.get(u, (1.0, u))
        lo = "-inf" if lo is None or not np.isfinite(lo) else f"{lo * k:.3g}"
        hi = "inf" if hi is None or not np.isfinite(hi) else f"{hi * k:.3g}"
        lines.append(f"{name} {value * k:.3g} {uu} in [{lo}, {hi}] {'ok' if ok else 'VIOLATED'}")
    ax1.set_title(f"{res.problem.base.name}: before / after rest-shape optimization{what}\n"
                  + "; ".join(lines[:3]), fontsize=8)
    if len(lines) > 3:
        ax2.set_title("; ".join(lines[3:]), fontsize=8)
    fig.tight_layout()
    return save_figure(fig, path, close=True)


def plot_shape(res, path) -> Path:
    """Initial silhouette (grey) under the optimized shape (colour), handles marked."""
    import matplotlib  # deferred: pyplot costs about a second of start-up, and only plotting needs it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    fem = res.problem.mesh
    H = res.problem.handles
    X0, X1 = np.asarray(fem.rest) * 1e3, res.best.rest * 1e3
    fig, ax = plt.subplots(figsize=(6.4, 5.6), dpi=120)
    if fem.dim == 2:
        el = np.asarray(fem.elements)
        ax.add_collection(PolyCollection(X0[el], facecolor="0.8", edgecolor="0.8", lw=0.3, label="initial"))
        ax.add_collection(PolyCollection(X1[el], facecolor="tab:orange", edgecolor="0.35", lw=0.2, alpha=0.75,
                                         label="optimized"))
        P0, P1 = X0, X1
    else:  # 3D: the boundary vertices projected onto the two axes of largest extent
        bv = np.asarray(fem.boundary_vertices)
        ext = np.ptp(X0, axis=0)
        ax_ids = np.argsort(ext)[::-1][:2]
        P0, P1 = X0[:, ax_ids], X1[:, ax_ids]
        ax.scatter(*P0[bv].T, s=2, color="0.7", label="initial (boundary vertices)")
        ax.scatter(*P1[bv].T, s=2, color="tab:orange", label="optimized")
    act = H.vertex[H.active]
    t, _ = H.split(res.best.h)
    ax.plot(*P0[act].T[:2], "o", color="tab:red", ms=7, mfc="none", mew=2, label="active handles (initial)")
    ax.plot(*P1[act].T[:2], "o", color="tab:red", ms=4, label="active handles (optimized)")
    for a, b in zip(P0[act], P1[act]):
        ax.annotate("", xy=b[:2], xytext=a[:2], arrowprops=dict(arrowstyle="->", color="tab:red", lw=1))
    kept = res.problem.kept
    ax.plot(*P0[kept].T[:2], "x", color="tab:blue", ms=4, label="kept (inactive handles)")
    ax.set_aspect("equal")
    ax.autoscale_view()
    lo = np.minimum(P0.min(0), P1.min(0))[:2]
    hi = np.maximum(P0.max(0), P1.max(0))[:2]
    pad = 0.08 * (hi - lo).max()
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_xlabel("x [mm]" if fem.dim == 2 else f"{'xyz'[ax_ids[0]]} [mm]")
    ax.set_ylabel("y [mm]" if fem.dim == 2 else f"{'xyz'[ax_ids[1]]} [mm]")
    ax.legend(fontsize=7, loc="best")
    ax.set_title(f"{res.problem.base.name}: optimized rest shape (E_L = {res.best.E_L:.3g})")
    fig.tight_layout()
    return save_figure(fig, path, close=True)


def write_usd(res, path) -> Path:
    """Accepted rest shapes (one time code each, ``simfab:objective`` attribute), then the final
    design's insertion (the object animated)."""
    cm = res.problem.base
    fem = cm.fem
    w = StageWriter(path, time_codes_per_second=12.0)
    w.add_mesh("part", display_faces(cm), fem.rest, color=[0.85, 0.55, 0.25])
    ov, of = object_display(cm)
    w.add_rigid("object", points=ov, faces=of, color=[0.55, 0.6, 0.7])
    final = res.best.result
    start_pos, start_quat = final.steps[0].pos, final.steps[0].quat
    t = 0
    for k, X, val in res.accepted:
        w.set_points("part", lift_rest(fem, X), t)
        w.set_attribute("part", "objective", val, t)
        w.set_attribute("part", "iteration", k, t)
        w.set_pose("object", start_pos, start_quat, t)
        t += 1
    stress = [vertex_von_mises(fem, r.von_mises) for r in final.steps]
    vmax = stress_colour_top(stress)
    for r, vm in zip(final.steps, stress):
        w.set_points("part", r.x, t)
        w.set_scalar("part", "von_mises", vm, t, interpolation="vertex", vmin=0.0, vmax=vmax, units="Pa")
        w.set_attribute("part", "objective", res.best.objective, t)
        w.set_pose("object", r.pos, r.quat, t)
        t += 1
    return w.save()


def write_all(result, out: Path, *, stem: str | None = None):
    """Write every output (see the module docstring) together.

    Args:
        result: a :class:`simfab.design.pipeline.DesignResult` (its ``optimization``, ``history``,
            ``scene_xml``/``scene_toml``).
        out: the output folder.
        stem: the files' stem (default: the scene's name).

    Returns:
        ``result`` with ``outputs``; the summary JSON holds its ``to_json()``.
    """
    import dataclasses

    res = result.optimization
    fem = res.problem.mesh
    stem = stem or res.problem.base.name
    paths = output_paths(out, stem, fem.dim, target=res.problem.target is not None)
    result = dataclasses.replace(result, outputs={k: str(v) for k, v in paths.items()})
    header, rows = history_table(result.history)
    with atomic_paths(paths) as tmp:
        save_mesh(part_mesh_mm(fem, res.best.rest), tmp["part_stl"])
        if fem.dim == 2:
            write_outline_csv(fem, res.best.rest, tmp["outline_csv"])
        write_optimized_scene(res, result.scene_xml, result.scene_toml, paths, tmp, stem)
        plot_profiles(res, tmp["profile_png"], result.mesh_check)
        plot_shape(res, tmp["shape_png"])
        write_csv(tmp["history_csv"], header, rows)
        write_usd(res, tmp["usd"])
        write_json(tmp["summary_json"], result.to_json())
    return result
