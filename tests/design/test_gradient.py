"""Design gradients (simfab.design.gradient): the brief's figures' derivatives with respect to the
handle parameters against central finite differences of whole evaluations, and the analytic E_L and
element-quality derivatives."""

import dataclasses

import numpy as np
import pytest

from simfab.coupling import config as C
from simfab.coupling.scene import load_coupling_scene
from simfab.design import gradient as G
from simfab.design.brief import DesignBrief
from simfab.design.problem import element_quality, evaluate, make_problem


@pytest.fixture(scope="module")
def problem():
    cm = load_coupling_scene("block2d_tight", overrides={"simulation": {"steps": 12}})
    # the step positions held (the default insertion length follows A's farthest point)
    cm = dataclasses.replace(cm, options=dataclasses.replace(cm.options, L_max=float(cm.s_steps[-1])))
    return make_problem(cm, DesignBrief(grip="tight", handles=3, placement="spatial"))


def test_figure_gradients_match_finite_differences(problem, monkeypatch):
    # exact maxima's gradients (T = 0) and equilibria solved far below the simulation's force
    # tolerance (see tests/coupling/test_adjoint.py): what is checked is the derivative itself
    monkeypatch.setattr(G, "TEMPERATURE_REL", 0.0)
    monkeypatch.setattr(C, "NEWTON_GRAD_TOL_REL", 1e-10)
    monkeypatch.setattr(C, "NEWTON_GRAD_TOL_START", 1e-10)
    monkeypatch.setattr(C, "NEWTON_STEP_TOL_REL", 1e-12)
    P = problem
    Jh = G.handle_jacobian(P.handles)
    h0 = P.handles.identity()
    dh = np.random.default_rng(0).standard_normal(len(h0)) * P.sigma0
    ev = evaluate(P, h0, keep_result=True,
                  recorder=lambda cm: G.SensitivityRecorder(cm, G.stress_measure(P, cm)))
    fg = G.figure_gradients(P, ev, Jh)
    # (the first steps, before contact, are solved with a rigid-motion pin, fg.supported False: no figure
    # is read from them)
    eps = 1e-2
    ep, em = evaluate(P, h0 + eps * dh), evaluate(P, h0 - eps * dh)
    assert ep.figures["category"] == em.figures["category"] == ev.figures["category"] == "tight"
    for name in ("E_max", "E_ss", "coupling_ratio", "insertion_force", "removal_force", "grip_force", "von_mises"):
        fd = (ep.figures[name] - em.figures[name]) / (2 * eps)
        assert float(fg.gradients[name] @ dh) == pytest.approx(fd, rel=1e-4), name


def test_modification_and_quality_gradients(problem):
    P = problem
    Jh = G.handle_jacobian(P.handles)
    rng = np.random.default_rng(1)
    h = P.handles.identity() + 0.3 * rng.standard_normal(P.handles.n_vars) * P.sigma0
    dh = rng.standard_normal(P.handles.n_vars) * P.sigma0
    eps = 1e-5
    fd = (P.energy(P.handles.apply(h + eps * dh)) - P.energy(P.handles.apply(h - eps * dh))) / (2 * eps)
    assert float(G.modification_gradient(P, P.handles.apply(h), Jh) @ dh) == pytest.approx(fd, rel=1e-6)
    el = P.base.fem.elements
    fdq = (element_quality(P.handles.apply(h + eps * dh), el) - element_quality(P.handles.apply(h - eps * dh), el)) / (
        2 * eps)
    Jq = G.quality_jacobian(P.handles.apply(h), el) @ Jh
    assert np.abs(Jq @ dh - fdq).max() <= 1e-6 * np.abs(fdq).max()


def test_couple_optimize_gradient_method(tmp_path):
    import json
    import subprocess
    import sys

    out = tmp_path / "o"
    r = subprocess.run([sys.executable, "-m", "simfab", "couple", "optimize", "block2d_tight", "--method", "gradient",
                        "--steps", "8", "--handles", "3", "--placement", "spatial", "--iterations", "3",
                        "--check-refinements", "0", "--correction-rounds", "0", "--out", str(out), "--json"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["method"] == "gradient" and s["iterations"] <= 3
    # every design SLSQP visited was simulated once, and each complete insertion gave its gradients
    assert 1 <= s["gradient_evaluations"] <= s["insertions"]
    assert s["E_L"] >= 0
    if s["feasible"]:
        assert all(c["satisfied"] for c in s["constraints"].values())
    for k, p in s["outputs"].items():
        assert (out / p.split("/")[-1]).is_file(), k
