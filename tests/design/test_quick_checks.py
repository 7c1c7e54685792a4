"""Quick mesh checks (``mesh_check(stop_missed=True)``, ``mesh_corrected(quick=True)``): a design
that misses its brief on the optimization mesh's P2 level is not run on the refined level; the kept
design always is."""

import pytest

from simfab.coupling.scene import load_coupling_scene
from simfab.design import gradient as G
from simfab.design.brief import DesignBrief
from simfab.design.pipeline import mesh_corrected
from simfab.design.problem import make_problem
from simfab.design.verify import mesh_check


@pytest.fixture(scope="module")
def cm():
    return load_coupling_scene("block2d_tight", overrides={"simulation": {"steps": 8}})


def test_a_check_stops_before_the_refined_level_only_when_the_brief_is_missed(cm):
    # the initial shape grips with ~12.6 N on P2 (both levels): a brief of 3..10 N is missed, 3..30 N met
    missed = make_problem(cm, DesignBrief(grip="tight", grip_force=(3.0, 10.0), handles=3, placement="spatial"))
    met = make_problem(cm, DesignBrief(grip="tight", grip_force=(3.0, 30.0), handles=3, placement="spatial"))
    quick = mesh_check(missed, missed.handles.rest, stop_missed=True)
    assert quick["stopped_before_refined"] and not quick["feasible_fine"]
    assert [(lv["element_order"], lv["subdivisions"]) for lv in quick["levels"]] == [(1, 0), (2, 0)]
    full = mesh_check(met, met.handles.rest, stop_missed=True)
    assert "stopped_before_refined" not in full and full["feasible_fine"]
    assert [(lv["element_order"], lv["subdivisions"]) for lv in full["levels"]] == [(1, 0), (2, 0), (2, 1)]
    # the same levels as far as both ran
    plain = mesh_check(missed, missed.handles.rest)
    for k, f in quick["figures"].items():
        assert f["values"] == plain["figures"][k]["values"][:2], k


def test_the_kept_design_gets_the_full_check(cm):
    # 8..10 N: the SQP's design grips within it on the linear mesh, below 8 N on P2: the first check
    # stops there, its round is aimed with P2's factors, and the round's design is checked in full
    P = make_problem(cm, DesignBrief(grip="tight", grip_force=(8.0, 10.0), handles=3, placement="spatial"))
    res = G.optimize_gradient(P, iterations=3, seed=0)
    _, check, rounds = mesh_corrected(res, 0, 1, True, quick=True)
    assert rounds and not rounds[0]["factors_refined"]
    assert "stopped_before_refined" not in check and check["feasible_fine"]
    assert (check["levels"][-1]["element_order"], check["levels"][-1]["subdivisions"]) == (2, 1)
