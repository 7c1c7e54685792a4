"""Shape derivatives of the Neo-Hookean energy (simfab.fem.shape_derivative) against central finite
differences of the Warp energy and gradient on perturbed rest shapes: linear and quadratic (P2)
elements, 2D and 3D. P2 models are rebuilt with ``to_p2`` from the perturbed linear mesh (straight
edges), so the derivatives are checked after ``linear_rest_derivative`` chains them to the corners."""

import numpy as np
import pytest

from simfab.design.stress import quadrature_von_mises
from simfab.fem import elastic, shape_derivative
from simfab.fem.meshing import structured_box, triangulate_polygon
from simfab.fem.model import make_model
from simfab.fem.p2 import to_p2
from simfab.fem.stress import det_and_von_mises

EPS = 1e-6  # central differences: truncation O(eps^2) ~ 1e-12 relative, round-off ~1e-16 / eps ~ 1e-10
CASES = [(2, 1), (3, 1), (2, 2), (3, 2)]


def _mesh(dim):
    if dim == 2:
        pts, tri = triangulate_polygon(np.array([[0, 0], [0.02, 0], [0.02, 0.01], [0, 0.01]]), max_area=2e-5)
        return np.asarray(pts, float), np.asarray(tri)
    pts, tet = structured_box([0.02, 0.01, 0.01], [2, 1, 1])
    return np.asarray(pts, float), np.asarray(tet)


def _builder(el, order):
    def at(X):
        model = make_model(X, el, "PLA", thickness=0.005)
        return model if order == 1 else to_p2(model)
    return at


def _corners(model, g):
    return shape_derivative.linear_rest_derivative(model, g)


@pytest.mark.parametrize(("dim", "order"), CASES)
def test_rest_gradient_and_mixed_product_match_finite_differences(dim, order):
    X, el = _mesh(dim)
    at = _builder(el, order)
    rng = np.random.default_rng(dim + 10 * order)
    model = at(X)
    h = model.mean_edge_length()
    x = model.rest + 0.05 * h * rng.standard_normal(model.rest.shape)  # a moderate, non-inverting deformation
    dX = h * rng.standard_normal(X.shape)
    w = rng.standard_normal(x.shape)

    assert shape_derivative.quadrature_energy(model, x) == pytest.approx(elastic.energy(model, x), rel=1e-12)
    # dE/dX . dX against (E(X + eps dX) - E(X - eps dX)) / 2 eps
    fd = (elastic.energy(at(X + EPS * dX), x) - elastic.energy(at(X - EPS * dX), x)) / (2 * EPS)
    an = float(np.sum(_corners(model, shape_derivative.rest_gradient(model, x)) * dX))
    assert an == pytest.approx(fd, rel=1e-6)
    # w . d2E/dx dX . dX against the directional difference of w . dE/dx
    gp = elastic.energy_gradient(at(X + EPS * dX), x)[1]
    gm = elastic.energy_gradient(at(X - EPS * dX), x)[1]
    fd2 = float(np.sum(w * (gp - gm))) / (2 * EPS)
    mixed = shape_derivative.mixed_product(model, x, np.stack([w, -2.0 * w]))  # a stack of directions
    assert float(np.sum(_corners(model, mixed[0]) * dX)) == pytest.approx(fd2, rel=1e-6)
    assert np.allclose(mixed[1], -2.0 * mixed[0], rtol=1e-12, atol=0)


@pytest.mark.parametrize(("dim", "order"), CASES)
def test_von_mises_derivatives_match_finite_differences(dim, order):
    X, el = _mesh(dim)
    at = _builder(el, order)
    rng = np.random.default_rng(20 + dim + 10 * order)
    model = at(X)
    h = model.mean_edge_length()
    x = model.rest + 0.05 * h * rng.standard_normal(model.rest.shape)

    def stresses(m, xe):  # the public per-point stresses: P1 per element, P2 at the quadrature points
        return det_and_von_mises(m, xe)[1] if order == 1 else quadrature_von_mises(m, xe).ravel()

    assert np.allclose(shape_derivative.point_von_mises(model, x), stresses(model, x), rtol=1e-10)
    c = rng.uniform(0, 1, stresses(model, x).size)
    dx, dX = h * rng.standard_normal(x.shape), h * rng.standard_normal(X.shape)
    gx, gX = shape_derivative.von_mises_derivatives(model, x, c)

    def q(Xe, xe):
        return float(c @ stresses(at(Xe), xe))

    fd_x = (q(X, x + EPS * dx) - q(X, x - EPS * dx)) / (2 * EPS)
    fd_X = (q(X + EPS * dX, x) - q(X - EPS * dX, x)) / (2 * EPS)
    assert float(np.sum(gx * dx)) == pytest.approx(fd_x, rel=1e-6)
    assert float(np.sum(_corners(model, gX) * dX)) == pytest.approx(fd_X, rel=1e-6)


def test_linear_rest_derivative_is_the_midpoint_chain():
    # d/dX_c of sum_i g_i . X_i with X_mid = (X_a + X_b) / 2: the adjoint of lifting corner moves
    X, el = _mesh(2)
    model = to_p2(make_model(X, el, "PLA", thickness=0.005))
    rng = np.random.default_rng(3)
    g, dXc = rng.standard_normal(model.rest.shape), rng.standard_normal(X.shape)
    lifted = model.lift(X + dXc) - model.lift(X)
    assert float(np.sum(shape_derivative.linear_rest_derivative(model, g) * dXc)) == pytest.approx(
        float(np.sum(g * lifted)), rel=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_mean_edge_length_gradient_matches_finite_differences(dim):
    # the barrier's d_hat is dhat_rel times this length: the design's clearance gradient carries it
    from simfab.fem.model import mean_edge_length_gradient

    X, el = _mesh(dim)
    X = X + np.random.default_rng(dim).uniform(-1e-4, 1e-4, X.shape)  # no edge of a regular grid is special
    g = mean_edge_length_gradient(X, el)
    V = np.random.default_rng(7).standard_normal(X.shape)
    eps = 1e-8  # moves of 1e-8 m against edges of ~1e-3 m: truncation ~1e-10, round-off ~1e-9 relative
    fd = (make_model(X + eps * V, el, "PLA", thickness=0.005).mean_edge_length()
          - make_model(X - eps * V, el, "PLA", thickness=0.005).mean_edge_length()) / (2 * eps)
    assert float(np.sum(g * V)) == pytest.approx(fd, rel=1e-6)  # a wrong sign or count is off by O(1)
