"""Adjoint sensitivities of insertion records against finite differences: the full table.

``python tools/bench.py sensitivities [--eps 1e-3] [--newton-tol 1e-10] [--lag-tol 1e-6] [--only NAME,...]``

Scenes: a 2D snap fit (``block2d_tight``, 12 steps) with linear and P2 elements and at mu = 0.3;
a rotating 2D path (an ellipse turned 90 degrees in the loose clamp), frictionless and at mu = 0.3;
a 3D clip (``clip3d``, 8 steps, 300 elements) with linear tets and all support dofs held, with its
slide along the cylinder pinned (support along the insertion axis only), with P2 tets and at mu = 0.3. Per
scene and figure (elastic energy, insertion force, grip, the averaged von Mises maximum; the
frictional scenes also over their removal records): the largest difference between the adjoint
derivative (:mod:`simfab.coupling.adjoint`) along a smooth rest-shape perturbation and the central
difference of whole insertions, relative to the figure's largest derivative over the run, over the
steps solved from a recorded state (``supported``); at the simulation's own Newton and lag
tolerances and at tight ones (``--newton-tol``, ``--lag-tol``: the adjoint differentiates the exact
equilibrium at a converged lag). The frictional scenes also with the lag's normal forces and normals
held fixed (``held_lag``, the cheaper approximation), to measure the error that causes. Also the
seconds of a plain insertion and of one recording the sensitivities (including the backward pass).
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

FIGURES = ("energy", "force", "grip", "stress")
FRICTION = 0.3


def _models() -> dict:
    """name -> (model, figures); built on demand (the 3D ones take seconds)."""
    from simfab.contact.imls import build_imls, curve_normals
    from simfab.coupling.config import InsertionConfig
    from simfab.coupling.scene import load_coupling_scene
    from simfab.coupling.simulate import make_coupling_model
    from simfab.io.mjcf import Trajectory

    def snap(order=1, mu=0.0):
        return load_coupling_scene("block2d_tight", overrides={"simulation": {"steps": 12, "element_order": order},
                                                               "contact": {"friction": mu}})

    def rot(mu=0.0):
        base = load_coupling_scene("clip2d_loose", overrides={"contact": {"friction": mu}})
        t = np.linspace(0, 2 * np.pi, 120, endpoint=False)
        v = np.c_[11.2e-3 * np.cos(t), 8.0e-3 * np.sin(t)]
        q90 = [np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)]
        path = Trajectory(np.array([[1.0e-3, 0, 0], [0.9e-3, 0, 0], [0.9e-3, 0, 0]]),
                          np.array([[1.0, 0, 0, 0], [1.0, 0, 0, 0], q90]), rot_length_scale=0.01)
        return make_coupling_model(name="ellipse", fem=base.fem, field=build_imls(v, curve_normals(v)), path=path,
                                   fixed_vertices=base.fixed_vertices,
                                   options=InsertionConfig(steps=10, fix_all_axes=True), object_vertices=v,
                                   contact=base.contact)

    def clip(order=1, held=True, mu=0.0):
        sim = {"steps": 8, "element_order": order, "fix_all_axes": held}
        return load_coupling_scene("clip3d", overrides={"simulation": sim, "contact": {"friction": mu},
                                                        "compliant": {"target_elements": 300, "layers": 1}})

    no_force = ("energy", "grip", "stress")  # the force along O's translation is zero during the rotation
    return {"snap_fit_2d": (lambda: snap(), FIGURES),
            "snap_fit_2d_p2": (lambda: snap(order=2), FIGURES),
            "snap_fit_2d_friction": (lambda: snap(mu=FRICTION), FIGURES),
            "rotating_path_2d": (lambda: rot(), no_force),
            "rotating_path_2d_friction": (lambda: rot(mu=FRICTION), no_force),
            "clip_3d": (lambda: clip(), FIGURES),
            "clip_3d_pinned_slide": (lambda: clip(held=False), FIGURES),
            "clip_3d_p2": (lambda: clip(order=2), FIGURES),
            "clip_3d_friction": (lambda: clip(mu=FRICTION), FIGURES)}


def _linear(cm):
    return cm.fem.linear if cm.fem.element_order == 2 else cm.fem


def _stresses(fem, x):
    from simfab.design.stress import quadrature_von_mises
    from simfab.fem.shape_derivative import point_von_mises

    return quadrature_von_mises(fem, x).ravel() if fem.element_order == 2 else point_von_mises(fem, x)


def _errors(cm, figures, eps) -> list[dict]:
    import scipy.sparse as sp

    from simfab.coupling.adjoint import SensitivityRecorder, StressMeasure
    from simfab.coupling.model import with_rest_shape
    from simfab.coupling.simulate import simulate_insertion
    from simfab.design.stress import averaging_matrix
    from simfab.fem.shape_derivative import linear_rest_derivative

    X = np.asarray(_linear(cm).rest, float)
    rng = np.random.default_rng(0)
    k = rng.standard_normal((cm.dim, cm.dim)) / np.ptp(X, axis=0).max()
    dX = 0.01 * cm.h * np.sin((X - X.mean(axis=0)) @ k + rng.uniform(0, np.pi, cm.dim))
    p2 = cm.fem.element_order == 2
    A = sp.identity(_stresses(cm.fem, cm.fem.rest).size, format="csr") if p2 else averaging_matrix(cm.fem, 0.5e-3)
    frictional = cm.contact.friction > 0
    variants = (False, True) if frictional else (False,)
    recs, t_adj = {}, None
    for held in variants:
        recs[held] = SensitivityRecorder(cm, StressMeasure(averaging=A, temperature_rel=0.0), held_lag=held)
        t0 = time.perf_counter()
        simulate_insertion(cm, recorder=recs[held])
        recs[held].insert  # the backward pass runs on first access
        if not held:
            t_adj = time.perf_counter() - t0
    t0 = time.perf_counter()
    plus = simulate_insertion(with_rest_shape(cm, X + eps * dX))
    t_plain = time.perf_counter() - t0
    minus = simulate_insertion(with_rest_shape(cm, X - eps * dX))

    def table(sens, pr, mr, keys):
        ok = [i for i, sn in enumerate(sens) if sn.supported]
        out = {}
        for key in keys:
            def value(r, run):
                return float((A @ _stresses(run.model.fem, r.x)).max()) if key == "stress" else getattr(r, key)

            fd = np.array([(value(p, plus) - value(m, minus)) / (2 * eps) for p, m in zip(pr, mr)])[ok]
            an = np.array([float(np.sum(linear_rest_derivative(cm.fem, getattr(sn, key)) * dX)) for sn in sens])[ok]
            out[key] = float(np.abs(an - fd).max() / np.abs(fd).max())
        return out, len(ok)

    rows = []
    for held, rec in recs.items():
        err, ok = table(rec.insert, plus.steps, minus.steps, figures)
        row = {"relative_error": err, "steps_checked": ok, "steps": len(rec.insert), "friction_lag": None,
               "seconds_insertion": t_plain, "seconds_with_sensitivities": t_adj}
        if frictional:
            row["friction_lag"] = "held" if held else "differentiated"
            same = len(rec.remove) == len(plus.removal) == len(minus.removal)
            row["relative_error_removal"] = (table(rec.remove, plus.removal, minus.removal,
                                                   [f for f in figures if f != "stress"])[0] if same else None)
        rows.append(row)
    return rows


def run(argv) -> dict:
    from simfab.coupling import config as C

    ap = argparse.ArgumentParser(prog="bench.py sensitivities")
    ap.add_argument("--eps", type=float, default=1e-3)
    ap.add_argument("--newton-tol", type=float, default=1e-10)
    ap.add_argument("--lag-tol", type=float, default=1e-6)
    ap.add_argument("--only", default=None, help="comma-separated scene names (default: all)")
    a = ap.parse_args(argv)
    models = _models()
    names = list(models) if a.only is None else [n.strip() for n in a.only.split(",")]
    unknown = [n for n in names if n not in models]
    if unknown:
        from simfab.errors import InputError
        raise InputError(f"unknown scene(s) {unknown}; have {list(models)}", where="--only")
    rows = []
    defaults = (C.NEWTON_GRAD_TOL_REL, C.NEWTON_GRAD_TOL_START, C.NEWTON_STEP_TOL_REL)
    for name in names:
        build, figures = models[name]
        cm = build()
        cm = dataclasses.replace(cm, options=dataclasses.replace(cm.options, L_max=float(cm.s_steps[-1])))
        for tol in ("simulation's", "tight"):
            model = cm
            if tol == "tight":
                C.NEWTON_GRAD_TOL_REL = C.NEWTON_GRAD_TOL_START = a.newton_tol
                C.NEWTON_STEP_TOL_REL = 1e-2 * a.newton_tol
                if cm.contact.friction > 0:
                    model = dataclasses.replace(cm, contact=dataclasses.replace(cm.contact, lag_tol=a.lag_tol,
                                                                                max_lag_iterations=50))
            try:
                for row in _errors(model, figures, a.eps):
                    rows.append({"scene": name, "element_order": cm.fem.element_order, "dim": cm.dim,
                                 "friction": cm.contact.friction, "tolerance": tol, **row})
            finally:
                C.NEWTON_GRAD_TOL_REL, C.NEWTON_GRAD_TOL_START, C.NEWTON_STEP_TOL_REL = defaults
    exact = [r for r in rows if r["tolerance"] == "tight" and r["friction_lag"] != "held"]
    worst = max(max(list(r["relative_error"].values()) + list((r.get("relative_error_removal") or {}).values()))
                for r in exact)
    return {"benchmark": "sensitivities", "rows": rows, "target_relative_error": 1e-4,
            "worst_relative_error_tight": worst, "ratio_to_target": worst / 1e-4, "meets_target": worst <= 1e-4}
