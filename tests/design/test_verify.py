"""Mesh check of an optimized shape on uniformly refined meshes (simfab.design.verify)."""

import dataclasses

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
    for k in ("grip_force", "von_mises"):  # the constraints read the mesh-converged values
        g = r["figures"][k]
        assert fine[k]["value"] == (g["values"][-1] if g["extrapolated"] is None else g["extrapolated"])
    # the averaged stress converges (the raw element maximum need not: corner singularities)
    assert r["figures"]["von_mises"]["converging"]
    assert r["feasible_fine"] == all(c["satisfied"] for c in r["constraints"])
    w = check_warnings(r)
    assert bool(w) == (not r["feasible_fine"])


def test_correction_factors_map_the_coarse_figures_to_the_reference(problem):
    from simfab.design.verify import correction_factors

    r = mesh_check(problem, problem.base.fem.rest, levels=(0, 1))
    c = correction_factors(r)
    from simfab.design.verify import FACTOR_RANGE, figure_unit

    for k, v in r["figures"].items():
        coarse, fine = v["values"][0], v["values"][-1]
        if abs(coarse) < figure_unit(k):  # below its constraint unit: noise, left uncorrected
            assert c[k] == 1.0
        elif FACTOR_RANGE[0] <= fine / coarse <= FACTOR_RANGE[1]:
            assert np.isclose(coarse * c[k], fine)  # maps the coarse value onto the refined one
        else:
            assert c[k] in FACTOR_RANGE
    assert c["insertion_force"] < 1.0  # linear triangles: the coarse mesh is too stiff
    corrected = dataclasses.replace(problem, corrections=c)
    coarse = {k: v["values"][0] for k, v in r["figures"].items()}
    vals = {x.name: x.value for x in corrected.constraints(dict(coarse, seat_clearance=0.0))}
    assert np.isclose(vals["grip_force"], r["figures"]["grip_force"]["values"][-1])


def test_target_matching_gets_a_profile_correction():
    """A target-matching design: the mesh check reports the RMS error per level and the factor
    that maps the coarse force profile onto the finest level's (linear triangles: too stiff, < 1)."""
    from simfab.design.scene import load_design_scene
    from simfab.design.verify import correction_factors, needs_correction

    ds = load_design_scene("profile2d", design={"handles": 2, "placement": "spatial"}, simulation={"steps": 8})
    P = make_problem(ds.cm, ds.brief, kept_regions=ds.kept_regions, target=ds.target)
    r = mesh_check(P, ds.cm.fem.rest, levels=(0, 1))
    c = r["profile_force_factor"]
    assert 0.5 < c < 0.98
    assert len(r["figures"]["rms_error"]["values"]) == 2
    assert correction_factors(r)["force_profile"] == c
    assert needs_correction(r, {}) and not needs_correction(r, {"force_profile": c})
