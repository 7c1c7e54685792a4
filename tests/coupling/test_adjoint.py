"""Adjoint sensitivities of insertion records to the rest shape (simfab.coupling.adjoint) against
central finite differences of whole insertions on perturbed rest shapes: a 2D snap fit, a 3D clip
and a rotating 2D path.

The adjoint differentiates the exact equilibrium of each step; the simulation stops Newton at a
force residual of NEWTON_GRAD_TOL_REL * force_scale, and the finite differences of figures that
read single contact forces (the grip) then see the solver's residual (~3e-3 relative on a snap
fit). The reference runs are therefore solved to a residual 1e-4 times smaller (the config's
public tolerances, raised for these runs), which is what "the derivative of the step's record"
means. Steps solved with a rigid-motion pin (nothing touching A yet) are excluded (``supported``).
"""

import dataclasses

import numpy as np
import pytest

from simfab.coupling import config as C
from simfab.coupling.adjoint import SensitivityRecorder, StressMeasure
from simfab.coupling.scene import load_coupling_scene
from simfab.coupling.simulate import make_coupling_model, simulate
from simfab.design.stress import averaging_matrix
from simfab.fem.model import make_model

EPS = 1e-3  # central-difference step along dX, whose size is ~1 % of A's mean edge length


@pytest.fixture
def tight_newton(monkeypatch):
    monkeypatch.setattr(C, "NEWTON_GRAD_TOL_REL", 1e-10)
    monkeypatch.setattr(C, "NEWTON_GRAD_TOL_START", 1e-10)
    monkeypatch.setattr(C, "NEWTON_STEP_TOL_REL", 1e-12)


def with_rest(cm, X):
    """``cm`` with A's rest shape X (same mesh, material, object, path, supports and options)."""
    fem = make_model(X, cm.fem.elements, cm.fem.material, thickness=cm.fem.thickness)
    return make_coupling_model(name=cm.name, fem=fem, field=cm.field, path=cm.path, fixed_vertices=cm.fixed_vertices,
                               options=cm.options, object_vertices=cm.object_vertices, object_faces=cm.object_faces,
                               contact=cm.contact)


def smooth_field(cm, seed):
    """A smooth rest-shape perturbation (n, dim) of amplitude ~ 1 % of the edge length: the profile's
    derivative along it is what is checked."""
    X = np.asarray(cm.fem.rest, float)
    rng = np.random.default_rng(seed)
    c = X.mean(axis=0)
    size = np.ptp(X, axis=0).max()
    k = rng.standard_normal((cm.dim, cm.dim)) / size
    return 0.01 * cm.h * np.sin((X - c) @ k + rng.uniform(0, np.pi, cm.dim))


def check(cm, seed=0, min_supported=3, figures=("energy", "force", "grip", "stress")):
    cm = dataclasses.replace(cm, options=dataclasses.replace(cm.options, L_max=float(cm.s_steps[-1])))
    X = np.asarray(cm.fem.rest, float)
    dX = smooth_field(cm, seed)
    A = averaging_matrix(cm.fem, 0.5e-3)  # held fixed (its X-dependence is not differentiated)
    rec = SensitivityRecorder(cm, StressMeasure(averaging=A, temperature_rel=0.0))  # T = 0: the max's gradient
    base = simulate(cm, recorder=rec)
    plus = simulate(with_rest(cm, X + EPS * dX))
    minus = simulate(with_rest(cm, X - EPS * dX))
    assert [r.s for r in plus.steps] == [r.s for r in base.steps] == [r.s for r in minus.steps]
    assert plus.refined_facets == minus.refined_facets == base.refined_facets  # no refinement event between
    ok = [k for k, sn in enumerate(rec.insert) if sn.supported]
    assert len(ok) >= min_supported and all(sn.stable for sn in rec.insert)
    for key in figures:
        def value(r):
            return float((A @ r.von_mises).max()) if key == "stress" else getattr(r, key)

        fd = np.array([(value(p) - value(m)) / (2 * EPS) for p, m in zip(plus.steps, minus.steps)])[ok]
        an = np.array([float(np.sum(getattr(sn, key) * dX)) for sn in rec.insert])[ok]
        scale = np.abs(fd).max()
        assert scale > 0
        # relative to the figure's largest derivative over the run: steps out of contact have ~0 of both
        assert np.abs(an - fd).max() <= 1e-4 * scale, (key, an, fd)
    return base, rec


def test_snap_fit_2d(tight_newton):
    check(load_coupling_scene("block2d_tight", overrides={"simulation": {"steps": 12}}))


def test_rotating_path_2d(tight_newton, ellipse_in_clamp_model):
    # the insertion force (along O's translation) is zero during the pure rotation
    check(ellipse_in_clamp_model(steps=10), figures=("energy", "grip", "stress"))


def test_clip_3d(tight_newton):
    # all support dofs held: the clip's slide along the cylinder is then resisted (no pinned steps)
    cm = load_coupling_scene("clip3d", overrides={"simulation": {"steps": 8, "element_order": 1, "fix_all_axes": True},
                                                  "compliant": {"target_elements": 300, "layers": 1}})
    check(cm)
