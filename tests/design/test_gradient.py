"""Design gradients (simfab.design.gradient): the brief's figures' derivatives with respect to the
handle parameters against central finite differences of whole evaluations, and the analytic E_L and
element-quality derivatives."""

import dataclasses

import numpy as np
import pytest

from simfab.coupling import config as C
from simfab.coupling.scene import load_coupling_scene
from simfab.design import figure_gradients as FG
from simfab.design import gradient as G
from simfab.design.brief import DesignConfig
from simfab.design.problem import element_quality, evaluate, make_problem


@pytest.fixture(scope="module")
def problem():
    cm = load_coupling_scene("block2d_tight", overrides={"simulation": {"steps": 12}})
    # the step positions held (the default insertion length follows A's farthest point)
    cm = dataclasses.replace(cm, options=dataclasses.replace(cm.options, L_max=float(cm.s_steps[-1])))
    return make_problem(cm, DesignConfig(grip="tight", handles=3, placement="spatial"))


@pytest.fixture(scope="module")
def problem_p2():
    """The same problem on P2 elements: handles on the linear mesh, candidates lifted to P2."""
    cm = load_coupling_scene("block2d_tight", overrides={"simulation": {"steps": 12, "element_order": 2}})
    cm = dataclasses.replace(cm, options=dataclasses.replace(cm.options, L_max=float(cm.s_steps[-1])))
    return make_problem(cm, DesignConfig(grip="tight", handles=3, placement="spatial"))


def _check_against_finite_differences(P, monkeypatch, names, rel=1e-4, rel_of=None):
    # exact maxima's gradients (T = 0) and equilibria solved far below the simulation's force
    # tolerance (see tests/coupling/test_adjoint.py): what is checked is the derivative itself
    monkeypatch.setattr(FG, "TEMPERATURE_REL", 0.0)  # the smooth maxima: simfab.design.figure_gradients
    monkeypatch.setattr(C, "NEWTON_GRAD_TOL_REL", 1e-10)
    monkeypatch.setattr(C, "NEWTON_GRAD_TOL_START", 1e-10)
    monkeypatch.setattr(C, "NEWTON_STEP_TOL_REL", 1e-12)
    Jh = G.handle_jacobian(P.handles)
    h0 = P.handles.identity()
    dh = np.random.default_rng(0).standard_normal(len(h0)) * P.sigma0
    ev = evaluate(P, h0, keep_result=True, recorder=lambda cm: G.DeferredRecorder(cm, G.stress_measure(P, cm)))
    fg = G.figure_gradients(P, ev, Jh)
    # the deferred recorder's sensitivities of the records the figures read give the gradients of
    # every record's (the same states replayed through the adjoint's recorder), up to the smooth
    # maxima's weights it drops (each below WEIGHT_FLOOR)
    rec = ev.recorder
    full = G.SensitivityRecorder(rec.cm, rec.stress)
    for r, st in rec.records:
        full(r, st)
    fg_full = G.figure_gradients(P, dataclasses.replace(ev, recorder=full), Jh)
    for name, g in fg_full.gradients.items():
        if g is not None:
            tol = len(rec.records) * G.WEIGHT_FLOOR * max(np.abs(g).max(), 1e-300)
            assert np.abs(fg.gradients[name] - g).max() <= tol, name
    assert fg.supported  # every record the figures read: its dependence on the records before it followed
    eps = 1e-2
    ep, em = evaluate(P, h0 + eps * dh), evaluate(P, h0 - eps * dh)
    assert ep.figures["category"] == em.figures["category"] == ev.figures["category"]
    for name in names:
        fd = (ep.figures[name] - em.figures[name]) / (2 * eps)
        assert abs(fd) > 0, name
        assert float(fg.gradients[name] @ dh) == pytest.approx(fd, rel=(rel_of or {}).get(name, rel)), name
    return ev, fg, len(rec.sensitivities(np.flatnonzero(
        G.needed_records(P, ev.result, G.analyze_run(ev.result), rec.stress_values()))))


FIGURES = ("E_max", "E_ss", "coupling_ratio", "insertion_force", "removal_force", "grip_force", "von_mises")


def test_figure_gradients_match_finite_differences(problem, monkeypatch):
    ev, _, computed = _check_against_finite_differences(problem, monkeypatch, FIGURES)
    assert ev.figures["category"] == "tight"
    assert computed < len(ev.result.steps)  # the records far from every figure's peak: none computed


def test_p2_figure_gradients_match_finite_differences(problem_p2, monkeypatch):
    """P2 candidates: the node derivatives chained to the linear mesh's vertices (edge nodes at the
    midpoints) before the handle Jacobian; the stress averaged over the quadrature points."""
    P = problem_p2
    assert type(P.base.fem).__name__ == "P2Model" and P.handles.rest.shape == P.mesh.rest.shape
    assert P.mesh.n_vertices < P.base.fem.n_vertices
    # the averaging's own dependence on X (quadrature weights) is not differentiated
    # (simfab.coupling.adjoint.StressMeasure): 4e-4 of the stress's derivative here
    ev, _, _ = _check_against_finite_differences(P, monkeypatch, FIGURES, rel_of={"von_mises": 1e-3})
    assert ev.result.model.fem.element_order == 2 and ev.figures["category"] == "tight"


def test_modification_and_quality_gradients(problem):
    P = problem
    Jh = G.handle_jacobian(P.handles)
    rng = np.random.default_rng(1)
    h = P.handles.identity() + 0.3 * rng.standard_normal(P.handles.n_vars) * P.sigma0
    dh = rng.standard_normal(P.handles.n_vars) * P.sigma0
    eps = 1e-5
    fd = (P.energy(P.handles.apply(h + eps * dh)) - P.energy(P.handles.apply(h - eps * dh))) / (2 * eps)
    assert float(G.modification_gradient(P, P.handles.apply(h), Jh) @ dh) == pytest.approx(fd, rel=1e-6)
    el = P.mesh.elements
    fdq = (element_quality(P.handles.apply(h + eps * dh), el) - element_quality(P.handles.apply(h - eps * dh), el)) / (
        2 * eps)
    Jq = G.quality_jacobian(P.handles.apply(h), el) @ Jh
    assert np.abs(Jq @ dh - fdq).max() <= 1e-6 * np.abs(fdq).max()


@pytest.mark.parametrize("order", [1, 2])
def test_couple_optimize_gradient_method(tmp_path, order):
    import json
    import subprocess
    import sys

    out = tmp_path / "o"
    r = subprocess.run([sys.executable, "-m", "simfab", "couple", "optimize", "block2d_tight", "--method", "gradient",
                        "--steps", "8", "--handles", "3", "--placement", "spatial", "--iterations", "3",
                        "--element-order", str(order),
                        "--check-refinements", "0", "--correction-rounds", "0", "--out", str(out), "--json"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    # the mesh check starts at the optimization mesh's own elements
    assert [lv["element_order"] for lv in s["mesh_check"]["levels"]] == ([1, 2] if order == 1 else [2])
    assert s["method"] == "gradient" and s["iterations"] <= 3
    # every design SLSQP visited was simulated once, and each complete insertion gave its gradients
    assert 1 <= s["gradient_evaluations"] <= s["insertions"]
    assert s["E_L"] >= 0
    if s["feasible"]:
        assert all(c["satisfied"] for c in s["constraints"].values())
    for k, p in s["outputs"].items():
        assert (out / p.split("/")[-1]).is_file(), k


def test_frictional_figure_gradients_match_finite_differences(monkeypatch):
    """mu = 0.3 with its removal traversal: F_rm and F_hold read from the removal records, whose
    sensitivities the adjoint's backward pass carries through the friction anchors; the lag solved
    to 1e-6 (the adjoint differentiates each step at its converged lag)."""
    cm = load_coupling_scene("block2d_tight", overrides={
        "simulation": {"steps": 12}, "contact": {"friction": 0.3, "lag_tol": 1e-6, "max_lag_iterations": 50}})
    cm = dataclasses.replace(cm, options=dataclasses.replace(cm.options, L_max=float(cm.s_steps[-1])))
    P = make_problem(cm, DesignConfig(grip="tight", handles=3, placement="spatial"))
    ev, fg, _ = _check_against_finite_differences(
        P, monkeypatch, ("E_max", "insertion_force", "grip_force", "removal_force", "hold_force"))
    assert ev.result.removal and fg.supported
    assert fg.values["removal_force"] > 0 and fg.values["hold_force"] > 0
