"""Shape derivatives of the linear Neo-Hookean energy (simfab.fem.shape_derivative) against central
finite differences of the Warp energy and gradient on perturbed rest shapes, 2D and 3D."""

import numpy as np
import pytest

from simfab.fem import elastic, shape_derivative
from simfab.fem.meshing import structured_box, triangulate_polygon
from simfab.fem.model import make_model


def _mesh(dim):
    if dim == 2:
        pts, tri = triangulate_polygon(np.array([[0, 0], [0.02, 0], [0.02, 0.01], [0, 0.01]]), max_area=2e-5)
        return np.asarray(pts, float), np.asarray(tri)
    pts, tet = structured_box([0.02, 0.01, 0.01], [2, 1, 1])
    return np.asarray(pts, float), np.asarray(tet)


@pytest.mark.parametrize("dim", [2, 3])
def test_rest_gradient_and_mixed_product_match_finite_differences(dim):
    X, el = _mesh(dim)
    rng = np.random.default_rng(dim)
    model = make_model(X, el, "PLA", thickness=0.005)
    h = model.mean_edge_length()
    x = X + 0.05 * h * rng.standard_normal(X.shape)  # a moderate, non-inverting deformation
    dX = h * rng.standard_normal(X.shape)
    w = rng.standard_normal(X.shape)
    eps = 1e-6

    def at(Xe):
        return make_model(Xe, el, "PLA", thickness=0.005)

    assert shape_derivative.energy(model, x) == pytest.approx(elastic.energy(model, x), rel=1e-12)
    # dE/dX . dX against (E(X + eps dX) - E(X - eps dX)) / 2 eps  (truncation O(eps^2))
    fd = (elastic.energy(at(X + eps * dX), x) - elastic.energy(at(X - eps * dX), x)) / (2 * eps)
    an = float(np.sum(shape_derivative.rest_gradient(model, x) * dX))
    assert an == pytest.approx(fd, rel=1e-6)
    # w . d2E/dx dX . dX against the directional difference of w . dE/dx
    gp = elastic.energy_gradient(at(X + eps * dX), x)[1]
    gm = elastic.energy_gradient(at(X - eps * dX), x)[1]
    fd2 = float(np.sum(w * (gp - gm))) / (2 * eps)
    an2 = float(np.sum(shape_derivative.mixed_product(model, x, w) * dX))
    assert an2 == pytest.approx(fd2, rel=1e-6)


@pytest.mark.parametrize("dim", [2, 3])
def test_von_mises_derivatives_match_finite_differences(dim):
    from simfab.fem.stress import det_and_von_mises

    X, el = _mesh(dim)
    rng = np.random.default_rng(10 + dim)
    model = make_model(X, el, "PLA", thickness=0.005)
    h = model.mean_edge_length()
    x = X + 0.05 * h * rng.standard_normal(X.shape)
    c = rng.uniform(0, 1, model.n_elements)
    dx, dX = h * rng.standard_normal(X.shape), h * rng.standard_normal(X.shape)
    eps = 1e-6
    assert np.allclose(shape_derivative.von_mises(model, x), det_and_von_mises(model, x)[1], rtol=1e-10)
    gx, gX = shape_derivative.von_mises_derivatives(model, x, c)

    def q(Xe, xe):
        return float(c @ det_and_von_mises(make_model(Xe, el, "PLA", thickness=0.005), xe)[1])

    fd_x = (q(X, x + eps * dx) - q(X, x - eps * dx)) / (2 * eps)
    fd_X = (q(X + eps * dX, x) - q(X - eps * dX, x)) / (2 * eps)
    assert float(np.sum(gx * dx)) == pytest.approx(fd_x, rel=1e-6)
    assert float(np.sum(gX * dX)) == pytest.approx(fd_X, rel=1e-6)
