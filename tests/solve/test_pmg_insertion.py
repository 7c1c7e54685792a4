"""An insertion whose solver solves by p-multigrid conjugate gradients (simfab.solve.pmg, forced at
every size) gives the figures of one that factorizes, to Newton's force tolerance."""

import functools

import pytest

from simfab.coupling import state
from simfab.coupling.outputs import summarize
from simfab.coupling.scene import load_coupling_scene
from simfab.coupling.simulate import simulate_insertion
from simfab.solve import pmg


def _run(monkeypatch, solvers, min_unknowns):
    # clip3d on P2 tets in one layer, 18 steps: the pin's rank-6 term is in every solve
    monkeypatch.setattr(state, "MultigridConfig", functools.partial(pmg.MultigridConfig, min_unknowns=min_unknowns))
    solvers.clear()
    cm = load_coupling_scene("clip3d", overrides={"simulation": {"steps": 18},
                                                  "compliant": {"target_elements": 600, "layers": 1}})
    res = simulate_insertion(cm)
    _, summ = summarize(res)
    mg = [s for s in solvers if isinstance(s, pmg.MultigridSolver)]
    return summ, sum(s.multigrid_solves for s in mg), sum(s.factorizations for s in mg)


def test_multigrid_solves_give_the_same_figures(monkeypatch, spd_solvers):
    direct, mg_direct, _ = _run(monkeypatch, spd_solvers, 10**9)
    forced, mg_solves, fine_factorizations = _run(monkeypatch, spd_solvers, 0)
    assert mg_direct == 0 and mg_solves > 0 and fine_factorizations < mg_solves
    # the solves stop at 0.1x Newton's force target (or 1e-6 relative): the converged states differ
    # within Newton's tolerance, carried along by the pin's anchors (docs/benchmarks.md 1b: up to
    # 2e-5 on F_in / F_rm at 1x); 2e-4 bounds that, a wrong solve would not be
    for key in ("F_in", "F_rm", "E_max"):
        assert forced[key] == pytest.approx(direct[key], rel=2e-4), key
