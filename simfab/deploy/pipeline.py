"""Target surface -> flat pattern -> deployment -> comparison (``simfab deploy surface``).

Stages (each timed): flatten (:mod:`~simfab.deploy.flatten`), layout
(:mod:`~simfab.deploy.pattern`), lasercut (:mod:`~simfab.deploy.lasercut`), deploy
(:mod:`~simfab.deploy.network`), tune (optional, scene ``[tune]``: the gaps adjusted by
Gauss-Newton on the deployed shape, the pattern re-cut and its equilibrium solved after every step:
:mod:`~simfab.deploy.tuning`), compare (:mod:`~simfab.deploy.compare`) and mujoco
(:mod:`~simfab.deploy.mjcf_sim`: build the simulatable scene, step it (damped) from the deployed
key until it is at rest - its convergence test, ``settle_tol`` - or for at most
``stability_seconds``, and compare the relaxed state with simfab's equilibrium after a rigid
alignment).

Deployed shape descriptors: the total angle defect of the deployed quad mesh's interior
vertices (the inserts) [rad] (its integrated Gaussian curvature when the quads are planar; the
deployed quads are skew, and a 1 mm local bump at an insert 30 mm from its neighbours changes
its angle defect by ~4 (1 mm / 30 mm)^2 = 0.004 rad, as much as a whole saddle cell's curvature,
so the per-insert sign is not read from it); per insert, the Gaussian curvature of the
least-squares quadric through the insert and its one-ring of the quad mesh (its 4 quads' 9
vertices) in their best-fit plane - ``curvature_sign_at_inserts`` counts their signs, ``kind``
is dome / saddle when 90 % of them are positive / negative, else mixed, and
``curvature_sign_agreement`` is the fraction of inserts whose sign is the target's (the same fit
on the target points); and the quadric z = a x^2 + b x y + c y^2 + (linear, constant) fitted to
all deployed vertices in their best-fit plane, K_fit = 4 a c - b^2 [1/m^2] (the global shape).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from simfab.deploy import auto, compare, cuts, flatten, lasercut, mjcf_sim, network, pattern, tuning
from simfab.deploy.compare import height_error, out_of_plane_extent
from simfab.deploy.network import discrete_gaussian_curvature
from simfab.progress import log


@dataclass
class SurfaceRun:
    """Everything a run produced (:func:`run`; for the writers and the summary).

    Args:
        scene: the :class:`simfab.deploy.scene.SurfaceScene`.
        flat: the :class:`simfab.deploy.flatten.Flattening` (of the cut mesh, with cuts).
        pattern: the :class:`simfab.deploy.pattern.Pattern`.
        cut: the :class:`simfab.deploy.lasercut.CutLayout`.
        network: the :class:`simfab.deploy.network.Network`.
        deployment: the :class:`simfab.deploy.network.Deployment` (the tuned one, with tuning).
        target_points: (n,3) [m] the pattern vertices' target points.
        deviation: the :class:`simfab.deploy.compare.Deviation`.
        sim: the :class:`simfab.deploy.mjcf_sim.SimScene` (None without the MuJoCo check).
        sim_check: the MuJoCo check's figures (:func:`mujoco_check_run`; empty without it).
        shape: :func:`shape_descriptors` of the deployed vertices.
        seconds: wall time per stage [s].
        tuning: the gap tuning's figures (None without tuning).
        cuts: the :class:`simfab.deploy.cuts.CutFlattening` when the scene has ``[cuts] max_cones > 0``.
        ties: the :class:`simfab.deploy.cuts.SeamTies` when the seams are joined.
    """

    scene: object
    flat: object
    pattern: object
    cut: object
    network: object
    deployment: object
    target_points: np.ndarray
    deviation: object
    sim: object
    sim_check: dict
    shape: dict
    seconds: dict
    tuning: dict | None = None
    cuts: object = None  # simfab.deploy.cuts.CutFlattening when the scene has [cuts] max_cones > 0
    ties: object = None  # simfab.deploy.cuts.SeamTies when the seams are joined


def quadric_curvature(X: np.ndarray) -> float:
    """K_fit = 4 a c - b^2 of the least-squares quadric z = a x^2 + b x y + c y^2 + ... over the points'
    best-fit plane.

    Args:
        X: (n,3) [m] points.

    Returns:
        K_fit [1/m^2].
    """
    c = X.mean(axis=0)
    _, _, Wt = np.linalg.svd(X - c)
    e1, e2, n = Wt
    p = X - c
    x, y, z = p @ e1, p @ e2, p @ n
    M = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], axis=1)
    a, b, cc, *_ = np.linalg.lstsq(M, z, rcond=None)[0]
    return float(4 * a * cc - b * b)


def _kind(K: np.ndarray) -> str:
    """"dome" / "saddle" when at least 90 % of the inserts' local curvatures K are positive /
    negative, else "mixed"."""
    if len(K) == 0:
        return "flat"
    pos = float(np.mean(K > 0))
    return "dome" if pos >= 0.9 else "saddle" if pos <= 0.1 else "mixed"


def local_curvature(pat, X: np.ndarray) -> np.ndarray:
    """Per insert, K_fit of the quadric through the insert and its one-ring of the quad mesh.

    Args:
        pat: the :class:`simfab.deploy.pattern.Pattern`.
        X: (n,3) [m] vertex positions.

    Returns:
        (n,) [1/m^2] (NaN at boundary vertices).
    """
    out = np.full(len(X), np.nan)
    for v in np.flatnonzero(pat.interior):
        ring = np.unique(pat.quads[np.any(pat.quads == v, axis=1)])
        out[v] = quadric_curvature(X[ring])
    return out


def shape_descriptors(pat, X: np.ndarray, Y: np.ndarray | None = None) -> dict:
    """Shape of the deployed vertices (see the module doc).

    Args:
        pat: the :class:`simfab.deploy.pattern.Pattern`.
        X: (n,3) [m] deployed vertices.
        Y: (n,3) [m] the target points (for the sign agreement; None: left out).

    Returns:
        {quadric_gaussian_curvature [1/m^2], total_angle_defect [rad], curvature_sign_at_inserts
        {positive, negative}, kind ("dome", "saddle" or "mixed"), curvature_sign_agreement [-] (with Y)}.
    """

    K = discrete_gaussian_curvature(X, pat.quads, pat.interior)
    Kl = local_curvature(pat, X)[pat.interior]
    out = dict(quadric_gaussian_curvature=quadric_curvature(X), total_angle_defect=float(np.nansum(K)),
               curvature_sign_at_inserts=dict(positive=int(np.sum(Kl > 0)), negative=int(np.sum(Kl < 0))),
               kind=_kind(Kl))
    if Y is not None and len(Kl):
        out["curvature_sign_agreement"] = float(np.mean(np.sign(Kl) == np.sign(local_curvature(pat, Y)[pat.interior])))
    return out


def run(scene, *, device: str = "cpu", quiet: bool = True, mujoco_check: bool = True) -> SurfaceRun:
    """Run every stage on a loaded scene: flattening (with cuts), pattern, laser-cut layout, network,
    deployment, tuning, deviation, MuJoCo check.

    Args:
        scene: the :class:`simfab.deploy.scene.SurfaceScene`.
        device: Warp device.
        quiet: no progress output.
        mujoco_check: build and step the MuJoCo scene.

    Returns:
        The :class:`SurfaceRun`.
    """

    sec = {}
    t = time.perf_counter()
    tgt = scene.target
    pattern.check_cell_count(float(np.sum(flatten.face_areas(tgt.V, tgt.F))), scene.pattern.spacing)
    log(f"deploy surface: flatten {len(tgt.V)} vertices (BFF)", quiet=quiet)
    cut_flat = None
    if getattr(scene, "cuts", None) is not None and scene.cuts.max_cones > 0:  # cones + cuts (the cut mesh)
        cut_flat = cuts.flatten_with_cuts(tgt.V, tgt.F, scene.cuts, scene.pattern)
        flat, mV, mF = cut_flat.flat, cut_flat.V, cut_flat.F
        log(f"deploy surface: {len(cut_flat.cones)} cone(s), cut paths to the boundary", quiet=quiet)
    else:
        flat, mV, mF = flatten.flatten(tgt.V, tgt.F), tgt.V, tgt.F
    sec["flatten"] = time.perf_counter() - t
    t = time.perf_counter()
    seams = [] if cut_flat is None else cuts.seam_lines(cut_flat)
    tips = np.zeros((0, 2)) if cut_flat is None else cuts.cone_points(cut_flat)
    import shapely

    def lay(pc):
        return pattern.layout(flat.uv, flat.boundary, mF, flat.u, pc, seams=[p for _, p in seams], cone_tips=tips)

    pat = lay(scene.pattern)
    decided = () if scene.decisions is None else scene.decisions.decided
    if "pattern.layout" in decided and scene.pattern.layout == "conforming" and pattern.covered_fraction(
            pat, shapely.Polygon(flat.uv[flat.boundary])) < auto.MIN_COVERED:
        # a decided conforming layout leaving too much of the domain uncovered (a narrow outline its grid
        # core cannot follow): the mesh layout, which follows the outline
        scene = dataclasses.replace(scene, pattern=dataclasses.replace(scene.pattern, layout="mesh"))
        log("deploy surface: the conforming layout leaves the outline uncovered, the mesh layout instead", quiet=quiet)
        pat = lay(scene.pattern)
    extra = None if scene.decisions is None else auto.unreachable_size(pat, scene.decisions)
    if extra is not None:  # a decided catalogue the layout left inserts out of reach with: one more size
        scene = dataclasses.replace(scene, pattern=dataclasses.replace(
            scene.pattern, insert_half_sizes=tuple(sorted((*pat.config.sizes, extra)))))
        log(f"deploy surface: {len(pat.unreachable)} gaps out of reach, the catalogue takes {1e3 * extra:g} mm too",
            quiet=quiet)
        pat = lay(scene.pattern)
    Y = pattern.map_to_surface(flat.uv, mF, mV, pat.P)
    sec["layout"] = time.perf_counter() - t
    t = time.perf_counter()
    cut = lasercut.cut_layout(pat, seams=seams)
    sec["lasercut"] = time.perf_counter() - t
    t = time.perf_counter()
    log(f"deploy surface: {pat.n_inserts} inserts, {len(pat.edges)} beams, {int(pat.spring.sum())} springs",
        quiet=quiet)
    ties = cuts.seam_ties(pat, Y, cut_flat) if cut_flat is not None and scene.cuts.join_seams else None
    net = network.build_network(pat, scene.deploy, ties=ties)
    to_target = lambda p: pattern.map_to_surface(flat.uv, mF, mV, p)  # noqa: E731
    dep = network.deploy(pat, net, scene.deploy, network.target_heights(pat, Y), device=device, quiet=quiet,
                         predictor=network.target_displacement(net, to_target))
    sec["deploy"] = time.perf_counter() - t
    tune_info = None
    if scene.tune is not None and scene.tune.iterations > 0:
        t = time.perf_counter()
        before = compare.deviation(dep.vertex_positions(), Y, pat.quads, tgt)
        log(f"deploy surface: tuning the gaps (RMS {100 * before.rms:.3g} % before)", quiet=quiet)
        gap0 = pat.gap
        tuned = tuning.tune_pattern(pat, net, dep, Y, tgt, scene.tune, scene.deploy, ties=ties, device=device)
        pat, net, dep = tuned.pattern, tuned.network, tuned.deployment
        cut = lasercut.cut_layout(pat, seams=seams)
        tune_info = dict(steps=tuned.steps, solves=tuned.solves, abandoned_trials=tuned.abandoned,
                         rejected_early_trials=tuned.rejected_early, newton_iterations=tuned.newton_iterations,
                         stop=tuned.stop,
                         rms_before=before.rms,
                         hausdorff_before=before.hausdorff, point_weight=scene.tune.point_weight,
                         point_to_plane_rms_mm=[1e3 * r for r in tuned.rms_history],
                         point_to_target_rms_mm=[1e3 * r for r in tuned.point_rms_history],
                         gap_change_max_mm=float(np.max(np.abs(pat.gap - gap0)) * 1e3))
        sec["tune"] = time.perf_counter() - t
    t = time.perf_counter()
    X = dep.vertex_positions()
    untuned = tune_info is not None and tune_info["steps"] == 0  # the deployment measured before the tuning
    dev = before if untuned else compare.deviation(X, Y, pat.quads, tgt)
    shape = shape_descriptors(pat, X, Y)
    sec["compare"] = time.perf_counter() - t
    sim, check = None, {}
    if mujoco_check:
        t = time.perf_counter()
        log("deploy surface: MuJoCo scene (stability + relaxation check)", quiet=quiet)
        sim, check = mujoco_check_run(net, dep, pat, scene)
        sec["mujoco"] = time.perf_counter() - t
    return SurfaceRun(scene=scene, flat=flat, pattern=pat, cut=cut, network=net, deployment=dep, target_points=Y,
                         deviation=dev, sim=sim, sim_check=check, shape=shape, seconds=sec, tuning=tune_info,
                         cuts=cut_flat, ties=ties)


def insert_geoms(pat, net) -> dict:
    """MuJoCo/USD geometry of the inserts: square plates of half-side r_i + beam_width, 2 t thick.

    Args:
        pat: the :class:`simfab.deploy.pattern.Pattern`.
        net: its :class:`simfab.deploy.network.Network`.

    Returns:
        simfab body name -> dict(box=half sizes [m], rgba).
    """
    pc = pat.config
    out = {}
    for v in np.flatnonzero(pat.interior):
        s = float(pat.insert_size[v]) + pc.beam_width
        out[net.model.body_names[net.vertex_body[v]]] = dict(box=[s, s, pc.beam_thickness], rgba=[0.85, 0.45, 0.2, 1])
    return out


def mujoco_check_run(net, dep, pat, scene):
    """Build the MuJoCo scene, step it from the key (stability) and relax it (agreement with simfab).

    Args:
        net: the :class:`simfab.deploy.network.Network`.
        dep: its :class:`simfab.deploy.network.Deployment`.
        pat: the :class:`simfab.deploy.pattern.Pattern`.
        scene: the :class:`simfab.deploy.scene.SurfaceScene` (its ``[mujoco]`` and material).

    Returns:
        (the :class:`simfab.deploy.mjcf_sim.SimScene`, the check's figures: model sizes, timestep,
        stability, relaxation).
    """
    import mujoco


    cfg = scene.mujoco
    sim = mjcf_sim.build(net.model, net.state, dep.final, density=scene.deploy.density, cfg=cfg,
                         name="deployed_surface", body_geoms=insert_geoms(pat, net))
    m = sim.model
    Y = dep.final.body_pos
    height = out_of_plane_extent(Y)
    # damped: also the relaxation; stops once at rest (within settle_tol of the height)
    ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n) for n in net.model.body_names]
    stab, d = mjcf_sim.step_from_key(m, cfg.stability_seconds, key=None, settle=cfg.settle_tol * height, bodies=ids)
    X = np.array([d.body(n).xpos for n in net.model.body_names])
    R, t = compare.kabsch(X, Y)
    diff = np.linalg.norm(X @ R.T + t - Y, axis=1)
    check = dict(nq=int(m.nq), nv=int(m.nv), welds=int(m.neq), timestep=stab.timestep,
                 stability=dict(seconds=stab.seconds, max_seconds=cfg.stability_seconds, settled=stab.settled,
                                steps=stab.steps, finite=stab.finite, max_speed=stab.max_speed,
                                final_kinetic_energy=stab.final_kinetic, max_drift_m=stab.max_drift, wall_s=stab.wall),
                 relaxation=dict(seconds=stab.seconds, finite=stab.finite,
                                 rms_m=float(np.sqrt(np.mean(diff**2))), max_m=float(np.max(diff)),
                                 out_of_plane_extent_m=height,
                                 rms_rel=float(np.sqrt(np.mean(diff**2))) / height if height > 0 else None,
                                 max_rel=float(np.max(diff)) / height if height > 0 else None))
    return sim, check


def summary(res: SurfaceRun) -> dict:
    """The JSON summary of a run (units in the keys; ``simfab deploy surface --json``).

    Args:
        res: the :class:`SurfaceRun`.

    Returns:
        The summary dict.
    """

    f, p, dv = res.flat, res.pattern, res.deviation
    ins = p.interior
    return dict(
        scene=res.scene.path, target=res.scene.target.name, vertices=int(len(res.scene.target.V)),
        faces=int(len(res.scene.target.F)),
        u_min=float(f.u.min()), u_max=float(f.u.max()),
        area_distortion_log_min=float(f.sigma.min()), area_distortion_log_max=float(f.sigma.max()),
        area_ratio_min=float(np.exp(2 * f.sigma.min())), area_ratio_max=float(np.exp(2 * f.sigma.max())),
        closure_angle_correction_rad=f.closure_angle_correction,
        quads=int(len(p.quads)), beams=int(len(p.edges)), springs=int(p.spring.sum()), inserts=p.n_inserts,
        layout=p.config.layout, flat_area_covered=flat_area_covered(res),
        insert_half_sizes_mm=[r * 1e3 for r in p.config.sizes],
        bill_of_materials=p.bill_of_materials(),
        gap_min_mm=float(p.gap[ins].min() * 1e3) if ins.any() else None,
        gap_max_mm=float(p.gap[ins].max() * 1e3) if ins.any() else None,
        unreachable_gaps=[dict(insert=int(p.insert_ids[v]), size_class=p.class_label(v),
                               required_mm=float(p.gap_required[v] * 1e3), cut_mm=float(p.gap[v] * 1e3),
                               growth_shortfall_mm=float(abs(p.gap_required[v] - p.gap[v]) * 1e3),
                               deviation_mm=float(dv.per_vertex[v] * 1e3))
                          for v in p.unreachable],
        spring_bulge_min=float(p.bulge[p.spring].min()) if p.spring.any() else None,
        spring_bulge_max=float(p.bulge[p.spring].max()) if p.spring.any() else None,
        quad_growth_max=float(p.growth.max()),
        springs_short_of_slack=[dict(quad=int(q), growth=float(p.growth[q][k]),
                                     arc_over_chord=float(p.spring_ratio[q][k]),
                                     deviation_mm=float(np.max(dv.per_vertex[p.quads[q]]) * 1e3))
                                for q in p.tight_springs
                                for k in [int(np.argmin(p.spring_ratio[q] / np.maximum(p.growth[q], 1.0)))]],
        lasercut=lasercut.cut_summary(res.cut),
        deployment=dict(stable=res.deployment.stable, increments=len(res.deployment.iterations),
                        newton_iterations=res.deployment.iterations, energy_J=res.deployment.energy, **res.shape),
        deviation=dict(rms=dv.rms, hausdorff=dv.hausdorff, rms_mm=dv.rms_m * 1e3, hausdorff_mm=dv.hausdorff_m * 1e3,
                       diameter_mm=dv.diameter * 1e3,
                       deployed_height_mm=out_of_plane_extent(dv.aligned) * 1e3,
                       target_height_mm=out_of_plane_extent(res.target_points) * 1e3),
        tuning=res.tuning,
        defaults=defaults_summary(res.scene),
        bounds=bounds(res),
        cuts=cuts_summary(res),
        mujoco=res.sim_check,
        seconds=dict(res.seconds, total=float(sum(res.seconds.values()))),
    )


def defaults_summary(scene) -> dict | None:
    """What the defaults decided from the target (:mod:`simfab.deploy.auto`).

    Args:
        scene: the :class:`simfab.deploy.scene.SurfaceScene`.

    Returns:
        The decisions as a dict; None when the defaults were off.
    """
    d = getattr(scene, "decisions", None)
    if d is None:
        return None
    pc = scene.pattern
    return dict(decided=list(d.decided), needs_cuts=d.needs_cuts, uncut_unreachable_vertices=d.uncut_unreachable,
                uncut_growth_max=d.uncut_growth_max, spacing_mm=pc.spacing * 1e3,
                insert_half_sizes_mm=[r * 1e3 for r in pc.sizes], layout=pc.layout, max_cones=scene.cuts.max_cones)


#: the deployment bounds a run is checked against (issue 42): RMS deviation over the diameter, height error
BOUND_RMS = 0.01
BOUND_HEIGHT = 0.03


def bounds(res: SurfaceRun) -> dict:
    """The run against the deployment bounds: RMS <= ``BOUND_RMS`` of the diameter, out-of-plane height
    within ``BOUND_HEIGHT``, no gap unreachable, no spring short of its reach (:func:`taut_springs`).

    Args:
        res: the :class:`SurfaceRun`.

    Returns:
        The figures, whether each bound is met, and ``missed``: one line per missed bound with the
        scene key or flag that would help.
    """
    dv, p = res.deviation, res.pattern
    herr = height_error(dv.aligned, res.target_points)
    sc = res.scene
    cut = sc.cuts is not None and sc.cuts.max_cones > 0
    tuned = sc.tune is not None and sc.tune.iterations > 0
    missed = []
    if dv.rms > BOUND_RMS:
        missed.append(f"RMS deviation {100 * dv.rms:.3g} % of the diameter (bound {100 * BOUND_RMS:g} %): "
                      + ("more tuning steps (--tune N, [tune] iterations, seconds)" if tuned else "tune the gaps "
                         "(--tune N)") + "; a finer pattern ([pattern] spacing, --spacing)")
    if abs(herr) > BOUND_HEIGHT:
        missed.append(f"height {100 * herr:+.3g} % (bound {100 * BOUND_HEIGHT:g} %): [tune] height_weight (the "
                      "height row's pull), point_weight (the pull towards each vertex's own target point)")
    if len(p.unreachable):
        missed.append(f"{len(p.unreachable)} gaps unreachable: [pattern] insert_half_sizes (a catalogue spanning "
                      "their growth)" + ("" if cut else ", or cuts: [cuts] max_cones"))
    taut = taut_springs(p)
    if len(taut):
        shrinks = float(np.min(res.flat.u)) < 0  # cones help where the flattening shrank (u < 0) only
        missed.append(f"{len(taut)} quads' springs short of their reach: a narrower [pattern] spring_width "
                      "(bends further) or a finer spacing" + (", or cuts: [cuts] max_cones, max_growth"
                                                              if shrinks and not cut else ""))
    return dict(rms=dv.rms, rms_bound=BOUND_RMS, height_error=herr, height_bound=BOUND_HEIGHT,
                unreachable_gaps=int(len(p.unreachable)), springs_short=int(len(taut)),
                springs_below_slack=int(len(p.tight_springs) - len(taut)), missed=missed)


def taut_springs(p) -> np.ndarray:
    """The quads of ``p`` with a spring arc shorter than its deployed chord, S/c < max(growth, 1): pulled
    taut, the spring holds its inserts short of their positions (a bound). A quad in
    ``p.tight_springs`` whose arcs all reach but keep less than the ``spring_slack`` margin over the
    chord deploys as designed (the deployment's equilibrium includes its springs); it is reported
    (``springs_below_slack``), not a missed bound.

    Args:
        p: the :class:`~simfab.deploy.pattern.Pattern`.

    Returns:
        (k,) the quads, a subset of ``p.tight_springs``.
    """
    q = np.asarray(p.tight_springs, dtype=np.int64)
    reach = np.maximum(p.growth[q], 1.0)
    return q[np.any(p.spring_ratio[q] < reach - 1e-9, axis=1)]


def flat_area_covered(res: SurfaceRun) -> float:
    """The fraction of the flat domain (cut, with cuts) that the pattern's quads cover.

    Args:
        res: the :class:`SurfaceRun`.

    Returns:
        The fraction [-].
    """
    import shapely

    f = res.flat
    return pattern.covered_fraction(res.pattern, shapely.Polygon(f.uv[f.boundary]))


def cuts_summary(res: SurfaceRun) -> dict | None:
    """Cones and seams of a run with cuts: per cone its angle defect [deg] and seam length [mm] (the cut
    path in 3D), the interior mesh vertices whose growth no insert size reaches without and with the
    cones, the inserts on cone tips (insert number, size class, growth [mm]:
    :func:`simfab.deploy.pattern.cone_tip_growth`), the seam ties, and the flat area the pattern's
    quads cover (of the cut domain: the cells clipped at the wedges leave notches the deviation does
    not see).

    Args:
        res: the :class:`SurfaceRun`.

    Returns:
        The dict; None without cuts.
    """
    cf = res.cuts
    if cf is None:
        return None
    V = res.scene.target.V
    p = res.pattern
    tips = [] if p.cone_tip is None else [
        dict(insert=int(p.insert_ids[v]), size_class=p.class_label(v),
             growth_mm=float((p.insert_size[v] - p.gap[v]) * 1e3)) for v in np.flatnonzero(p.cone_tip & p.interior)]
    return dict(cones=len(cf.cones), unreachable_mesh_vertices=cf.unreachable_vertices, cone_tip_inserts=tips,
                flat_area_covered=flat_area_covered(res),
                seams_joined=res.ties is not None, seam_ties=0 if res.ties is None else int(len(res.ties.pairs)),
                seams=[dict(cone_defect_deg=float(np.degrees(d)),
                            length_mm=float(np.sum(np.linalg.norm(np.diff(V[s.path], axis=0), axis=1)) * 1e3))
                       for d, s in zip(cf.cone_defect, cf.seams)])
