"""simulate_insertion(refined=...): starting with the facets a similar run refined (what the rest-shape
optimizer does for every candidate) gives the same profile with fewer Newton iterations."""

import numpy as np
import pytest

from simfab.coupling.simulate import simulate_insertion
from simfab.design.problem import profile_figures
from simfab.design.scene import load_design_scene


def test_seeded_refinement_keeps_the_profile_and_saves_the_second_solves():
    cm = load_design_scene("standside2d").cm
    plain = simulate_insertion(cm)
    assert 0 < len(plain.refined_facets) < len(cm.fem.boundary_facets)
    seeded = simulate_insertion(cm, refined=plain.refined_facets)
    assert set(plain.refined_facets) <= set(seeded.refined_facets)
    it0 = sum(s.iterations for s in plain.steps)
    it1 = sum(s.iterations for s in seeded.steps)
    assert it1 < 0.9 * it0  # the steps where facets were refined are not solved twice
    # the same physics: the points exist from the start instead of from the step that found them
    # crossing, so facets whose interior would dip into O by less than the penetration tolerance
    # (1e-3 h) are held out of it too. The figures agree to that contact discretization: measured
    # E_max, E_ss, F_rm, F_grip within 0.1 %, F_in (a near-jam force) within 1.2 %
    f0, f1 = profile_figures(plain), profile_figures(seeded)
    for k, rel in (("E_max", 2e-3), ("E_ss", 2e-3), ("removal_force", 5e-3), ("grip_force", 5e-3),
                   ("insertion_force", 2e-2)):
        assert f1[k] == pytest.approx(f0[k], rel=rel), k
    assert np.allclose(seeded.column("energy"), plain.column("energy"), rtol=1e-2, atol=1e-3 * f0["E_max"])


def test_seeded_refinement_rejects_facet_ids_outside_the_boundary():
    cm = load_design_scene("standside2d").cm
    with pytest.raises(ValueError, match="facet ids"):
        simulate_insertion(cm, refined=[len(cm.fem.boundary_facets)])
