"""Averaged von Mises stress on quadratic elements at quadrature-point resolution (simfab.design.stress)."""

import numpy as np
import pytest

from simfab.design.stress import averaged_von_mises, p2_averaged_von_mises, quadrature_von_mises

MU, LAM = 1.0e9, 2.0e9
EPS0, K = 0.01, 0.8  # axial strain [-] and curvature [1/m] of the bending field below


def _plate(n):
    """P2 model of the plane-strain rectangle [0, 0.04] x [0, 0.01] m, n x n/4 cells, 2 triangles each."""
    from simfab.fem.materials import Material
    from simfab.fem.p2 import make_p2_model

    nx, ny = n, max(n // 4, 1)
    xs, ys = np.linspace(0, 0.04, nx + 1), np.linspace(0, 0.01, ny + 1)
    X = np.array([[x, y] for y in ys for x in xs])
    idx = lambda i, j: j * (nx + 1) + i  # noqa: E731
    tris = []
    for j in range(ny):
        for i in range(nx):
            a, b, c, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
            tris += [[a, b, c], [a, c, d]]
    E = MU * (3 * LAM + 2 * MU) / (LAM + MU)
    nu = LAM / (2 * (LAM + MU))
    mat = Material(name="t", youngs_modulus=E, poisson_ratio=nu, yield_stress=50e6, density=1000.0)
    return make_p2_model(X, np.array(tris), mat)


def _bending(X):
    """Deformed positions of the quadratic field u = (EPS0 x + K x y, -K x^2 / 2) (P2 holds it exactly)."""
    x, y = X[:, 0], X[:, 1]
    return X + np.c_[EPS0 * x + K * x * y, -0.5 * K * x * x]


def _exact_vm(X):
    """sigma_vm = sqrt(3/2) mu |dev(F F^T - I)| / J at rest points X (k, 2), plane strain (C_zz = 0)."""
    x, y = X[:, 0], X[:, 1]
    F = np.zeros((len(X), 2, 2))
    F[:, 0, 0], F[:, 0, 1] = 1 + EPS0 + K * y, K * x
    F[:, 1, 0], F[:, 1, 1] = -K * x, 1.0
    C = F @ np.swapaxes(F, 1, 2) - np.eye(2)
    tr = np.einsum("kii->k", C)
    dev = np.sqrt(1.5 * (np.einsum("kij,kij->k", C, C) - tr * tr / 3))
    return MU * dev / np.linalg.det(F)


def test_quadrature_stress_is_the_exact_field_and_its_maximum_the_solvers():
    from simfab.fem.elastic import det_and_von_mises

    fem = _plate(8)
    x = _bending(fem.rest)
    q = quadrature_von_mises(fem, x)
    corners = fem.rest[fem.elements[:, :3]]
    Xq = np.einsum("qc,mcd->mqd", fem.qp_bary, corners).reshape(-1, 2)
    assert np.allclose(q.ravel(), _exact_vm(Xq), rtol=1e-10)
    _, vm = det_and_von_mises(fem, x)  # what the insertion records per element: the largest point's
    assert np.allclose(q.max(axis=1), vm, rtol=1e-10)


@pytest.mark.parametrize("n", [4, 8])
def test_whole_body_mean_converges_where_the_element_maximum_is_biased(n):
    """With a radius larger than the part every point's mean is the body's mean stress; the
    3-point rule is exact for quadratics and this field is nearly one (measured: < 2e-8 relative at
    n = 4, 8, 16), while averaging each element's largest point is biased high by O(h |grad sigma|)
    (measured: +14 %, +7.1 %, +3.6 %)."""
    from simfab.fem.elastic import det_and_von_mises

    fem = _plate(n)
    x = _bending(fem.rest)
    g = np.linspace(0, 1, 801)
    G = np.stack(np.meshgrid(0.04 * (g[1:] + g[:-1]) / 2, 0.01 * (g[1:] + g[:-1]) / 2), -1).reshape(-1, 2)
    exact = float(_exact_vm(G).mean())  # midpoint rule on 800 x 800 cells: ~1e-6 relative
    qp = p2_averaged_von_mises(fem, x, 1.0)
    _, vm = det_and_von_mises(fem, x)
    elem = averaged_von_mises(fem, vm, 1.0)
    assert abs(qp / exact - 1) < 1e-5
    assert 0.5 * 0.14 * 4 / n < elem / exact - 1 < 2 * 0.14 * 4 / n


def test_a_radius_below_the_point_spacing_gives_the_largest_point_stress():
    fem = _plate(4)
    x = _bending(fem.rest)
    assert p2_averaged_von_mises(fem, x, 1e-6) == pytest.approx(quadrature_von_mises(fem, x).max(), rel=1e-12)
