"""Coulomb friction in the insertion (simfab.coupling.friction): the inclined-face snap-fit against
its closed-form force ratios, self-locking reported as a jam, a block pressed and slid (|F_t| / N =
mu while slipping, no slip below the threshold), the energy balance over insertion and removal, and
the frictional objective's gradient against finite differences."""

import dataclasses

import numpy as np
import pytest

from simfab.contact.sdf import Primitive, build_primitive_field
from simfab.coupling import friction
from simfab.coupling.config import ContactConfig, InsertionConfig
from simfab.coupling.objective import StepObjective
from simfab.coupling.points import edge_weights, facet_points, vertex_points
from simfab.coupling.profile import analyze_run
from simfab.coupling.scene import load_coupling_scene
from simfab.coupling.settle import energy_balance
from simfab.coupling.simulate import TURN_STEPS, make_coupling_model, simulate_insertion
from simfab.coupling.timing import Timer
from simfab.fem.materials import PLA
from simfab.fem.meshing import triangulate_polygon
from simfab.fem.model import make_model
from simfab.io.mjcf import Trajectory
from simfab.verification.snapfit import GAP, contact_law, ratio_formula, snapfit_model


def _deflected(res):
    """Insertion path positions past the first fifth of the deflected travel (contact established)."""
    s = res.column("s")
    return s >= GAP + 0.2 * (s[-1] - GAP)


def _lateral(records) -> np.ndarray:
    """The lateral force on the beam [N]: the face's push across it (+x), which the support's reaction
    (the force of the beam on the box) balances."""
    return -np.array([r.reaction[0] for r in records])


@pytest.mark.parametrize("alpha, mu, dim", [(20, 0.5, 2), (30, 0.3, 2), (40, 0.5, 2), (30, 0.3, 3)])
def test_snapfit_forces_follow_the_wedge_formula(alpha, mu, dim):
    # The contact law: the force along the path over the lateral force on the beam is
    # (tan a + mu) / (1 - mu tan a) on insertion and (tan a - mu) / (1 + mu tan a) on removal, both
    # measured in the same run (lagged normal forces within lag_tol = 1 %): within 3 % and 5 %
    # (removal's ratio is small). The force ratios F(mu) / F(0) at the same lateral force follow
    # within 5 %; at the same position they differ by how much the larger axial tip load softens and
    # bends the beam (simfab.verification.snapfit), within 5 % where mu tan a <= 0.2.
    steps = 24 if dim == 2 else 12
    r0 = simulate_insertion(snapfit_model(alpha, 0.0, dim=dim, steps=steps))
    r1 = simulate_insertion(snapfit_model(alpha, mu, dim=dim, steps=steps))
    # the removal turns O around in TURN_STEPS graded steps, then runs back over the insertion's positions
    assert r0.removal == [] and r1.jammed_at is None and len(r1.removal) == len(r1.steps) - 1 + TURN_STEPS
    sel = _deflected(r0)
    P0, L0 = r0.column("path_force")[sel], _lateral(r0.steps)[sel]
    P1, L1 = r1.column("path_force")[sel], _lateral(r1.steps)[sel]
    assert np.all(P0 < 0) and np.all(L0 > 0)  # the beam resists the box; the face pushes the tip along +x
    # frictionless: tan(alpha) exactly in theory; the first records after first touch sit up to 2.1 %
    # above it (the barrier's standoff is a finite fraction of the tip's small deflection there)
    np.testing.assert_allclose(-P0 / L0, contact_law(alpha, 0.0, "insert"), rtol=0.025)
    np.testing.assert_allclose(-P1 / L1, contact_law(alpha, mu, "insert"), rtol=0.03)
    np.testing.assert_allclose((P1 / L1) / (P0 / L0), ratio_formula(alpha, mu, "insert"), rtol=0.05)
    s0 = np.round(r0.column("s")[sel], 12)
    rm = [r for r in r1.removal if round(r.s, 12) in set(s0)]
    assert len(rm) >= 0.7 * sel.sum()
    Pr, Lr = np.array([r.path_force for r in rm]), _lateral(rm)
    np.testing.assert_allclose(-Pr / Lr, contact_law(alpha, mu, "remove"), rtol=0.05)  # pushes the box back out
    if mu * np.tan(np.radians(alpha)) <= 0.2:
        np.testing.assert_allclose(P1 / P0, ratio_formula(alpha, mu, "insert"), rtol=0.05)
    prof = analyze_run(r1)
    assert prof.friction == mu and prof.F_in == pytest.approx(-r1.column("force").min())


def test_a_self_locking_snapfit_is_reported_as_jammed():
    # mu tan(alpha) = 0.5 tan 70 deg = 1.37 >= 1: the box is pushed inside the tip's friction cone,
    # the contact sticks and drags the beam tip along (a jam, not a solver failure); at 0.2 it slides
    jam = simulate_insertion(snapfit_model(70, 0.5, steps=24))
    assert jam.jammed_at is not None and analyze_run(jam).category == "jams"
    assert any("jams" in w for w in jam.warnings) and jam.removal == []
    ok = simulate_insertion(snapfit_model(70, 0.2, steps=24))
    assert ok.jammed_at is None and analyze_run(ok).category != "jams"


def test_energy_balance_over_insertion_and_removal():
    # work done on the part = change of stored energy + what friction dissipated, step by step
    # (trapezoidal normal force, the step's own friction force): within 1 % of the peak energy in total
    res = simulate_insertion(snapfit_model(30, 0.3, steps=48))
    bal = energy_balance(res.steps, res.removal)
    assert bal["dissipated_J"] > 0.5 * bal["E_max_J"]  # friction dissipates a real share of the work
    assert bal["total"] < 0.01 and bal["step"] < 0.01


def _block_and_plate(mu: float, slide: float, h_in: float = 20e-6):
    """A 10 x 4 mm PLA block fixed at its bottom, pressed 20 um by a wide rigid plate (from 50 um
    above) that then slides ``slide`` [m] along x, in steps of ``h_in`` [m]."""
    P, T = triangulate_polygon(np.array([[-5, 0], [5, 0], [5, 4], [-5, 4]]) * 1e-3, max_area=0.4e-6)
    fem = make_model(P, T, PLA, thickness=2e-3)
    plate = Primitive(kind="box", size=(20e-3, 2e-3, np.inf), centre=np.zeros(3), rotation=np.eye(3))
    field = build_primitive_field((plate,), 2)
    top = 4e-3 + 2e-3
    keys = np.array([[0.0, top + 0.05e-3, 0.0], [0.0, top - 0.02e-3, 0.0], [slide, top - 0.02e-3, 0.0]])
    path = Trajectory(keys, np.array([[1.0, 0, 0, 0]] * 3))
    opts = InsertionConfig(h_in=h_in, L_max=float(path.length), fix_all_axes=True)
    return make_coupling_model(name="block", fem=fem, field=field, path=path, options=opts,
                               fixed_vertices=np.flatnonzero(P[:, 1] < 1e-9), object_vertices=field.vertices,
                               contact=ContactConfig(friction=mu))


def test_a_sliding_block_feels_mu_times_the_normal_force():
    mu = 0.3
    res = simulate_insertion(_block_and_plate(mu, 1e-3, h_in=40e-6))
    sliding = [r for r in res.steps if r.pos[0] > 0.2e-3]  # past the shear ramp: the contact slips
    assert len(sliding) > 5 and all(r.slipping > 0.99 for r in sliding)
    lag_tol = res.model.contact.lag_tol  # the friction reads normal forces lagged to this tolerance
    for r in sliding:  # the path runs along x there: the path force is the tangential force on the plate
        assert abs(r.path_force) == pytest.approx(mu * r.normal_force, rel=lag_tol + 0.01)


def test_below_the_slip_threshold_the_contact_sticks():
    # a 10 um sideways move of the pressed plate needs a shear force below mu N: the block's top
    # moves with the plate (it shears; only the edges, where the pressure falls off, slip a little,
    # as in Cattaneo-Mindlin partial slip), and the friction force stays inside the cone
    mu = 0.3
    cm = _block_and_plate(mu, 10e-6, h_in=5e-6)
    res = simulate_insertion(cm)
    pressed = [r for r in res.steps if r.pos[0] < 1e-12][-1]
    moved = [r for r in res.steps if r.pos[0] >= 1e-12]
    assert len(moved) == 2 and all(abs(r.path_force) < mu * r.normal_force for r in moved)
    top = np.flatnonzero(np.abs(cm.fem.rest[:, 1] - 4e-3) < 1e-9)
    carried = (moved[-1].x[top, 0] - pressed.x[top, 0]) / (moved[-1].pos[0] - pressed.pos[0])
    assert np.median(carried) > 0.95 and carried.min() > 0.5


def test_frictional_objective_gradient_and_hessian_match_finite_differences(coarse_block_model):
    cm = coarse_block_model(refine=True)
    cm = dataclasses.replace(cm, contact=ContactConfig(friction=0.4, friction_eps_rel=1e-2))
    facets = np.asarray(cm.fem.boundary_facets)
    top = [i for i, f in enumerate(facets) if set(f.tolist()) == {2, 3}]
    pts = vertex_points(np.asarray(cm.fem.boundary_vertices), 2).concat(facet_points(facets, top, edge_weights(20)))
    R, _ = cm.pose(0.0)
    p = np.array([0.0, 3e-3 + 0.05 * cm.dhat, 0.0])
    x = cm.fem.rest.copy()
    y = pts.positions(x)
    fld = cm.field.evaluate(y, (R, p), hessian=False)
    # anchors 0.2 to 2.5 eps to the side: some points stick, others slip
    eps = cm.contact.friction_eps_rel * 2e-3
    anchors = y + np.array([eps, 0.0]) * np.resize([0.2, 0.6, 1.5, 2.5], len(y))[:, None]
    lag = friction.lag(cm, pts, anchors, anchors - y, -fld.psi, -fld.grad, cm.kappa)
    slip = np.linalg.norm(y[lag.rows] - anchors[lag.rows], axis=1) / lag.eps
    assert len(lag.rows) >= 4 and slip.min() < 1 < slip.max()
    obj = StepObjective(cm, pts, R, p, Timer(), friction=lag)
    f, g, H = obj(x.ravel(), True)
    H = H[0] if isinstance(H, tuple) else H  # the exact Hessian (the friction blocks are exact and PSD)
    free = np.flatnonzero(cm.free)
    rng = np.random.default_rng(0)
    h = 1e-10
    for _ in range(6):
        d = np.zeros(x.size)
        d[free] = rng.normal(size=free.size)
        fp, gp, _ = obj(x.ravel() + h * d, False)
        fm, gm, _ = obj(x.ravel() - h * d, False)
        assert (fp - fm) / (2 * h) == pytest.approx(g @ d, rel=1e-5)
        np.testing.assert_allclose(H @ d, (gp - gm) / (2 * h), rtol=1e-4, atol=1e-4 * np.abs(H @ d).max())


def test_friction_through_refinement_events():
    # the stand side refines facets during steps: the friction lag is rebuilt for the new points and
    # the normal-force extrapolation only reads normal forces over the same points
    res = simulate_insertion(load_coupling_scene("standside2d", overrides={"contact": {"friction": 0.3}}))
    assert res.refined_facets and res.jammed_at is None and res.removal
    assert res.removal[-1].s == 0.0 and res.removal[-1].normal_force == 0.0  # O back out of the part
    prof = analyze_run(res)
    assert prof.friction == 0.3 and prof.F_rm > 0
