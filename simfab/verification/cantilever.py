"""Cantilever under a tip load: the bending verification problem for linear and P2 elements.

A prismatic beam of length L and square (3D) or rectangular plane-strain (2D) cross-section of
height h is clamped at X = 0 (all dofs of the face fixed) and loaded at X = L by a uniform shear
traction of resultant P in -y (consistent nodal loads). The deflection reported is the
work-conjugate one, delta = -f.u / P (the traction-weighted mean of the tip face's displacement,
i.e. the compliance), compared with Timoshenko beam theory:

    delta = P L^3 / (3 E' I) + P L / (kappa G A)

3D: E' = E, I = h^4 / 12, A = h^2; 2D plane strain (thickness t): E' = E / (1 - nu^2) (the beam
cannot contract out of plane), I = t h^3 / 12, A = t h; G = E / (2 (1 + nu)); kappa = 10 (1 + nu) /
(12 + 11 nu) (Cowper's shear coefficient of a rectangle). Beam theory ignores the clamp's
restraint of the Poisson contraction at the root, which stiffens a beam of slenderness 10 by a
few tenths of a percent (the mesh-converged FEM value in ``python tools/bench.py p2`` shows it).

Meshes: structured, cells of aspect ratio 1 (``n`` cells through the height, 10 n along L/h = 10):
3D 6-tet cubes (:func:`simfab.fem.meshing.structured_box`), 2D two triangles per square.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from simfab.fem import elastic as nh
from simfab.fem.loads import traction_loads
from simfab.fem.materials import Material
from simfab.fem.meshing import structured_box
from simfab.fem.model import FemModel, make_model
from simfab.fem.p2 import P2Model, to_p2
from simfab.solve.newton import minimize

#: the beam of the verification problem: steel-like modulus is irrelevant in the small-load limit
BEAM = Material(name="beam", youngs_modulus=1.0e6, poisson_ratio=0.3, yield_stress=1e12, density=1.0)


@dataclass(frozen=True, kw_only=True)
class CantileverResult:
    """One cantilever solve against Timoshenko beam theory.

    Args:
        delta: the work-conjugate tip deflection [m].
        reference: Timoshenko's tip deflection [m].
        ratio: delta / reference [-].
        dofs: free degrees of freedom.
        seconds: the static solve's wall time [s].
        iterations: Newton iterations.
    """

    delta: float
    reference: float
    ratio: float
    dofs: int
    seconds: float
    iterations: int


def rectangle_mesh(lx: float, ly: float, nx: int, ny: int) -> tuple[np.ndarray, np.ndarray]:
    """[0, lx] x [0, ly] in nx x ny cells, two counter-clockwise triangles per cell (diagonal from
    the lower left to the upper right corner): points ((nx+1)(ny+1), 2), triangles (2 nx ny, 3)."""
    X, Y = np.meshgrid(np.linspace(0, lx, nx + 1), np.linspace(0, ly, ny + 1), indexing="ij")
    i, j = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij"))
    v = lambda di, dj: (i + di) * (ny + 1) + j + dj  # noqa: E731
    tris = np.concatenate([np.stack([v(0, 0), v(1, 0), v(1, 1)], 1), np.stack([v(0, 0), v(1, 1), v(0, 1)], 1)])
    return np.c_[X.ravel(), Y.ravel()], tris.astype(np.int32)


def cantilever_model(dim: int, n: int, *, order: int = 1, length: float = 1.0, height: float = 0.1,
                     thickness: float = 0.05, material: Material = BEAM, degree: int | None = None
                     ) -> FemModel | P2Model:
    """The beam with ``n`` cells through the height (10 n along it at L/h = 10), linear (order 1)
    or P2 (order 2, quadrature ``degree``)."""
    nx = int(round(n * length / height))
    if dim == 3:
        V, T = structured_box((length, height, height), (nx, n, n))
        model = make_model(V, T, material)
    else:
        V, T = rectangle_mesh(length, height, nx, n)
        model = make_model(V, T, material, thickness=thickness)
    return to_p2(model, degree=degree) if order == 2 else model


def timoshenko_deflection(load: float, *, dim: int, length: float = 1.0, height: float = 0.1,
                          thickness: float = 0.05, material: Material = BEAM) -> float:
    """Tip deflection [m] of Timoshenko's cantilever (module docstring) under tip load [N]."""
    E, nu = material.youngs_modulus, material.poisson_ratio
    G = E / (2 * (1 + nu))
    kappa = 10 * (1 + nu) / (12 + 11 * nu)
    if dim == 3:
        E_eff, I, A = E, height**4 / 12, height**2
    else:
        E_eff, I, A = E / (1 - nu**2), thickness * height**3 / 12, thickness * height
    return load * length**3 / (3 * E_eff * I) + load * length / (kappa * G * A)


def tip_loads(model: FemModel | P2Model, load: float, length: float) -> np.ndarray:
    """Consistent nodal forces (n, dim) [N] of a uniform -y traction with resultant ``load`` on the
    face X = length (:func:`simfab.fem.loads.traction_loads`)."""
    X = model.rest
    on_tip = np.all(np.abs(X[model.boundary_facets, 0] - length) < 1e-9 * length, axis=1)
    f = traction_loads(model, on_tip, np.eye(model.dim)[1])
    return -load * f / f[:, 1].sum()


def static_solve(model: FemModel | P2Model, x0, free_vertices, forces):
    """Minimize E(x) - f.x over the free vertices (others stay at x0), exact-first Newton steps
    (:func:`simfab.solve.newton.minimize`). Returns (x (n, dim), NewtonResult)."""
    f = np.asarray(forces, float).ravel()

    def fun(x, need_h):
        if need_h:
            E, g, H_exact, H_psd = nh.energy_gradient_hessians(model, x)
            return E - f @ x, g.ravel() - f, (H_exact, H_psd)
        E, g = nh.energy_gradient(model, x)
        return E - f @ x, g.ravel() - f, None

    res = minimize(fun, np.asarray(x0, float).ravel(), free=np.repeat(np.asarray(free_vertices), model.dim),
                   admissible=lambda x: bool(np.all(nh.det_F(model, x) > 0)))
    return res.x.reshape(-1, model.dim), res


def solve_cantilever(model: FemModel | P2Model, *, length: float = 1.0, height: float = 0.1,
                     thickness: float = 0.05, rel_deflection: float = 1e-3) -> CantileverResult:
    """Tip deflection of ``model`` (from :func:`cantilever_model`) under the load whose Euler-
    Bernoulli deflection is ``rel_deflection`` L (small: geometric nonlinearity ~ its square)."""
    dim = model.dim
    material = model.material
    E_eff = material.youngs_modulus / (1 - material.poisson_ratio**2) if dim == 2 else material.youngs_modulus
    I = thickness * height**3 / 12 if dim == 2 else height**4 / 12
    load = rel_deflection * 3 * E_eff * I / length**2
    X = model.rest
    free = X[:, 0] > 1e-9 * length
    f = tip_loads(model, load, length)
    t0 = time.perf_counter()
    x, res = static_solve(model, X, free, f)
    seconds = time.perf_counter() - t0
    delta = float(np.sum(f * (x - X))) / load
    ref = timoshenko_deflection(load, dim=dim, length=length, height=height, thickness=thickness, material=material)
    return CantileverResult(delta=delta, reference=ref, ratio=delta / ref, dofs=int(free.sum() * dim),
                            seconds=seconds, iterations=res.iterations)
