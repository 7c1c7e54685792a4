"""Mesh check of an optimized shape on uniformly refined meshes (simfab.design.verify)."""


import numpy as np
import pytest

from simfab.design.brief import DesignConfig
from simfab.design.problem import make_problem, profile_figures
from simfab.design.verify import check_levels, check_warnings, mesh_check, refined_model
from simfab.results import to_json


@pytest.fixture(scope="module")
def problem():
    from simfab.coupling.scene import load_coupling_scene

    cm = load_coupling_scene("block2d_tight", overrides={"simulation": {"steps": 8}})
    return make_problem(cm, DesignConfig(grip="tight", grip_force=(3.0, 10.0), handles=3, placement="spatial"))


def test_refined_model_keeps_the_shape_support_and_options(problem):
    from simfab.coupling.simulate import simulate_insertion

    cm = problem.base
    same = refined_model(cm, cm.fem.rest, 0)
    a, b = profile_figures(simulate_insertion(cm)), profile_figures(simulate_insertion(same))
    assert a["insertion_force"] == b["insertion_force"] and a["von_mises"] == b["von_mises"]
    fine = refined_model(cm, cm.fem.rest, 1)
    assert fine.fem.n_elements == 4 * cm.fem.n_elements
    assert np.isclose(np.sum(fine.fem.volume), np.sum(cm.fem.volume), rtol=1e-12)  # the same domain
    assert set(cm.fixed_vertices.tolist()) <= set(fine.fixed_vertices.tolist())
    assert len(fine.fixed_vertices) > len(cm.fixed_vertices)  # the support's midpoints are held too
    assert np.array_equal(fine.s_steps, cm.s_steps)  # the same insertion
    # P2: the same mesh lifted to quadratic elements, whose edge nodes are the red refinement's
    # vertices: the same support, and the same nodes as the linear mesh refined once
    p2 = refined_model(cm, cm.fem.rest, 0, 2)
    assert p2.options.element_order == 2 and p2.fem.n_elements == cm.fem.n_elements
    assert np.array_equal(p2.fixed_vertices, fine.fixed_vertices)
    assert np.allclose(p2.fem.rest, fine.fem.rest, rtol=0, atol=1e-15)
    assert p2.h == cm.h and p2.dhat == cm.dhat  # h_A: the corner mesh's


def test_p2_level_matches_the_scene_loaded_with_quadratic_elements(problem):
    """refined_model(order 2) is what ``[simulation] element_order = 2`` runs, but for the support:
    the check holds a P2 edge node when both its corners are held (the linear mesh's support,
    refined), the scene every node inside the fixed box, which adds the midpoints of edges
    leaving the box. Measured: 0.1 % in F_in; the support's discretization, not the element's."""
    from simfab.coupling.scene import load_coupling_scene
    from simfab.coupling.simulate import simulate_insertion

    cm = problem.base
    mine = refined_model(cm, cm.fem.rest, 0, 2)
    scene = load_coupling_scene("block2d_tight", overrides={"simulation": {"steps": 8, "element_order": 2}})
    assert np.array_equal(mine.fem.rest, scene.fem.rest) and np.array_equal(mine.fem.elements, scene.fem.elements)
    extra = np.setdiff1d(scene.fixed_vertices, mine.fixed_vertices)
    assert np.all(np.isin(mine.fixed_vertices, scene.fixed_vertices)) and np.all(extra >= cm.fem.n_vertices)
    held = np.isin(mine.fem.edges[extra - cm.fem.n_vertices], cm.fixed_vertices)
    assert np.all(held.sum(axis=1) == 1)  # each extra node sits on an edge with one held corner
    a = profile_figures(simulate_insertion(mine))
    b = profile_figures(simulate_insertion(scene))
    for k in ("insertion_force", "removal_force", "grip_force", "von_mises"):
        assert np.isclose(a[k], b[k], rtol=5e-3), k


def test_linear_mesh_check_extrapolates_three_levels(problem):
    cm = problem.base
    r = mesh_check(problem, cm.fem.rest, levels=(0, 1, 2))
    n = cm.fem.n_elements
    assert [lv.elements for lv in r.levels] == [n, 4 * n, 16 * n]
    f = r.figures["insertion_force"]
    # linear triangles lock in bending: the coarse mesh is stiffer, forces fall with refinement
    assert f.values[0] > f.values[1] > f.values[2]
    assert f.converging and f.extrapolated < f.values[2]
    assert 0.05 < f.difference_of_optimization_mesh < 1.0
    fine = {c.name: c for c in r.constraints}
    for k in ("grip_force", "von_mises"):  # the constraints read the mesh-converged values
        g = r.figures[k]
        assert fine[k].value == (g.values[-1] if g.extrapolated is None else g.extrapolated)
    # the averaged stress converges (the raw element maximum need not: corner singularities)
    assert r.figures["von_mises"].converging
    assert r.feasible_fine == all(c.satisfied for c in r.constraints)
    w = check_warnings(r)
    assert bool(w) == (not r.feasible_fine)


def test_default_check_reads_p2_levels(problem):
    """Default: linear on the optimization mesh, then P2 on it and on its refinement (2D: 4x). The
    reference is P2 refined; P2 does not lock, so its own refinement changes the forces by far
    less than the linear mesh is off (measured here: linear +30 % in F_in, P2 1x -> 4x -0.8 %)."""
    from simfab.design.verify import check_levels, correction_factors, reference_value

    assert problem.brief.check_refinements == 1 and check_levels(1) == ((1, 0), (2, 0), (2, 1))
    cm = problem.base
    r = mesh_check(problem, cm.fem.rest)
    n = cm.fem.n_elements
    assert [(lv.element_order, lv.elements) for lv in r.levels] == [(1, n), (2, n), (2, 4 * n)]
    assert "P2" in r.reference
    for k in ("insertion_force", "removal_force"):
        f = r.figures[k]
        assert f.extrapolated is None and reference_value(f) == f.values[-1]  # two P2 levels: no fit
        assert 0.05 < f.difference_of_optimization_mesh < 1.0  # linear locks: too stiff
        assert abs(f.reference_change) < 0.25 * f.difference_of_optimization_mesh
        assert f.converging
    c = correction_factors(r)
    assert np.isclose(c["insertion_force"] * r.figures["insertion_force"].values[0],
                      r.figures["insertion_force"].values[-1])


def test_correction_factors_map_the_coarse_figures_to_the_reference(problem):
    from simfab.design.verify import correction_factors

    r = mesh_check(problem, problem.base.fem.rest, levels=(0, 1))
    c = correction_factors(r)
    from simfab.design.verify import FACTOR_RANGE, figure_unit

    for k, v in r.figures.items():
        coarse, fine = v.values[0], v.values[-1]
        if abs(coarse) < figure_unit(k):  # below its constraint unit: noise, left uncorrected
            assert c[k] == 1.0
        elif FACTOR_RANGE[0] <= fine / coarse <= FACTOR_RANGE[1]:
            assert np.isclose(coarse * c[k], fine)  # maps the coarse value onto the refined one
        else:
            assert c[k] in FACTOR_RANGE
    assert c["insertion_force"] < 1.0  # linear triangles: the coarse mesh is too stiff
    corrected = problem.with_settings(corrections=c)
    coarse = {k: v.values[0] for k, v in r.figures.items()}
    vals = {x.name: x.value for x in corrected.constraints(dict(coarse, seat_clearance=0.0))}
    assert np.isclose(vals["grip_force"], r.figures["grip_force"].values[-1])


def test_target_matching_gets_a_profile_correction():
    """A target-matching design: the mesh check reports the RMS error per level and the factor
    that maps the coarse force profile onto the finest level's (linear triangles: too stiff, < 1)."""
    from simfab.design.scene import load_design_scene
    from simfab.design.verify import correction_factors, needs_correction

    ds = load_design_scene("profile2d", design={"handles": 2, "placement": "spatial"}, simulation={"steps": 8})
    P = make_problem(ds.cm, ds.brief, kept_regions=ds.kept_regions, target=ds.target)
    r = mesh_check(P, ds.cm.fem.rest, levels=(0, 1))
    c = r.profile_force_factor
    assert 0.5 < c < 0.98
    assert len(r.figures["rms_error"].values) == 2
    assert correction_factors(r)["force_profile"] == c
    assert needs_correction(r, {}) and not needs_correction(r, {"force_profile": c})


def test_step_check_runs_where_the_steps_do_not_resolve_the_profile():
    """With 3 steps the block's snap falls between steps (its P2 run warns "steps too coarse"):
    the check runs that level again with 4x the steps, and each reference value is the finest
    level's times its step factor (finer steps / the scene's steps); the figures' own values per
    level stay those of the scene's steps."""
    from simfab.design import verify
    from simfab.design.scene import load_design_scene

    ds = load_design_scene("block2d_tight", design={"handles": 3, "placement": "spatial"}, simulation={"steps": 3})
    P = make_problem(ds.cm, ds.brief, kept_regions=ds.kept_regions)
    r = mesh_check(P, ds.cm.fem.rest, levels=(0, (2, 0)))
    st = r.step_check
    assert st.steps == 12 and st.factor == verify.STEP_CHECK_FACTOR
    moved = 0
    for k, fig in r.figures.items():
        c = st.factors.get(k, 1.0)
        assert (1.0 if fig.step_factor is None else fig.step_factor) == c
        assert np.isclose(verify.reference_value(fig), fig.values[-1] * c)
        moved += abs(c - 1.0) > 0.02
    assert moved >= 1  # the coarse steps did miss something
    vals = {c.name: c.value for c in r.constraints}
    assert np.isclose(vals["grip_force"], r.figures["grip_force"].values[-1] * st.factors["grip_force"])
    # 35 steps resolve the block's profile: no step check
    ds35 = load_design_scene("block2d_tight", design={"handles": 3, "placement": "spatial"})
    P35 = make_problem(ds35.cm, ds35.brief, kept_regions=ds35.kept_regions)
    r35 = mesh_check(P35, ds35.cm.fem.rest, levels=(0, (2, 0)))
    assert r35.step_check is None and "step_check" not in to_json(r35)  # (left out of the summary's JSON)
    assert "step_check" in to_json(r) and "step_factor" in to_json(r)["figures"]["grip_force"]


def test_profile_factor_leaves_out_the_search_for_the_rest_point():
    """The coarse profile is the fine one times 1.25 along the path; past the path's end the runs
    search for their rest points, and the seat (force jumping from +9 to -4 N) lies 1 um apart
    between the meshes: those records would pull the least-squares factor away from 0.8."""
    from simfab.design.verify import profile_factor

    s = np.linspace(0.0, 0.01, 21)
    f = 9.0 * np.sin(np.pi * s / 0.02)
    coarse = (np.append(s, [0.010500, 0.010501]), np.append(1.25 * f, [-4.0, -4.0]))
    fine = (np.append(s, [0.010500, 0.010502]), np.append(f, [9.0, -4.0]))
    assert np.isclose(profile_factor(coarse, fine, 0.01), 0.8)
    s0, f0 = coarse
    ref = np.interp(s0, *fine)
    assert abs(float(f0 @ ref / (f0 @ f0)) - 0.8) > 0.02  # with the seat's records: off


def test_a_p2_problem_designs_on_the_linear_mesh_and_its_check_starts_at_p2(problem):
    """A scene with P2 elements: the handles, E_L and the quality bound act on its linear mesh, every
    candidate is simulated on P2 (edge nodes at the midpoints of the moved linear mesh), and the mesh
    check's first level is the optimization mesh itself (P2 1x), then P2 refined; the linear
    problem's check leaves its model linear."""
    from simfab.coupling.scene import load_coupling_scene
    from simfab.design.problem import candidate_model, lift_rest

    p2 = load_coupling_scene("block2d_tight", overrides={"simulation": {"steps": 8, "element_order": 2}})
    P = make_problem(p2, problem.brief)
    assert P.mesh is p2.fem.linear and P.handles.rest.shape == (p2.fem.n_corners, 2)
    assert np.all(P.kept < p2.fem.n_corners)
    X = P.handles.apply(P.handles.identity() + 0.5 * P.sigma0)
    cm, why = candidate_model(P, X)
    assert not why and cm.fem.element_order == 2
    assert np.allclose(cm.fem.rest, lift_rest(p2.fem, X))
    assert check_levels(1, 2) == ((2, 0), (2, 1)) and check_levels(1) == ((1, 0), (2, 0), (2, 1))
    m = refined_model(p2, X, 1, 2)
    assert m.fem.n_elements == 4 * p2.fem.n_elements and m.options.element_order == 2
    lin = refined_model(problem.base, problem.base.fem.rest, 0, 2)
    assert lin.options.element_order == 2 and problem.base.options.element_order == 1
    assert type(problem.base.fem).__name__ == "FemModel"
