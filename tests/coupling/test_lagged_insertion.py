"""An insertion whose solver lags its factorizations (simfab.solve.linear.LagConfig) gives the
figures of one that factorizes every Hessian, to Newton's force tolerance, with fewer factorizations."""

import functools

import pytest

from simfab.coupling import state
from simfab.coupling.outputs import summarize
from simfab.coupling.scene import load_coupling_scene
from simfab.coupling.simulate import simulate_insertion
from simfab.solve import linear


def _run(monkeypatch, solvers, lag):
    # the clip slides freely along the cylinder (the rigid-mode pin's Woodbury update is in every
    # solve); 18 steps of linear tets keep the test short
    monkeypatch.setattr(state, "LagConfig", (lambda: None) if lag is None else functools.partial(linear.LagConfig,
                                                                                                  **lag))
    solvers.clear()
    cm = load_coupling_scene("clip3d", overrides={"simulation": {"steps": 18, "element_order": 1},
                                                  "compliant": {"target_elements": 2000}})
    res = simulate_insertion(cm)
    _, summ = summarize(res)
    return summ, sum(s.factorizations for s in solvers), sum(s.lagged_solves for s in solvers)


def test_lagged_factorizations_give_the_same_figures(monkeypatch, spd_solvers):
    direct, n_direct, lagged_direct = _run(monkeypatch, spd_solvers, None)
    lagged, n_lagged, lagged_solves = _run(monkeypatch, spd_solvers, {"min_unknowns": 0})
    assert lagged_direct == 0 and lagged_solves > 0 and n_lagged < n_direct
    # the converged states differ within Newton's force tolerance, which the history of the pin's
    # anchors carries along (here up to 4e-5 of F_in); 2e-4 bounds that, a wrong solve would not be
    for key in ("F_in", "F_rm", "E_max"):
        assert lagged[key] == pytest.approx(direct[key], rel=2e-4), key


def test_a_quadratic_model_lags_at_every_size_and_keeps_its_figures_to_newtons_target(monkeypatch, spd_solvers):
    # P2 lags from 0 unknowns (state.P2_LAG_MIN_UNKNOWNS), every iterative solve stopping at Newton's
    # force target: its figures differ from a run that factorizes every Hessian by what that target
    # leaves (the force on O sums the residuals of its contact nodes), here bounded by 3 targets;
    # a solve that missed its target would not be
    from simfab.coupling import config as C

    cm = load_coupling_scene("clip3d", overrides={"simulation": {"steps": 12, "element_order": 2},
                                                  "compliant": {"target_elements": 300, "layers": 1}})
    target = C.NEWTON_GRAD_TOL_REL * cm.force_scale
    _, lagged = summarize(simulate_insertion(cm))
    n_lagged, fact_lagged = sum(s.lagged_solves for s in spd_solvers), sum(s.factorizations for s in spd_solvers)
    spd_solvers.clear()
    monkeypatch.setattr(state, "P2_LAG_MIN_UNKNOWNS", 10**9)
    _, direct = summarize(simulate_insertion(cm))
    assert sum(s.lagged_solves for s in spd_solvers) == 0 and n_lagged > 0
    assert fact_lagged < sum(s.factorizations for s in spd_solvers)
    for key in ("F_in", "F_rm", "F_grip"):
        assert abs(lagged[key] - direct[key]) <= 3 * target, key
    assert lagged["E_max"] == pytest.approx(direct["E_max"], rel=1e-4)
