"""Two-grid warm start (simfab.coupling.guide): a coarse P2 run guides the refined P2 level of the
mesh check; the records stay the refined level's own equilibria."""

import numpy as np
import pytest

from simfab.coupling import config as C
from simfab.coupling.guide import CoarseGuide
from simfab.coupling.record import StepResult
from simfab.coupling.scene import load_coupling_scene
from simfab.coupling.settle import REST_ENERGY_REL
from simfab.design.brief import DesignConfig
from simfab.design.problem import make_problem
from simfab.design.verify import FIGURES, mesh_check, p2_prolongation, refined_model


def quadratic(X):
    """A quadratic field (n, dim) of the positions X: what P2 interpolates exactly."""
    cols = [X[:, 0] ** 2 + X[:, 1] * X[:, -1], X[:, 1] ** 2 - 3.0 * X[:, 0] + 0.5]
    if X.shape[1] == 3:
        cols.append(X[:, 2] * X[:, 0] - X[:, 2] ** 2)
    return np.stack(cols, axis=1)


@pytest.mark.parametrize("scene, overrides", [
    ("block2d_tight", {}),
    ("clip3d", {"compliant": {"target_elements": 300, "layers": 1}}),
])
def test_p2_prolongation_interpolates_a_quadratic_field_exactly(scene, overrides):
    cm = load_coupling_scene(scene, overrides={"simulation": {"element_order": 1}, **overrides})
    coarse = refined_model(cm, cm.fem.rest, 0, 2).fem
    fine = refined_model(cm, cm.fem.rest, 1, 2).fem
    P = p2_prolongation(coarse, fine)
    assert P.shape == (len(fine.rest), len(coarse.rest))
    scale = np.abs(quadratic(fine.rest)).max()
    assert np.abs(P @ quadratic(coarse.rest) - quadratic(fine.rest)).max() <= 1e-12 * scale
    assert np.allclose(P @ np.ones(len(coarse.rest)), 1.0, rtol=0, atol=1e-12)  # a partition of unity
    with pytest.raises(ValueError):  # not coarse subdivided once
        p2_prolongation(fine, coarse)


def record(s, x, energy):
    z = np.zeros(3)
    return StepResult(s=s, pos=z, quat=np.array([1.0, 0, 0, 0]), x=np.asarray(x, float), energy=energy, force=0.0,
                      path_force=0.0, barrier_energy=0.0, grip=0.0, max_von_mises=0.0, von_mises=np.zeros(1),
                      penetration=0.0, min_det_F=1.0, iterations=1, contact_points=0, kappa=1.0)


def test_guide_offers_candidates_only_while_the_coarse_run_loads():
    # three coarse records on one node: loading from s = 0 to 1, a release (a snap) from 1 to 2
    recs = [record(0.0, [[0.0]], 0.0), record(1.0, [[1.0]], 2.0), record(2.0, [[5.0]], 1.0)]
    g = CoarseGuide.from_records(recs[::-1], np.array([[1.0], [0.5]]))  # two fine nodes; records in any order
    assert np.array_equal(g.s, [0.0, 1.0, 2.0])
    coarse, incr = g.candidates(np.array([[0.1], [0.2]]), 0.25, 0.75)
    assert np.allclose(coarse, [[0.75], [0.375]])  # P x_c(0.75)
    assert np.allclose(incr, [[0.1 + 0.5], [0.2 + 0.25]])  # x_f + P (x_c(0.75) - x_c(0.25))
    assert g.candidates(np.zeros((2, 1)), 0.5, 1.5) == []  # the coarse energy falls inside the step
    assert g.candidates(np.zeros((2, 1)), 1.5, 2.5) == []  # past the coarse run's range
    assert g.candidates(np.zeros((2, 1)), 0.75, 0.25) == []  # backwards


@pytest.fixture(scope="module")
def problem():
    # 4 steps: too coarse for the snap, so the check runs its step check too
    cm = load_coupling_scene("block2d_tight", overrides={"simulation": {"steps": 4}})
    return make_problem(cm, DesignConfig(grip="tight", grip_force=(3.0, 10.0), handles=3, placement="spatial"))


def checks(problem):
    return [mesh_check(problem, problem.handles.rest, two_grid=g) for g in (False, True)]


def test_two_grid_start_saves_newton_iterations(problem):
    plain, guided = checks(problem)
    p, g = plain.levels[-1], guided.levels[-1]
    assert (p.element_order, p.subdivisions) == (2, 1)
    assert p.guided_steps == 0 and g.guided_steps >= 2
    assert g.newton_iterations < p.newton_iterations
    assert plain.levels[1].newton_iterations == guided.levels[1].newton_iterations  # P2 1x: unguided
    # the step check (P2 1x at 4x the steps) is guided by P2 1x at the scene's steps
    ps, gs = plain.step_check, guided.step_check
    assert ps.guided_steps == 0 and gs.guided_steps >= 2
    assert gs.newton_iterations <= ps.newton_iterations


def test_two_grid_start_keeps_the_checks_figures(problem, monkeypatch):
    # with Newton solved 1e-4 times tighter both runs reach the same equilibria: the start decides
    # how many iterations, not where they end (at the default tolerance the figures differ by what
    # that tolerance leaves, which depends on the start's residual: the averaged stress by 3e-4)
    monkeypatch.setattr(C, "NEWTON_GRAD_TOL_REL", 1e-10)
    monkeypatch.setattr(C, "NEWTON_GRAD_TOL_START", 1e-10)
    monkeypatch.setattr(C, "NEWTON_STEP_TOL_REL", 1e-12)
    # The seat's figures are the rest search's: it stops once the energy between its bracket's ends is
    # known to REST_ENERGY_REL of E_max, so where the two runs' first trial past the seat (a step deep
    # into it, from different starts) ends on different sides, their rest points differ within that:
    # E_ss within REST_ENERGY_REL E_max, the coupling ratio 100 E_ss / E_max within REST_ENERGY_REL
    # relative to it times E_max / E_ss (measured on the finest level: coupling ratio 1.3e-3, grip 2e-4)
    plain, guided = checks(problem)
    rel_seat = REST_ENERGY_REL * 100.0 / min(plain.figures["coupling_ratio"].values)  # (1.2e-2 here)
    seat = {"coupling_ratio": rel_seat, "grip_force": rel_seat}
    assert guided.levels[-1].guided_steps >= 2 and guided.step_check.guided_steps >= 2
    for k in FIGURES:
        a, b = plain.figures[k], guided.figures[k]
        assert b.values == pytest.approx(a.values, rel=seat.get(k, 1e-6), abs=1e-9), k
        assert b.step_factor == pytest.approx(a.step_factor, rel=2 * seat.get(k, 1e-6)), k
    assert plain.feasible_fine == guided.feasible_fine
