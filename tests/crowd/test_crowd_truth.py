"""Support volume and overhang area against closed forms and the ray-cast estimate."""

import numpy as np
import pytest
import trimesh

from simfab.crowd import truth as T
from simfab.errors import InputError


def _diamond_prism(a=0.02, length=0.05):
    """Square a x a cross-section standing on an edge (45 deg about x): the two lower faces
    (width a, length L, |n_z| = 1/sqrt(2)) overhang. V = L * (area under the V between the
    faces and the plate) = L * (a/sqrt2)^2 = L a^2 / 2; overhang area = 2 a L."""
    box = trimesh.creation.box((length, a, a))
    verts = T.oriented(box.vertices, T.Orientation(name="d", euler_deg=(45.0, 0.0, 0.0)))
    return verts, box.faces, length * a * a / 2, 2 * a * length


def _t_shape(w=0.06, t=0.01, h=0.04, s=0.012, depth=0.03):
    """Extruded T: stem s wide, h tall, on the plate; crossbar w wide, t thick on top. The
    crossbar's underside left and right of the stem ((w - s) wide, depth deep) overhangs at
    height h: V = (w - s) * depth * h, overhang area = (w - s) * depth."""
    stem = trimesh.creation.box((s, depth, h))
    stem.apply_translation((0, 0, h / 2))
    bar = trimesh.creation.box((w, depth, t))
    bar.apply_translation((0, 0, h + t / 2))
    m = trimesh.boolean.union([stem, bar], engine="manifold")
    return m.vertices, m.faces, (w - s) * depth * h, (w - s) * depth


def test_box_on_its_face_needs_no_support():
    box = trimesh.creation.box((0.03, 0.02, 0.01))
    for o in T.parse_orientations(["six"]):
        m = T.support_metrics(T.oriented(box.vertices, o), box.faces)
        assert m["support_volume"] == 0.0 and m["overhang_area"] == 0.0


@pytest.mark.parametrize(
    "shape,rel",
    [
        (_diamond_prism, 1e-12),
        (_t_shape, 1e-6),  # exact up to the boolean's float32 vertex rounding (relative 1e-7)
    ],
)
def test_closed_form_and_raycast(shape, rel):
    v, f, vol, area = shape()
    m = T.support_metrics(v, f)
    assert m["support_volume"] == pytest.approx(vol, rel=rel)
    assert m["overhang_area"] == pytest.approx(area, rel=rel)
    assert T.raycast_support_volume(v, f) == pytest.approx(vol, rel=0.01)


def test_t_shape_upside_down_needs_no_support():
    # 180 deg about x: the crossbar lies on the plate and the stem's end faces up, nothing
    # overhangs
    v, f, _, _ = _t_shape()
    vu = T.oriented(v, T.Orientation(name="u", euler_deg=(180.0, 0.0, 0.0)))
    assert T.support_metrics(vu, f)["support_volume"] == pytest.approx(0.0, abs=1e-15)


def test_sphere_matches_closed_form_within_discretization():
    # sphere radius r resting on the plate: V = int (r - sqrt(r^2 - rho^2)) 2 pi rho drho = pi r^3 / 3
    # an icosphere (5 subdivisions, 10242 vertices) deviates from the sphere by < 0.05 %
    r = 0.01
    s = trimesh.creation.icosphere(subdivisions=5, radius=r)
    m = T.support_metrics(s.vertices, s.faces)
    assert m["support_volume"] == pytest.approx(np.pi * r**3 / 3, rel=5e-4)
    # lower hemisphere 2 pi r^2; the facets straddling the equator count by their normal's
    # sign, which costs the polyhedron ~1 % of the band's area
    assert m["overhang_area"] == pytest.approx(2 * np.pi * r**2, rel=0.01)
    assert T.raycast_support_volume(s.vertices, s.faces) == pytest.approx(m["support_volume"], rel=0.01)


def test_scaling_to_survey_scale():
    np.testing.assert_allclose(T.scale_to_survey([0.0, 5.0, 10.0]), [1.0, 5.5, 10.0])
    np.testing.assert_allclose(T.scale_to_survey([0.0, 5.0, 10.0], higher_is_more=False), [10.0, 5.5, 1.0])
    np.testing.assert_allclose(T.scale_to_survey([2.0, 2.0], lo=1, hi=5), [3.0, 3.0])


def test_orientation_table_scores():
    v, f, _, _ = _t_shape()
    rows = T.orientation_table(v, f, T.parse_orientations(["up=0:0:0", "down=180:0:0", "side=0:90:0"]), raycast=False)
    by = {r["orientation"]: r for r in rows}
    assert by["up"]["support_score"] == 10.0 and by["down"]["support_score"] == 1.0
    assert by["down"]["finish_score"] == 10.0


@pytest.mark.parametrize("spec", [["sideways"], ["a=1:2"], ["a=1:2:x"], ["a=0:0:0", "a=90:0:0"], []])
def test_bad_orientations(spec):
    with pytest.raises(InputError):
        T.parse_orientations(spec)


def test_bundled_survey_truth_matches_its_mesh():
    from simfab.crowd.data import Scale, load_ratings, load_truth
    from simfab.crowd.survey import load_survey, survey_truth

    spec = load_survey()
    rows = survey_truth(spec, raycast=False)
    r = load_ratings(spec.root / spec.crowds[0].file, Scale(lo=1, hi=10))
    truth = load_truth(spec.root / spec.truth_file, r)
    scores = {x["orientation"]: x["support_score"] for x in rows}
    np.testing.assert_allclose(truth, [scores[t] for t in r.tasks], rtol=1e-9)
    assert len(spec.crowds[0].mix.__dict__) and len(r.workers) == 15
    assert len(load_ratings(spec.root / spec.crowds[1].file, Scale(lo=1, hi=10)).workers) == 100
