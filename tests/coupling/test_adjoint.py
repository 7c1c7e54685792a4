"""Adjoint sensitivities of insertion records to the rest shape (simfab.coupling.adjoint) against
central finite differences of whole insertions on perturbed rest shapes: a 2D snap fit (linear and
P2 elements, frictionless and at mu = 0.3 with its removal), a rotating 2D path (frictionless and
at mu = 0.3) and a 3D clip whose slide along the cylinder is pinned (the pin's anchor followed
through the steps).

The adjoint differentiates the exact equilibrium of each step; the simulation stops Newton at a
force residual of NEWTON_GRAD_TOL_REL * force_scale, and the finite differences of figures that
read single contact forces (the grip) then see the solver's residual (~3e-3 relative on a snap
fit). The reference runs are therefore solved to a residual 1e-6 times smaller (the config's
public tolerances, raised for these runs), which is what "the derivative of the step's record"
means; at 1e-4 the difference quotients kept the residual's noise, and agreed only while the
perturbed runs took the same solver path (the same lagged and direct solves). With friction the
lag is converged likewise (``lag_tol`` 1e-6): the adjoint differentiates the step at its converged
lag. Steps solved from an unrecorded state (``supported`` False) are excluded. P2 models are
rebuilt from the perturbed linear mesh (``to_p2``), their derivatives chained to its vertices
(``linear_rest_derivative``).
"""

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp

from simfab.coupling import config as C
from simfab.coupling.adjoint import SensitivityRecorder, StressMeasure
from simfab.coupling.model import with_rest_shape
from simfab.coupling.scene import load_coupling_scene
from simfab.coupling.simulate import simulate_insertion
from simfab.design.stress import averaging_matrix, quadrature_von_mises
from simfab.fem.shape_derivative import linear_rest_derivative

EPS = 1e-3  # central-difference step along dX, whose size is ~1 % of A's mean edge length
FRICTION = {"friction": 0.3, "lag_tol": 1e-6, "max_lag_iterations": 50}


@pytest.fixture
def tight_newton(monkeypatch):
    monkeypatch.setattr(C, "NEWTON_GRAD_TOL_REL", 1e-12)
    monkeypatch.setattr(C, "NEWTON_GRAD_TOL_START", 1e-12)
    # no step-size stop: at round-off it can fire with the residual above it, and a difference quotient of
    # two references stopped at different residuals is noise (docs/decisions.md, the contact predictor)
    monkeypatch.setattr(C, "NEWTON_STEP_TOL_REL", 0.0)


def linear_mesh(cm):
    return cm.fem.linear if cm.fem.element_order == 2 else cm.fem


def smooth_field(cm, seed):
    """A smooth perturbation (n, dim) of the linear mesh's rest shape, of amplitude ~ 1 % of the edge
    length: the profile's derivative along it is what is checked."""
    X = np.asarray(linear_mesh(cm).rest, float)
    rng = np.random.default_rng(seed)
    c = X.mean(axis=0)
    size = np.ptp(X, axis=0).max()
    k = rng.standard_normal((cm.dim, cm.dim)) / size
    return 0.01 * cm.h * np.sin((X - c) @ k + rng.uniform(0, np.pi, cm.dim))


def stresses(fem, x):
    """Per-point von Mises stresses: per element (linear), at the quadrature points (P2)."""
    from simfab.fem.shape_derivative import point_von_mises

    return quadrature_von_mises(fem, x).ravel() if fem.element_order == 2 else point_von_mises(fem, x)


def compare(cm, sens, plus, minus, dX, A, figures, ok, tol=1e-4):
    for key in figures:
        def value(r, run):
            return float((A @ stresses(run.model.fem, r.x)).max()) if key == "stress" else getattr(r, key)

        fd = np.array([(value(p, plus) - value(m, minus)) / (2 * EPS) for p, m in zip(*ok[0])])[ok[1]]
        an = np.array([float(np.sum(linear_rest_derivative(cm.fem, getattr(sn, key)) * dX)) for sn in sens])[ok[1]]
        scale = np.abs(fd).max()
        assert scale > 0
        # relative to the figure's largest derivative over the run: steps out of contact have ~0 of both
        assert np.abs(an - fd).max() <= tol * scale, (key, an, fd)


def check(cm, seed=0, min_supported=3, figures=("energy", "force", "grip", "stress"), tol=1e-4):
    cm = dataclasses.replace(cm, options=dataclasses.replace(cm.options, L_max=float(cm.s_steps[-1])))
    X = np.asarray(linear_mesh(cm).rest, float)
    dX = smooth_field(cm, seed)
    if cm.fem.element_order == 2:  # held fixed (its X-dependence is not differentiated); P2: the points' maximum
        A = sp.identity(stresses(cm.fem, cm.fem.rest).size, format="csr")
    else:
        A = averaging_matrix(cm.fem, 0.5e-3)
    rec = SensitivityRecorder(cm, StressMeasure(averaging=A, temperature_rel=0.0))  # T = 0: the max's gradient
    base = simulate_insertion(cm, recorder=rec)
    plus = simulate_insertion(with_rest_shape(cm, X + EPS * dX))
    minus = simulate_insertion(with_rest_shape(cm, X - EPS * dX))
    assert [r.s for r in plus.steps] == [r.s for r in base.steps] == [r.s for r in minus.steps]
    assert plus.refined_facets == minus.refined_facets == base.refined_facets  # no refinement event between
    # nor a barrier-stiffness doubling at another step (each kappa is a fixed multiple of kappa_0 on a branch)
    doublings = [[r.kappa / run.model.kappa for r in run.steps] for run in (plus, minus, base)]
    assert doublings[0] == doublings[1] == doublings[2]
    ok = [k for k, sn in enumerate(rec.insert) if sn.supported]
    assert len(ok) >= min_supported and all(sn.stable for sn in rec.insert)
    compare(cm, rec.insert, plus, minus, dX, A, figures, ((plus.steps, minus.steps), ok), tol)
    if cm.contact.friction > 0:  # the removal: a traversal of its own, each step from the one before
        assert len(rec.remove) == len(plus.removal) == len(minus.removal) > 0
        assert all(sn.supported for sn in rec.remove)
        compare(cm, rec.remove, plus, minus, dX, A, tuple(f for f in figures if f != "stress"),
                ((plus.removal, minus.removal), list(range(len(rec.remove)))), tol)
    return base, rec


def test_snap_fit_2d(tight_newton):
    check(load_coupling_scene("block2d_tight", overrides={"simulation": {"steps": 12}}))


def test_snap_fit_2d_p2(tight_newton):
    check(load_coupling_scene("block2d_tight", overrides={"simulation": {"steps": 12, "element_order": 2}}))


def test_snap_fit_2d_friction(tight_newton):
    # every step starts from the one before (the friction anchors): the backward pass follows them
    check(load_coupling_scene("block2d_tight", overrides={"simulation": {"steps": 12}, "contact": FRICTION}))


def test_rotating_path_2d(tight_newton, ellipse_in_clamp_model):
    # the insertion force (along O's translation) is zero during the pure rotation
    check(ellipse_in_clamp_model(steps=10), figures=("energy", "grip", "stress"))


def test_rotating_path_2d_friction(tight_newton, ellipse_in_clamp_model):
    # the anchors turn with O over each step (M != I in the backward pass)
    cm = ellipse_in_clamp_model(steps=10)
    cm = dataclasses.replace(cm, contact=dataclasses.replace(cm.contact, **FRICTION))
    check(cm, figures=("energy", "grip", "stress"))


def test_clip_3d_pinned_slide(tight_newton):
    # the support holds the clip along the insertion axis only: its slide along the cylinder is
    # pinned at every step (anchored at the step's start, followed back through the steps)
    cm = load_coupling_scene("clip3d", overrides={"simulation": {"steps": 8, "element_order": 1},
                                                  "compliant": {"target_elements": 300, "layers": 1}})
    _, rec = check(cm)
    assert sum(sn.supported for sn in rec.insert) >= len(rec.insert) - 1


@pytest.mark.parametrize("friction", [0.0, 0.3])
def test_clip_3d_after_barrier_stiffness_doublings(tight_newton, friction):
    # a soft initial barrier (kappa_rel 1e-4): contact gaps fall below KAPPA_GROW_BELOW d_hat and the run
    # doubles kappa twice; in 3D kappa_0 = kappa_rel E h_A moves with the design, and a step's kappa is
    # kappa_0 times the doublings, so its derivative carries them (without that factor: force 1.5e-4,
    # stress 6.7e-5 of their largest derivatives; with it 4e-7, 1.6e-6; grip 2.1e-5). With friction a
    # step solved from an unrecorded state (held) cuts the chain of the records after it: those whose
    # chain still matters there are not supported (before, the next record's stress was off by 2e-3)
    over = {"simulation": {"steps": 8, "element_order": 1, "kappa_rel": 1e-4},
            "compliant": {"target_elements": 300, "layers": 1}}
    if friction:
        over["contact"] = FRICTION
    cm = load_coupling_scene("clip3d", overrides=over)
    base, rec = check(cm, tol=5e-5)
    assert max(r.kappa for r in base.steps) >= 4.0 * cm.kappa  # the branch under test: two doublings
    if friction:  # a held step, and records after it cut off
        held = [k for k, sn in enumerate(rec.insert) if not sn.supported]
        assert held and held[-1] > held[0]
