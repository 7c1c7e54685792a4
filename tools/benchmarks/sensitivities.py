"""Adjoint sensitivities of insertion records against finite differences: the full table.

``python tools/bench.py sensitivities [--eps 1e-3] [--newton-tol 1e-10]``

Per scene (a 2D snap fit ``block2d_tight`` at 12 steps; a rotating 2D path: an ellipse turned 90
degrees in the loose clamp; a 3D clip ``clip3d`` at 8 steps, linear tets, all support dofs held) and
per figure (elastic energy, insertion force, grip, the averaged von Mises maximum): the largest
difference between the adjoint derivative (:mod:`simfab.coupling.adjoint`) along a smooth rest-shape
perturbation and the central difference of whole insertions, relative to the figure's largest
derivative over the run, over the steps solved without a rigid-motion pin; with the simulation's
own Newton tolerance and with a tight one (``--newton-tol``: the adjoint differentiates the exact
equilibrium). Also the seconds of a plain insertion and of one recording the sensitivities.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np


def _models():
    from simfab.contact.imls import build_imls, curve_normals
    from simfab.coupling.config import InsertionOptions
    from simfab.coupling.scene import load_coupling_scene
    from simfab.coupling.simulate import make_coupling_model
    from simfab.io.mjcf import Trajectory

    snap = load_coupling_scene("block2d_tight", overrides={"simulation": {"steps": 12}})
    base = load_coupling_scene("clip2d_loose")
    t = np.linspace(0, 2 * np.pi, 120, endpoint=False)
    v = np.c_[11.2e-3 * np.cos(t), 8.0e-3 * np.sin(t)]
    q90 = [np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)]
    path = Trajectory(np.array([[1.0e-3, 0, 0], [0.9e-3, 0, 0], [0.9e-3, 0, 0]]),
                      np.array([[1.0, 0, 0, 0], [1.0, 0, 0, 0], q90]), rot_length_scale=0.01)
    rot = make_coupling_model(name="ellipse", fem=base.fem, field=build_imls(v, curve_normals(v)), path=path,
                              fixed_vertices=base.fixed_vertices, options=InsertionOptions(steps=10, fix_all_axes=True),
                              object_vertices=v)
    sim = {"steps": 8, "element_order": 1, "fix_all_axes": True}
    part = {"target_elements": 300, "layers": 1}
    clip = load_coupling_scene("clip3d", overrides={"simulation": sim, "compliant": part})
    return {"snap_fit_2d": (snap, ("energy", "force", "grip", "stress")),
            "rotating_path_2d": (rot, ("energy", "grip", "stress")),
            "clip_3d": (clip, ("energy", "force", "grip", "stress"))}


def _with_rest(cm, X):
    from simfab.coupling.simulate import make_coupling_model
    from simfab.fem.model import make_model

    fem = make_model(X, cm.fem.elements, cm.fem.material, thickness=cm.fem.thickness)
    return make_coupling_model(name=cm.name, fem=fem, field=cm.field, path=cm.path, fixed_vertices=cm.fixed_vertices,
                               options=cm.options, object_vertices=cm.object_vertices, object_faces=cm.object_faces,
                               contact=cm.contact)


def _errors(cm, figures, eps):
    from simfab.coupling.adjoint import SensitivityRecorder, StressMeasure
    from simfab.coupling.simulate import simulate
    from simfab.design.stress import averaging_matrix

    X = np.asarray(cm.fem.rest, float)
    rng = np.random.default_rng(0)
    k = rng.standard_normal((cm.dim, cm.dim)) / np.ptp(X, axis=0).max()
    dX = 0.01 * cm.h * np.sin((X - X.mean(axis=0)) @ k + rng.uniform(0, np.pi, cm.dim))
    A = averaging_matrix(cm.fem, 0.5e-3)
    rec = SensitivityRecorder(cm, StressMeasure(averaging=A, temperature_rel=0.0))
    t0 = time.perf_counter()
    simulate(cm, recorder=rec)
    t_adj = time.perf_counter() - t0
    t0 = time.perf_counter()
    plus = simulate(_with_rest(cm, X + eps * dX))
    t_plain = time.perf_counter() - t0
    minus = simulate(_with_rest(cm, X - eps * dX))
    ok = [i for i, sn in enumerate(rec.insert) if sn.supported]
    out = {}
    for key in figures:
        def value(r):
            return float((A @ r.von_mises).max()) if key == "stress" else getattr(r, key)

        fd = np.array([(value(p) - value(m)) / (2 * eps) for p, m in zip(plus.steps, minus.steps)])[ok]
        an = np.array([float(np.sum(getattr(sn, key) * dX)) for sn in rec.insert])[ok]
        out[key] = float(np.abs(an - fd).max() / np.abs(fd).max())
    return out, len(ok), len(rec.insert), t_plain, t_adj


def run(argv) -> dict:
    from simfab.coupling import config as C

    ap = argparse.ArgumentParser(prog="bench.py sensitivities")
    ap.add_argument("--eps", type=float, default=1e-3)
    ap.add_argument("--newton-tol", type=float, default=1e-10)
    a = ap.parse_args(argv)
    rows = []
    defaults = (C.NEWTON_GRAD_TOL_REL, C.NEWTON_GRAD_TOL_START, C.NEWTON_STEP_TOL_REL)
    for name, (cm, figures) in _models().items():
        cm = dataclasses.replace(cm, options=dataclasses.replace(cm.options, L_max=float(cm.s_steps[-1])))
        for tol in ("simulation's", "tight"):
            if tol == "tight":
                C.NEWTON_GRAD_TOL_REL = C.NEWTON_GRAD_TOL_START = a.newton_tol
                C.NEWTON_STEP_TOL_REL = 1e-2 * a.newton_tol
            try:
                err, ok, n, t_plain, t_adj = _errors(cm, figures, a.eps)
            finally:
                C.NEWTON_GRAD_TOL_REL, C.NEWTON_GRAD_TOL_START, C.NEWTON_STEP_TOL_REL = defaults
            rows.append({"scene": name, "newton_tolerance": tol, "relative_error": err, "steps_checked": ok,
                         "steps": n, "seconds_insertion": t_plain, "seconds_with_sensitivities": t_adj})
    worst = max(max(r["relative_error"].values()) for r in rows if r["newton_tolerance"] == "tight")
    return {"benchmark": "sensitivities", "rows": rows, "target_relative_error": 1e-4,
            "worst_relative_error_tight": worst, "meets_target": worst <= 1e-4}
