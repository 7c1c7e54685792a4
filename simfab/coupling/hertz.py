"""Hertz check of the contact: a rigid sphere pressed into an elastic block meshed with tetrahedra
graded toward the contact point (used by a test at modest size and by ``tools/bench.py hertz``).

Hertz (frictionless rigid sphere of radius R on an elastic half-space, E* = E / (1 - nu^2)):

    F(d) = 4/3 E* sqrt(R) d^(3/2),   contact radius a = sqrt(R d)

The block is W wide (half-width), D deep, held in all axes on its bottom face; its grid is graded
toward the top centre, x_i = W sign(t_i) |t_i|^g on an even t in [-1, 1] (z likewise), each hex
split into 6 tetrahedra around its diagonal.
"""

from __future__ import annotations

import numpy as np


def graded_block(n: int, nz: int, W: float, D: float, g: float) -> tuple[np.ndarray, np.ndarray]:
    """(points (p, 3) [m], tets (m, 4)): n x n x nz hexes over [-W, W]^2 x [-D, 0], graded by g."""
    t = np.linspace(-1, 1, n + 1)
    xs = W * np.sign(t) * np.abs(t) ** g
    zs = np.sort(-D * np.linspace(0, 1, nz + 1) ** g)
    X, Y, Z = np.meshgrid(xs, xs, zs, indexing="ij")
    P = np.c_[X.ravel(), Y.ravel(), Z.ravel()]
    idx = np.arange(len(P)).reshape(len(xs), len(xs), len(zs))
    i, j, k = np.meshgrid(np.arange(n), np.arange(n), np.arange(nz), indexing="ij")
    v = [idx[i + a, j + b, k + c].ravel() for a in (0, 1) for b in (0, 1) for c in (0, 1)]  # corner 4a + 2b + c
    T = [np.c_[v[0], v[p1], v[p1 | p2], v[7]] for p1, p2 in ((4, 6), (4, 5), (2, 6), (2, 3), (1, 5), (1, 3))]
    return P, np.vstack(T)


def sphere_on_block(*, n: int = 8, nz: int = 6, W: float = 2.0, D: float = 2.0, g: float = 2.5, R: float = 0.01,
                    d_max: float = 0.05, steps: int = 5, E: float = 1e6, nu: float = 0.3):
    """Run the sphere (radius R [m]) down into the block (sizes in units of R) to indentation
    d_max * R; returns (result, rows) with one row per step in contact: d/R, F / F_Hertz (F the
    support reaction), a / h (contact radius over the smallest element), block indentation / d
    (the top centre's downward displacement over the sphere's travel: 1 - standoff / d)."""
    from simfab.contact.sdf import Primitive, build_primitive_field
    from simfab.coupling.config import InsertionOptions
    from simfab.coupling.simulate import make_coupling_model, simulate
    from simfab.fem.materials import Material
    from simfab.fem.model import make_model
    from simfab.io.mjcf import Trajectory

    mat = Material(name="soft", youngs_modulus=E, poisson_ratio=nu, yield_stress=1e12, density=1000.0)
    P, T = graded_block(n, nz, W * R, D * R, g)
    fem = make_model(P, T, mat)
    fld = build_primitive_field((Primitive(kind="sphere", size=(R,), centre=np.zeros(3), rotation=np.eye(3)),), 3, 500)
    gap = 1e-4 * R
    path = Trajectory(np.array([[0, 0, R + gap], [0, 0, R - d_max * R]]), np.array([[1.0, 0, 0, 0]] * 2))
    bottom = np.flatnonzero(P[:, 2] <= -D * R * (1 - 1e-12))
    cm = make_coupling_model(name="hertz", fem=fem, field=fld, path=path, fixed_vertices=bottom,
                             options=InsertionOptions(steps=steps, fix_all_axes=True, L_max=path.length),
                             object_vertices=fld.vertices)
    res = simulate(cm)
    Es = E / (1 - nu**2)
    top = np.flatnonzero(P[:, 2] == 0)
    centre = top[np.argmin(np.linalg.norm(P[top, :2], axis=1))]
    h = float(np.min(np.diff(np.unique(P[:, 0]))))
    rows = []
    for r in res.steps:
        d = r.s - gap
        if d <= 0:
            continue
        F = -r.force
        rows.append({"d_over_R": d / R, "F_over_Hertz": F / (4 / 3 * Es * np.sqrt(R) * d**1.5),
                     "a_over_h": float(np.sqrt(R * d) / h), "indentation_over_d": float(-r.x[centre, 2] / d)})
    return res, rows
