"""An insertion whose solver solves by p-multigrid conjugate gradients (simfab.solve.pmg, forced at
every size) gives the figures of one that factorizes, to Newton's force tolerance."""

import functools

import pytest

from simfab.coupling import config as C
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
    target = C.NEWTON_GRAD_TOL_REL * cm.force_scale  # Newton's force target [N]
    return summ, sum(s.multigrid_solves for s in mg), sum(s.factorizations for s in mg), target


def test_multigrid_solves_give_the_same_figures(monkeypatch, spd_solvers):
    direct, mg_direct, _, target = _run(monkeypatch, spd_solvers, 10**9)
    forced, mg_solves, fine_factorizations, _ = _run(monkeypatch, spd_solvers, 0)
    assert mg_direct == 0 and mg_solves > 0 and fine_factorizations < mg_solves
    # the solves stop at 0.1x Newton's force target (or 1e-6 relative): the converged states differ
    # within Newton's tolerance, carried along by the pin's anchors. The path forces then differ by a
    # fraction of Newton's force target (0.08 N here; measured 0.002-0.018 N on F_in, 2e-4 N on F_rm),
    # the energy far less (4e-8 relative); a wrong solve would be off by many targets
    for key in ("F_in", "F_rm"):
        assert forced[key] == pytest.approx(direct[key], abs=0.5 * target), key
    assert forced["E_max"] == pytest.approx(direct["E_max"], rel=1e-6)
