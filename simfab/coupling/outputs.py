"""Outputs of an insertion simulation: profile CSV + JSON summary, plot, USD stage, MJCF.

All files of a run are written atomically and together (temporaries renamed only when every
writer succeeded; see :func:`write_all`). Units: SI (m, J, N, Pa); the plot's axis shows
the insertion distance in mm.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simfab.coupling.profile import ProfileSummary, analyze_run, record_phases, rest_bracket
from simfab.coupling.settle import energy_balance
from simfab.coupling.simulate import InsertionResult
from simfab.io.atomic import atomic_paths, save_figure, write_csv, write_json
from simfab.io.mjcf import MAX_KEYFRAMES, MJCFBuilder
from simfab.io.outpaths import safe_name
from simfab.io.usd import StageWriter
from simfab.rotations import quat_to_matrix

#: Units of the summary keys (also written into the JSON summary).
SUMMARY_UNITS = {
    "E_max": "J", "E_ss": "J", "coupling_ratio": "%", "F_in": "N", "F_rm": "N", "F_grip": "N",
    "max_von_mises": "Pa", "max_penetration": "m", "min_det_F": "-", "seconds": "s", "kappa_initial": "N/m",
    "kappa_final": "N/m", "dhat": "m", "s_max": "m", "s_path_end": "m", "s_ss": "m", "friction": "-",
    "F_hold": "N", "dissipated": "J", "energy_balance": "-", "jammed_at": "m",
    "averaged_von_mises": "Pa", "stress_radius": "m",
}

#: One row per record, the insertion's then (with friction) the removal's: ``phase`` says which; in
#: both, s_m is the position along the path and path_force_N the force on O along the path's forward
#: tangent (the removal runs back over the same positions, so the phases compare row by row).
CSV_HEADER = ["step", "s_m", "energy_J", "force_N", "path_force_N", "grip_N", "max_von_mises_Pa", "max_penetration_m",
              "min_det_F", "newton_iterations", "contact_points", "phase", "normal_force_N", "path_force_friction_N",
              "dissipated_J", "lag_solves"]
#: What each profile column means, its unit and its sign convention (written into the JSON summary as
#: ``profile_columns``; the user guide's table is generated from it).
CSV_COLUMN_DOCS = {
    "step": "record index (0: the start)",
    "s_m": "position of O along its path [m] (translation plus rotation angle times rho)",
    "energy_J": "elastic energy stored in the part [J]",
    "force_N": "force on O along its translation from the supports' reactions [N]: negative = the part resists "
               "(pushing O in takes -force_N), positive = the part draws O in",
    "path_force_N": "force on O along the path's forward tangent [N], = -dE/ds without friction: same sign "
                    "convention as force_N (negative resists forward motion)",
    "grip_N": "grip force: total normal contact force squeezing O [N], >= 0",
    "max_von_mises_Pa": "largest element von Mises stress [Pa]",
    "max_penetration_m": "deepest penetration of the part into O [m] (<= the penetration tolerance)",
    "min_det_F": "smallest deformation-gradient determinant [-] (> 0: no inverted element)",
    "newton_iterations": "Newton iterations of the record's step",
    "contact_points": "constraint points within the barrier's range",
    "phase": "insert (planned steps along the keyframes), rest (the search for the rest point past the keyframes' "
             "end; its last probe may overshoot it: read F_in/F_grip from the summary), remove (with friction: "
             "the removal traversal back over the same positions)",
    "normal_force_N": "sum of the contact normal forces [N], >= 0",
    "path_force_friction_N": "friction's part of path_force_N [N] (opposes the motion: negative on insertion, "
                             "positive on removal)",
    "dissipated_J": "work dissipated by friction over the record's step [J], >= 0",
    "lag_solves": "friction lagging solves of the step",
}


def summarize(res: InsertionResult) -> tuple[ProfileSummary, dict]:
    """(profile summary, JSON-ready dict of the key figures)."""
    prof = analyze_run(res)
    records = [*res.steps, *res.removal]
    d = {
        "scene": res.model.name,
        "category": prof.category,
        "E_max": prof.E_max,
        "E_ss": prof.E_ss,
        "coupling_ratio": prof.coupling_ratio,
        "F_in": prof.F_in,
        "F_rm": prof.F_rm,
        "F_grip": prof.F_grip,
        "s_max": float(res.steps[prof.index_max].s),
        "s_ss": float(res.steps[prof.index_ss].s),
        "E_ss_stationary": prof.stationary,
        "s_path_end": float(res.model.path.length),
        "max_von_mises": float(max(r.max_von_mises for r in records)),  # (the removal's too, as the averaged)
        "yield_stress": float(res.model.fem.material.yield_stress) if res.model.fem.material else None,
        "max_penetration": float(max(r.penetration for r in records)),
        "penetration_tolerance": float(res.model.tol),
        "min_det_F": float(min(r.min_det_F for r in records)),
        "steps": len(res.steps) - 1,
        "newton_iterations": int(res.column("iterations").sum()),
        "elements": int(res.model.fem.n_elements),
        "element_order": int(res.model.options.element_order),
        "nodes": int(res.model.fem.n_vertices),
        "kappa_initial": float(res.model.kappa),
        "kappa_final": float(res.steps[-1].kappa),
        "dhat": float(res.model.dhat),
        "object_samples": int(len(res.model.field.vertices)),
        "seconds": float(res.seconds),
        "time_split": {k: float(v) for k, v in res.timings.items()},
        "phase_split": {k: float(v) for k, v in res.phases.items()},
        "friction": prof.friction,
        "F_hold": prof.F_hold,
        "removal_steps": len(res.removal),
        "dissipated": float(sum(r.dissipated for r in records)),
        "energy_balance": energy_balance(res.steps, res.removal)["total"] if len(res.steps) > 1 else 0.0,
        "jammed_at": res.jammed_at,
        "lag_solves_per_step": float(np.mean([r.lag_solves for r in records[1:]])) if len(records) > 1 else 0.0,
        "newton_iterations_removal": int(sum(r.iterations for r in res.removal)),
        "warnings": list(res.warnings),
        "notes": list(getattr(res, "notes", [])),
        "units": SUMMARY_UNITS,
        "profile_columns": CSV_COLUMN_DOCS,
    }
    return prof, d


def write_profile_csv(res: InsertionResult, path) -> Path:
    """The profile CSV (:data:`CSV_HEADER`), SI units."""
    rows = [[k, r.s, r.energy, r.force, r.path_force, r.grip, r.max_von_mises, r.penetration, r.min_det_F, r.iterations,
             r.contact_points, ph, r.normal_force, r.path_force_friction, r.dissipated, r.lag_solves]
            for k, (r, ph) in enumerate(zip([*res.steps, *res.removal], record_phases(res)))]
    return write_csv(path, CSV_HEADER, rows)


@dataclass(frozen=True, kw_only=True)
class TraversalCurve:
    """The insertion traversal the profile plot draws: its planned steps and the rest search up to the
    steady state (not the search's probes past the rest point, which push O on into its seat). When
    two rest-search records bracket the rest point the curve ends there, at F = 0 interpolated between
    them.

    Args:
        s_mm: insertion distance of each point [mm].
        energy: elastic energy [J].
        force: force on O along its translation [N] (resisting < 0).
        records: the record index of each point (the interpolated rest point has none: it is last).
        marker_index: point index of a record (``index_max``, ``index_ss``; index_ss the rest point
            when its record is past it).
    """

    s_mm: np.ndarray
    energy: np.ndarray
    force: np.ndarray
    records: list
    marker_index: dict


def traversal_curve(res: InsertionResult, prof: ProfileSummary) -> TraversalCurve:
    """The curve :func:`plot_profile` draws (see :class:`TraversalCurve`).

    Args:
        res: the insertion run.
        prof: its profile summary (``index_ss``, ``index_max``).

    Returns:
        The :class:`TraversalCurve`.
    """
    phases = record_phases(res)[:len(res.steps)]
    F_all, s_all, E_all = res.column("force"), res.column("s"), res.column("energy")
    a = rest_bracket(F_all, prof.index_ss, phases.index("rest") if "rest" in phases else None)
    bracket = a is not None and phases[a + 1] == "rest"
    last = a if bracket else prof.index_ss
    keep = [k for k, ph in enumerate(phases) if ph == "insert" or k <= last]
    s, E, F = s_all[keep] * 1e3, E_all[keep], F_all[keep]
    if bracket:  # the rest point between records a and a + 1 (a = index_ss or the record before it)
        w = F_all[a] / (F_all[a] - F_all[a + 1])
        s = np.r_[s, 1e3 * (s_all[a] + w * (s_all[a + 1] - s_all[a]))]
        E, F = np.r_[E, E_all[a] + w * (E_all[a + 1] - E_all[a])], np.r_[F, 0.0]
    at = {k: i for i, k in enumerate(keep)}
    at[prof.index_ss] = at.get(prof.index_ss, len(s) - 1)
    return TraversalCurve(s_mm=s, energy=E, force=F, records=keep, marker_index=at)


def plot_profile(res: InsertionResult, prof: ProfileSummary, path) -> Path:
    """Energy (solid, left axis) and insertion force (dashed, right axis) against insertion
    distance, with markers at E_max and E_ss (the style of the thesis' deformation profiles)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = traversal_curve(res, prof)
    s, E, F, keep, at = c.s_mm, c.energy, c.force, c.records, c.marker_index
    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=120)
    ax.plot(s, E, "-", color="tab:blue", lw=2, label="elastic energy")
    ax.plot(s[at[prof.index_max]], E[at[prof.index_max]], "o", color="tab:red", ms=8, label=r"$E_d^{max}$")
    ax.plot(s[at[prof.index_ss]], E[at[prof.index_ss]], "s", color="tab:green", ms=8, label=r"$E_d^{ss}$")
    ax.set_xlabel("insertion distance [mm]")
    ax.set_ylabel("elastic energy [J]", color="tab:blue")
    ax2 = ax.twinx()
    ax2.plot(s, F, "--", color="tab:orange", lw=1.5, label="insertion force")
    if res.removal:  # friction: the removal is its own traversal
        ax.plot(res.column("s", "remove") * 1e3, res.column("energy", "remove"), "-", color="tab:cyan", lw=1.5,
                label="elastic energy (removal)")
        ax2.plot(res.column("s", "remove") * 1e3, res.column("force", "remove"), "-.", color="tab:brown", lw=1.5,
                 label="force on removal")
    q = np.array([r.quat for r in res.steps])
    if np.abs(np.abs(q @ q[0]) - 1.0).max() > 1e-9:  # rotating path: also the work-conjugate force
        ax2.plot(s[:len(keep)], res.column("path_force")[keep], ":", color="tab:purple", lw=1.5,
                 label="path force (-dE/ds)")
    ax2.axhline(0.0, color="0.7", lw=0.8)
    ax2.set_ylabel("force on O along the path [N] (resisting < 0)", color="tab:orange")
    lines = ax.get_legend_handles_labels()[0] + ax2.get_legend_handles_labels()[0]
    labels = ax.get_legend_handles_labels()[1] + ax2.get_legend_handles_labels()[1]
    ax.legend(lines, labels, loc="upper left", fontsize=8)
    p2 = ", P2 elements" if res.model.options.element_order == 2 else ""
    mu = f", friction {prof.friction:g}" if prof.friction > 0 else ""
    category = "no contact" if prof.category == "none" else prof.category
    ax.set_title(f"{res.model.name}: {category} (coupling ratio {prof.coupling_ratio:.1f}%{p2}{mu})")
    fig.tight_layout()
    try:
        return save_figure(fig, path)
    finally:
        plt.close(fig)


def vertex_von_mises(fem, vm: np.ndarray) -> np.ndarray:
    """Per-node von Mises stress: mean over incident elements (n,) [Pa] (P2: the elements' largest
    value over their quadrature points, at all their nodes)."""
    n = fem.n_vertices
    el = np.asarray(fem.elements)
    k = el.shape[1]
    s = np.bincount(el.ravel(), weights=np.repeat(vm, k), minlength=n)
    c = np.bincount(el.ravel(), minlength=n)
    return s / np.maximum(c, 1)


#: The stress colour scale's top: this percentile of the nodes' von Mises stress, the largest over the
#: records. A single element's peak (a contact edge's, clip3d's 355 MPa) would otherwise set the scale and
#: leave the rest of the part in its lowest colour at most time codes; nodes above it take the top colour
#: (the stage marks the scale clipped: ``simfab:clipped``).
STRESS_COLOUR_PERCENTILE = 99.0


def stress_colour_top(values: list) -> float:
    """The top of a timeline's stress colour scale [Pa]: the largest over its records of
    STRESS_COLOUR_PERCENTILE of the nodes' values (the largest value where that is 0; 1 where all are 0).

    Args:
        values: each record's per-node von Mises stress (n,) [Pa] (:func:`vertex_von_mises`).

    Returns:
        The scale's top [Pa], > 0.
    """
    top = max((float(np.percentile(v, STRESS_COLOUR_PERCENTILE)) for v in values if len(v)), default=0.0)
    if top > 0:
        return top
    return max((float(np.max(v)) for v in values if len(v)), default=0.0) or 1.0


def display_faces(cm) -> np.ndarray:
    """Triangles over A's nodes to display it: 2D its (sub-)elements, 3D its boundary (sub-)facets."""
    return cm.display_elements if cm.dim == 2 else cm.contact_facets


def object_display(cm):
    """O's display mesh in its body frame: (vertices (k, 3), faces (f, 3))."""
    if cm.object_faces is not None:
        return cm.object_vertices, cm.object_faces
    import triangle

    seg = _loop_edges(len(cm.object_vertices))
    t = triangle.triangulate({"vertices": cm.object_vertices, "segments": seg}, "p")  # no Steiner points
    V, F = np.asarray(t["vertices"]), np.asarray(t["triangles"])
    return np.c_[V, np.zeros(len(V))], F


def write_usd(res: InsertionResult, path) -> Path:
    """USD stage: A's deforming mesh (``part``) with a per-vertex ``von_mises`` primvar [Pa] coloured on one
    scale for the whole timeline (0 to :func:`stress_colour_top`), O's animated transform (``object``);
    time code k = record k (the insertion's, then the removal's)."""

    cm = res.model
    fem = cm.fem
    w = StageWriter(path, time_codes_per_second=12.0)
    faces = display_faces(cm)
    w.add_mesh("part", faces, res.steps[0].x)
    ov, of = object_display(cm)
    w.add_rigid("object", points=ov, faces=of, color=[0.55, 0.6, 0.7])
    records = [*res.steps, *res.removal]
    stress = [vertex_von_mises(fem, r.von_mises) for r in records]
    vmax = stress_colour_top(stress)
    for k, (r, vm) in enumerate(zip(records, stress)):
        w.set_points("part", r.x, k)
        w.set_scalar("part", "von_mises", vm, k, interpolation="vertex", vmin=0.0, vmax=vmax, units="Pa")
        w.set_pose("object", r.pos, r.quat, k)
    return w.save()


def extruded_slab(V2: np.ndarray, F: np.ndarray, edges: np.ndarray, thickness: float):
    """Extrude a 2D triangle mesh along z to a closed slab: (vertices (2n, 3), faces)."""
    n = len(V2)
    h = 0.5 * thickness
    V = np.vstack([np.c_[V2, np.full(n, -h)], np.c_[V2, np.full(n, h)]])
    top = F + n
    bottom = F[:, ::-1]
    a, b = edges[:, 0], edges[:, 1]
    sides = np.vstack([np.c_[a, b, b + n], np.c_[a, b + n, a + n]])
    return V, np.vstack([bottom, top, sides])


#: The viewer's insertion slider: O (display only, no contacts) follows its control as a
#: critically damped oscillator of this natural frequency [Hz]; mass and inertia are nominal.
PLAYER_HZ, PLAYER_MASS, PLAYER_INERTIA = 20.0, 0.01, 1e-6


def straight_path(res: InsertionResult):
    """(start (3,), unit direction (3,), s (k,)) when O only translates along one line, else None."""
    P = np.array([np.r_[np.asarray(r.pos, float), np.zeros(3 - len(r.pos))][:3] for r in res.steps])
    Q = np.array([np.asarray(r.quat, float) for r in res.steps])
    d = P[-1] - P[0]
    L = float(np.linalg.norm(d))
    if L <= 0 or np.any(np.abs(np.abs(Q @ Q[0]) - 1.0) > 1e-12):
        return None
    u = d / L
    off = (P - P[0]) - np.outer((P - P[0]) @ u, u)
    if np.linalg.norm(off, axis=1).max() > 1e-9 * L:
        return None
    return P[0], u, (P - P[0]) @ u


def write_mjcf(res: InsertionResult, prof: ProfileSummary, path) -> Path:
    """MJCF for the MuJoCo viewer: A deformed at the steady state (body ``part``), O at that step,
    and one keyframe per insertion step to scrub the path (the viewer's Key slider).

    When O's path is a straight translation (the usual insertion), O hangs on a slide joint along
    it driven by a position actuator ``insertion`` [m along the path]: press play and drag the
    control slider to move O along the path (gravity off, O has no contacts; keyframes set qpos and
    ctrl). Otherwise O is a mocap body and the keyframes hold its poses."""

    cm = res.model
    fem = cm.fem
    r_ss = res.steps[prof.index_ss]
    if fem.dim == 2:
        V, F = extruded_slab(r_ss.x, cm.display_elements, cm.contact_facets, fem.thickness)
    else:
        V, F = r_ss.x, cm.contact_facets
        used = np.unique(F)
        remap = np.full(len(V), -1)
        remap[used] = np.arange(len(used))
        V, F = V[used], remap[F]
    ov, of = object_display(cm)
    if cm.dim == 2:
        ov, of = extruded_slab(ov[:, :2], of, _loop_edges(len(cm.object_vertices)), fem.thickness * 1.5)
    line = straight_path(res)
    b = MJCFBuilder(f"{cm.name}_insertion", gravity=[0, 0, 0] if line is not None else None)
    b.mesh_asset("part", V, F)
    b.mesh_asset("object", ov, of)
    part = b.body("part")
    b.geom(part, type="mesh", mesh="part", rgba=[0.85, 0.55, 0.25, 1], contype=0, conaffinity=0)
    if line is None:
        o = b.body("object", pos=r_ss.pos, quat=r_ss.quat, mocap=True)
        b.geom(o, type="mesh", mesh="object", rgba=[0.5, 0.6, 0.7, 0.8], contype=0, conaffinity=0)
        for k in key_steps(len(res.steps), prof.index_ss):
            b.key(f"step{k}", mpos=res.steps[k].pos, mquat=res.steps[k].quat)
        return b.save(path)
    p0, u, s = line
    q0 = np.asarray(res.steps[0].quat, float)
    o = b.body("object", pos=p0, quat=q0)
    b.add(o, "inertial", pos=[0, 0, 0], mass=PLAYER_MASS, diaginertia=[PLAYER_INERTIA] * 3)
    w = 2 * np.pi * PLAYER_HZ
    lo, hi = float(s.min()), float(s.max())
    b.add(o, "joint", name="insertion", type="slide", axis=quat_to_matrix(q0).T @ u, range=[lo, hi],
          damping=2 * PLAYER_MASS * w)
    b.geom(o, type="mesh", mesh="object", rgba=[0.5, 0.6, 0.7, 0.8], contype=0, conaffinity=0, mass=0)
    b.add(b.section("actuator"), "position", name="insertion", joint="insertion", kp=PLAYER_MASS * w * w,
          ctrlrange=[lo, hi])
    b.root.find("option").set("integrator", "implicitfast")
    for k in key_steps(len(s), prof.index_ss):
        b.key(f"step{k}", qpos=[s[k]], ctrl=[s[k]])
    return b.save(path)


def key_steps(n: int, keep: int) -> np.ndarray:
    """Indices of the records that get a viewer keyframe: every one of ``n`` when there are at most
    :data:`simfab.io.mjcf.MAX_KEYFRAMES` (the most an MJCF simfab reads may hold), else that many
    evenly spread, the first, the last and ``keep`` (the steady state) among them.

    Args:
        n: number of records.
        keep: a record that must have its key.

    Returns:
        Sorted record indices, at most ``MAX_KEYFRAMES``.
    """
    if n <= MAX_KEYFRAMES:
        return np.arange(n)
    # n > MAX_KEYFRAMES: the spread indices are more than one apart, so rounding merges none
    return np.unique(np.r_[np.linspace(0, n - 1, MAX_KEYFRAMES - 1).round().astype(int), keep])


def _loop_edges(k: int) -> np.ndarray:
    """Edges (k, 2) of a closed curve through vertices 0..k-1 in order (CCW: the first k vertices
    of O's 2D display triangulation)."""
    i = np.arange(k)
    return np.c_[i, (i + 1) % k]


def write_all(result, out: Path, stem: str | None = None):
    """Write every output of an insertion run into ``out`` together: a failure while writing any of
    them leaves none.

    Args:
        result: a :class:`simfab.coupling.insertion.CouplingResult` (its ``insertion`` and ``profile``).
        out: the output folder.
        stem: the files' stem (default: the scene's name).

    Returns:
        ``result`` with ``outputs`` (profile_csv, plot_png, usd, mjcf, profile_json); the JSON file
        holds its ``to_json()``.
    """
    import dataclasses

    out = Path(out)
    res = result.insertion
    stem = safe_name(stem or res.model.name)  # the scene's name comes from a file: no separators, no '..'
    prof = analyze_run(res)
    paths = {"profile_csv": out / f"{stem}_profile.csv", "plot_png": out / f"{stem}_profile.png",
             "usd": out / f"{stem}.usda", "mjcf": out / f"{stem}.xml", "profile_json": out / f"{stem}_summary.json"}
    result = dataclasses.replace(result, outputs={k: str(v) for k, v in paths.items()})
    with atomic_paths(paths) as tmp:
        write_profile_csv(res, tmp["profile_csv"])
        plot_profile(res, prof, tmp["plot_png"])
        write_usd(res, tmp["usd"])
        write_mjcf(res, prof, tmp["mjcf"])
        write_json(tmp["profile_json"], result.to_json())
    return result
