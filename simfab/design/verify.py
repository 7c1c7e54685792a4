"""Mesh-convergence check of an optimized design: is the brief met by the shape, or only by its
mesh?

The optimizer simulates every candidate on the scene's own (coarse) mesh: linear simplices are
too stiff in bending, and at the design scenes' ~450 triangles the coupling figures are tens of
percent off their mesh-converged values (``simfab couple converge``). The optimized shape exists
only as a mesh, so it is refined uniformly (:func:`simfab.fem.subdivide.subdivide`: every edge
split, the same piecewise-linear domain, h -> h/2) and the same insertion (object, path, steps,
support, options) is run on each level: 2D at 1x, 4x and 16x the elements, 3D at 1x and 8x.

Reported per figure: the value at every level, the extrapolated value (three levels whose
changes shrink: f = f_inf + b h^p fitted, :func:`simfab.coupling.converge.extrapolate`; else
none, and a figure whose changes grow - the max von Mises stress at a sharp re-entrant corner is
singular - is flagged as not converging), and the relative difference of the optimization mesh
from the extrapolated value (else the finest level); per constraint: its value there (the
mesh-converged answer as far as the levels tell) and whether it is satisfied. A design that meets
its brief only on the coarse mesh gets a warning in the summary, and
:func:`correction_factors` turn the check into the next round's correction of the coarse figures
(:func:`simfab.design.pipeline.optimize_scene`).
"""

from __future__ import annotations

import time

import numpy as np

from simfab.design import brief as B

#: Refinement levels (number of uniform subdivisions) of the check, per dimension.
LEVELS = {2: (0, 1, 2), 3: (0, 1)}
#: Correction factors are clipped to this range (a coarse linear mesh is too stiff by tens of percent,
#: not by orders of magnitude; a larger ratio means the figure changed character, e.g. a contact
#: that exists on one mesh only).
FACTOR_RANGE = (0.25, 4.0)
#: Target matching: the corrected coarse force profile may differ from the finest level's by this
#: fraction (least-squares scale) before another correction round runs.
PROFILE_TOL = 0.05
FIGURES = ("coupling_ratio", "grip_force", "insertion_force", "removal_force", "von_mises", "von_mises_peak")


def refined_model(cm, rest: np.ndarray, times: int):
    """The coupling model of rest shape ``rest`` (n, d) [m] on cm's mesh subdivided ``times`` times:
    the fixed support is every vertex whose parents were all fixed."""
    from simfab.coupling.model import make_coupling_model
    from simfab.fem.model import make_model
    from simfab.fem.subdivide import midpoint_mask, subdivide

    fem = cm.fem
    X, el = np.asarray(rest, float), np.asarray(fem.elements)
    fixed = np.zeros(len(X), bool)
    fixed[np.asarray(cm.fixed_vertices)] = True
    for _ in range(times):
        X, el, edges = subdivide(X, el)
        fixed = midpoint_mask(fixed, edges)
    new = make_model(X, el, fem.material, thickness=fem.thickness, device=fem.device)
    return make_coupling_model(name=cm.name, fem=new, field=cm.field, path=cm.path, fixed_vertices=np.flatnonzero(fixed),
                               options=cm.options, object_vertices=cm.object_vertices, object_faces=cm.object_faces)


def mesh_check(problem, rest: np.ndarray, *, figures0: dict | None = None, levels=None, quiet: bool = True) -> dict:
    """Run the design ``rest`` at each refinement level and compare (see the module docstring).

    figures0 : the optimizer's figures of ``rest`` (level 0), reused instead of simulating again
        (not for target matching: its RMS force error per level needs the profiles)
    Returns {"levels": [{elements, seconds}], "figures": {name: {values, extrapolated, order,
    converging, difference_of_optimization_mesh}}, "constraints": [{name, value, lo, hi,
    satisfied}] at the reference values, "feasible_fine": bool, "reference", "units"}.
    """
    from simfab.coupling.converge import extrapolate
    from simfab.coupling.simulate import simulate
    from simfab.design.optimize import profile_figures

    cm = problem.base
    levels = LEVELS[cm.dim] if levels is None else tuple(levels)
    rows, figs, profiles = [], [], []
    for t in levels:
        t0 = time.perf_counter()
        if t == 0 and figures0 is not None and problem.target is None:
            f, n = figures0, cm.fem.n_elements
        else:
            m = refined_model(cm, rest, t)
            res = simulate(m, quiet=quiet)
            f, n = profile_figures(res, problem.brief.stress_radius), m.fem.n_elements
            if problem.target is not None:  # the profile-matching error, a figure like the others
                f = dict(f, rms_error=problem.target.rms_error(res.column("s"), res.column("force")))
                profiles.append((res.column("s"), res.column("force")))
        rows.append({"subdivisions": int(t), "elements": int(n), "seconds": time.perf_counter() - t0,
                     "category": f["category"]})
        figs.append(f)
    N = np.array([r["elements"] for r in rows], float)
    out = {}
    for k in FIGURES + (("rms_error",) if problem.target is not None else ()):
        v = np.array([f[k] for f in figs], float)
        d = np.abs(np.diff(v))
        # converging: the changes shrink with refinement (a stress at a sharp re-entrant corner is
        # singular - its maximum grows without bound - and has no mesh-converged value)
        converging = bool(len(v) < 3 or d[-1] < d[-2] or d[-1] <= 1e-9 * max(np.abs(v).max(), 1e-300))
        f_inf, p = extrapolate(N, v, cm.dim) if len(v) >= 3 and converging else (None, float("nan"))
        ref = float(v[-1]) if f_inf is None else f_inf
        out[k] = {"values": v.tolist(), "extrapolated": f_inf, "order": p, "converging": converging,
                  "difference_of_optimization_mesh": float((v[0] - ref) / ref) if ref else 0.0}
    # the mesh-converged answer: extrapolated values where they exist, else the finest level's
    fine = dict(figs[-1], **{k: (v["values"][-1] if v["extrapolated"] is None else v["extrapolated"])
                             for k, v in out.items()})
    cons = B.constraints(fine, problem.limits)
    extra = {}
    if profiles:  # least-squares factor c of c F_coarse(s) ~ F_finest(s): the profile's mesh correction
        (s0, f0), (s1, f1) = profiles[0], profiles[-1]
        ref = np.interp(s0, s1, f1)
        extra["profile_force_factor"] = float(f0 @ ref / (f0 @ f0)) if f0 @ f0 > 0 else 1.0
    return {**extra, "levels": rows, "figures": out,
            "constraints": [{"name": c.name, "value": c.value, "lo": c.lo, "hi": c.hi, "satisfied": c.satisfied}
                            for c in cons],
            "feasible_fine": all(c.satisfied for c in cons),
            "reference": "extrapolated where converging, else the finest level",
            "units": {"coupling_ratio": "%", "grip_force": "N", "insertion_force": "N", "removal_force": "N",
                      "von_mises": "Pa", "von_mises_peak": "Pa", "rms_error": "N"}}


def check_warnings(check: dict) -> list[str]:
    """Summary warnings of a :func:`mesh_check`: constraints met only on the optimization mesh."""
    lv = check["levels"]
    bad = [c for c in check["constraints"] if not c["satisfied"]]
    if not bad:
        return []
    what = ", ".join(f"{c['name']} {c['value']:.4g} (bounds {c['lo']:.4g}..{c['hi']:.4g})" for c in bad)
    return [f"mesh-converged (refined up to {lv[-1]['elements']} elements from {lv[0]['elements']}) the design misses: {what}"]


def figure_unit(name: str) -> float:
    """The constraint unit of a mesh-check figure (:data:`simfab.design.brief.SCALES`; the raw
    stress peak like the averaged stress; 0 for figures without a constraint)."""
    return B.SCALES.get("von_mises" if name.startswith("von_mises") else name, 0.0)


def correction_factors(check: dict) -> dict:
    """{figure: reference value / optimization-mesh value} of a :func:`mesh_check` (space mapping
    of the coarse model's outputs: the optimizer multiplies its coarse figures by these, so that
    the next round aims at the mesh-converged values; figures with a zero coarse value keep 1)."""
    out = {}
    for k, v in check["figures"].items():
        coarse = v["values"][0]
        ref = v["values"][-1] if v["extrapolated"] is None else v["extrapolated"]
        # a figure below its constraint unit (1 N, 1 %, 1 MPa: B.SCALES) is noise, not a biased
        # value: its ratio (e.g. 1e-8 N / 1e-11 N) says nothing about the mesh
        if abs(coarse) < figure_unit(k):
            out[k] = 1.0
            continue
        r = ref / coarse if coarse else 1.0
        out[k] = float(np.clip(r, *FACTOR_RANGE)) if np.isfinite(r) and r > 0 else 1.0
    if "profile_force_factor" in check:  # target matching: the whole force profile, scaled
        out["force_profile"] = check["profile_force_factor"]
    return out


def needs_correction(check: dict, applied: dict) -> bool:
    """Another correction round is due when the mesh-converged figures miss the brief, or (target
    matching) when the coarse force profile, as corrected so far, is still more than
    PROFILE_TOL off the finest level's."""
    if not check["feasible_fine"]:
        return True
    c = check.get("profile_force_factor")
    return c is not None and abs(c / applied.get("force_profile", 1.0) - 1.0) > PROFILE_TOL


def checked_objective(problem, ev, check: dict) -> float:
    """The design objective with the mesh-converged figures of ``check``: E_L (or, for target
    matching, the squared RMS force error of the finest level) plus the penalties of the
    constraints at the reference values."""
    cons = [B.Constraint(name=c["name"], value=c["value"], lo=c["lo"], hi=c["hi"], unit=B.UNITS[c["name"]],
                         scale=B.SCALES[c["name"]]) for c in check["constraints"]]
    if problem.target is not None:
        v = check["figures"]["rms_error"]
        base = (v["values"][-1] if v["extrapolated"] is None else v["extrapolated"]) ** 2
    else:
        base = ev.E_L
    return float(base + B.penalty(cons))
