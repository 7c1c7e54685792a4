"""Laplacian editing energy of the boundary (simfab.design.modification)."""

import numpy as np

from simfab.design.modification import ModificationEnergy
from simfab.fem.meshing import triangulate_polygon


def _disk(n=48):
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    V, F = triangulate_polygon(np.c_[np.cos(a), np.sin(a)] * 0.01, max_area=2e-6)
    from simfab.fem.model import make_model

    return make_model(V, F, "PLA", thickness=0.005)


def test_zero_for_rigid_translation_positive_for_shape_change():
    fem = _disk()
    E = ModificationEnergy(fem.rest, fem.boundary_facets)
    X = np.asarray(fem.rest)
    assert E(X) == 0.0
    assert E(X + [0.003, -0.002]) < 1e-20  # translation of the whole boundary: round-off only
    bump = X.copy()
    b = E.vertices
    bump[b[:5]] += [0.0, 0.0005]  # a local bump of half an edge length
    assert E(bump) > 0.1
    assert E(X * 1.05) > 0.0  # scaling changes the curved boundary's Laplacian coordinates


def test_energy_is_the_quadratic_form_and_size_independent():
    fem = _disk()
    E = ModificationEnergy(fem.rest, fem.boundary_facets)
    rng = np.random.default_rng(0)
    X = np.asarray(fem.rest) + rng.normal(scale=1e-4, size=fem.rest.shape)
    v = (X - fem.rest)[E.vertices]
    assert np.isclose(E(X), float(np.sum(v * (E.M @ v))), rtol=1e-12)
    # dimensionless: the same relative edit of a 10x larger part costs the same
    E10 = ModificationEnergy(np.asarray(fem.rest) * 10, fem.boundary_facets)
    assert np.isclose(E10(X * 10), E(X), rtol=1e-10)
