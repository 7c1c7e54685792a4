"""Mesh check of an optimized shape on uniformly refined meshes (simfab.design.verify)."""

import numpy as np
import pytest

from simfab.design.brief import DesignBrief
from simfab.design.optimize import make_problem, profile_figures
from simfab.design.verify import check_warnings, mesh_check, refined_model


@pytest.fixture(scope="module")
def problem():
    from simfab.coupling.scene import load_coupling_scene

    cm = load_coupling_scene("block2d_tight", overrides={"simulation": {"steps": 8}})
    return make_problem(cm, DesignBrief(grip="tight", grip_force=(3.0, 10.0), handles=3, placement="spatial"))


def test_refined_model_keeps_the_shape_support_and_options(problem):
    from simfab.coupling.simulate import simulate

    cm = problem.base
    same = refined_model(cm, cm.fem.rest, 0)
    a, b = profile_figures(simulate(cm)), profile_figures(simulate(same))
    assert a["insertion_force"] == b["insertion_force"] and a["von_mises"] == b["von_mises"]
    fine = refined_model(cm, cm.fem.rest, 1)
    assert fine.fem.n_elements == 4 * cm.fem.n_elements
    assert np.isclose(np.sum(fine.fem.volume), np.sum(cm.fem.volume), rtol=1e-12)  # the same domain
    assert set(cm.fixed_vertices.tolist()) <= set(fine.fixed_vertices.tolist())
    assert len(fine.fixed_vertices) > len(cm.fixed_vertices)  # the support's midpoints are held too
    assert np.array_equal(fine.s_steps, cm.s_steps)  # the same insertion


def test_mesh_check_reports_the_coarse_mesh_error(problem):
    cm = problem.base
    r = mesh_check(problem, cm.fem.rest)
    n = cm.fem.n_elements
    assert [lv["elements"] for lv in r["levels"]] == [n, 4 * n, 16 * n]
    f = r["figures"]["insertion_force"]
    # linear triangles lock in bending: the coarse mesh is stiffer, forces fall with refinement
    assert f["values"][0] > f["values"][1] > f["values"][2]
    assert f["converging"] and f["extrapolated"] < f["values"][2]
    assert 0.05 < f["difference_of_optimization_mesh"] < 1.0
    fine = {c["name"]: c for c in r["constraints"]}
    assert fine["grip_force"]["value"] == r["figures"]["grip_force"]["values"][-1]
    assert r["feasible_fine"] == all(c["satisfied"] for c in r["constraints"])
    w = check_warnings(r)
    assert bool(w) == (not r["feasible_fine"])
