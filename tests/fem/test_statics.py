"""Static equilibrium solves with the Neo-Hookean energy and projected Newton: patch test and
cantilevers against Euler-Bernoulli beam theory."""

import numpy as np
import pytest
from _fem_meshes import box_tet, box_tet24, rect_tri

from simfab.fem import neohookean as nh
from simfab.fem.materials import Material
from simfab.fem.model import make_model
from simfab.solve.newton import minimize


def _static_solve(model, x0, free_vertices, force):
    """Minimize E(x) - f.x over the free vertices (others stay at x0): equilibrium grad E = f."""
    f = np.asarray(force, float).ravel()

    def fun(x, need_h):
        if need_h:
            E, g, H = nh.energy_gradient_hessian(model, x)
            return E - f @ x, g.ravel() - f, H
        E, g = nh.energy_gradient(model, x)
        return E - f @ x, g.ravel() - f, None

    res = minimize(fun, np.asarray(x0, float).ravel(), free=np.repeat(free_vertices, model.dim),
                   admissible=lambda x: bool(np.all(nh.det_F(model, x) > 0)))
    return res.x.reshape(-1, model.dim), res


@pytest.mark.parametrize("dim", [2, 3])
def test_patch_test_affine_field_is_reproduced(dim):
    # A homogeneous deformation x = A X + t gives the same F (hence P) in every element, so the
    # internal forces at interior nodes cancel: with the boundary prescribed from the affine map,
    # the interior must reproduce it exactly (to the Newton tolerance), for any hyperelastic law.
    rng = np.random.default_rng(20 + dim)
    mat = Material(name="t", youngs_modulus=1e6, poisson_ratio=0.4, yield_stress=1e9, density=1.0)
    if dim == 2:
        P, T = rect_tri(1.0, 0.8, 5, 4, crossed=False)
    else:
        P, T = box_tet(1.0, 0.8, 0.6, 4, 3, 3)
    P = P.copy()
    model0 = make_model(P, T, mat)
    interior = np.setdiff1d(np.arange(len(P)), model0.boundary_vertices)
    P[interior] += 0.03 * rng.standard_normal((len(interior), dim))  # irregular interior nodes
    model = make_model(P, T, mat)
    A = np.eye(dim) + 0.2 * rng.standard_normal((dim, dim))  # large (finite) strain
    assert np.linalg.det(A) > 0.3
    t = rng.standard_normal(dim)
    exact = model.rest @ A.T + t
    x0 = exact.copy()
    x0[interior] = model.rest[interior] + t  # interior starts far from the solution
    if np.any(nh.det_F(model, x0) <= 0):
        x0[interior] = exact[interior] + 0.02 * rng.standard_normal((len(interior), dim))
    free = np.zeros(len(P), bool)
    free[interior] = True
    x, res = _static_solve(model, x0, free, np.zeros_like(P))
    assert res.converged and res.iterations >= 1
    # the Newton tolerance is relative 1e-8 on the residual -> displacement error ~1e-8 of the
    # initial error (O(1)); allow 1e-7 of the body size
    np.testing.assert_allclose(x, exact, atol=1e-7)


def _cantilever(dim):
    """Clamped at X = 0, tip load -P (y) spread over the nodes of the tip face X = L."""
    E, nu = 1.0e6, 0.3
    mat = Material(name="beam", youngs_modulus=E, poisson_ratio=nu, yield_stress=1e9, density=1.0)
    L, h = 1.0, 0.1
    if dim == 2:
        thickness = 0.05
        # crossed triangles (4 per cell) lock far less in bending than 2 per cell
        P, T = rect_tri(L, h, 80, 8)
        model = make_model(P, T, mat, thickness=thickness)
        # plane strain: the beam cannot contract out of plane, so its bending modulus is
        # E' = E / (1 - nu^2); I = thickness h^3 / 12
        E_eff, I = E / (1 - nu**2), thickness * h**3 / 12
    else:
        # square section h x h, 24-tet cubes (less shear locking than 6-tet cubes): 80 x 8 x 2 cells
        P, T = box_tet24(L, h, h, 80, 8, 2)
        model = make_model(P, T, mat)
        E_eff, I = E, h**4 / 12  # 3D: free lateral contraction, plain E
    return model, L, E_eff, I


@pytest.mark.parametrize("dim", [2, 3])
def test_cantilever_tip_deflection_matches_euler_bernoulli(dim):
    model, L, E_eff, I = _cantilever(dim)
    # small load: tip deflection 1e-3 L, so geometric nonlinearity (O(delta/L)^2) is negligible
    P_load = 3 * E_eff * I / L**2 * 1e-3
    X = model.rest
    clamped = X[:, 0] < 1e-12
    tip = np.abs(X[:, 0] - L) < 1e-12
    f = np.zeros_like(X)
    f[tip, 1] = -P_load / tip.sum()
    x, res = _static_solve(model, X, ~clamped, f)
    delta = -np.mean(x[tip, 1] - X[tip, 1])
    # Euler-Bernoulli: delta = P L^3 / (3 E I). Slenderness L/h = 10: Timoshenko shear adds
    # +0.8%; the linear-element discretization is slightly stiff (-0.6% in 2D, -2% in 3D at
    # these resolutions, measured). Tolerance: 3%.
    delta_eb = P_load * L**3 / (3 * E_eff * I)
    assert delta == pytest.approx(delta_eb, rel=0.03)
    assert res.iterations <= 6
