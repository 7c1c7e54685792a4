"""Hertz check of the contact: a rigid sphere pressed into an elastic block meshed with tetrahedra
graded toward the contact point: a verification of the contact against a closed form that users
can run (``python tools/bench.py hertz`` runs it at full size, a test at modest size).

Hertz (frictionless rigid sphere of radius R on an elastic half-space, E* = E / (1 - nu^2)):

    F(d) = 4/3 E* sqrt(R) d^(3/2),   contact radius a = sqrt(R d)

The half-space is a block 2W wide and D deep (in units of R), held in all axes on its bottom face
(sides free). By symmetry only its quarter x, y >= 0 is modelled, with the symmetry planes x = 0 and
y = 0 held normal to themselves (the force on the whole block is 4 times the quarter's support
reaction); it is meshed by :func:`simfab.fem.meshing.graded_box` with edge length h0 R at the contact
point growing by ``growth`` per unit distance.

The check's error has three sources (figures in docs/decisions.md): the stiffness of linear tets in
the zone r < ~5a that carries most of Hertz's compliance (the growth rate of the grading matters
most: at r = a the edge is ~ growth * a), the finite block, and the barrier's nodal pressure
(F / F_Hertz scales as (u_centre / d)^-1.5: the contact adds no stiffness of its own).
:func:`linear_centre_displacement` separates the first two from the third: the small-strain centre
displacement of the same mesh under Hertz's pressure p0 sqrt(1 - r^2/a^2), which is d exactly on a
half-space.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from simfab.contact.sdf import Primitive, build_primitive_field
from simfab.coupling.config import InsertionConfig
from simfab.coupling.simulate import make_coupling_model, simulate_insertion
from simfab.fem.elastic import energy_gradient_hessian
from simfab.fem.materials import Material
from simfab.fem.meshing import graded_box
from simfab.fem.model import make_model
from simfab.io.mjcf import Trajectory


def hertz_force(d, R: float, E: float, nu: float):
    """Hertz's force [N] of a rigid sphere (radius R [m]) pressed d [m] into a half-space (E [Pa], nu)."""
    return 4.0 / 3.0 * E / (1.0 - nu**2) * np.sqrt(R) * np.asarray(d, dtype=float) ** 1.5


def sphere_on_block(*, h0: float = 0.0025, growth: float = 0.1, W: float = 20.0, D: float = 20.0, R: float = 0.01,
                    d_max: float = 0.05, steps: int = 5, E: float = 1e6, nu: float = 0.3):
    """Run the sphere (radius R [m]) down into the block (sizes W, D, h0 in units of R; see the
    module docstring) to indentation d_max * R; returns (result, rows) with one row per step in
    contact: d/R, F / F_Hertz (F the support reaction, d the sphere's nominal travel past first
    touch), a / h (contact radius over the mean edge length of the top faces within the contact
    radius), block indentation / d (the top centre's downward displacement over the sphere's
    travel: 1 + standoff / d, the surface is pushed the barrier's standoff past the sphere)."""

    mat = Material(name="soft", youngs_modulus=E, poisson_ratio=nu, yield_stress=1e12, density=1000.0)
    P, T = graded_box((0.0, 0.0, -D * R), (W * R, W * R, 0.0), centre=(0.0, 0.0, 0.0), h0=h0 * R,
                      growth=growth, h_max=0.5 * min(W, D) * R)
    fem = make_model(P, T, mat)
    fld = build_primitive_field((Primitive(kind="sphere", size=(R,), centre=np.zeros(3), rotation=np.eye(3)),), 3, 500)
    gap = 1e-4 * R
    path = Trajectory(np.array([[0, 0, R + gap], [0, 0, R - d_max * R]]), np.array([[1.0, 0, 0, 0]] * 2))
    bottom = np.flatnonzero(P[:, 2] <= -D * R * (1 - 1e-12))
    cm = make_coupling_model(name="hertz", fem=fem, field=fld, path=path, fixed_vertices=bottom,
                             options=InsertionConfig(steps=steps, fix_all_axes=True, L_max=path.length),
                             object_vertices=fld.vertices)
    free = cm.free.reshape(-1, 3).copy()
    free[np.abs(P[:, 0]) <= 1e-12 * R, 0] = False  # symmetry planes
    free[np.abs(P[:, 1]) <= 1e-12 * R, 1] = False
    cm = replace(cm, free=free.ravel())
    res = simulate_insertion(cm)
    top = np.flatnonzero(np.abs(P[:, 2]) <= 1e-12 * R)
    centre = top[np.argmin(np.linalg.norm(P[top, :2], axis=1))]
    facets = np.asarray(fem.boundary_facets)
    top_f = facets[np.all(np.abs(P[facets][:, :, 2]) <= 1e-12 * R, axis=1)]
    edges = np.linalg.norm(P[top_f] - P[np.roll(top_f, 1, axis=1)], axis=2)  # (f, 3)
    r_f = np.linalg.norm(P[top_f][:, :, :2].mean(axis=1), axis=1)
    rows = []
    for r in res.steps:  # r.force: the bottom's reaction along z on the quarter
        d = r.s - gap
        if d <= 0:
            continue
        a = np.sqrt(R * d)
        h = float(edges[r_f <= a].mean()) if np.any(r_f <= a) else float(edges[np.argmin(r_f)].mean())
        rows.append({"d_over_R": d / R, "F_over_Hertz": float(-4.0 * r.force / hertz_force(d, R, E, nu)),
                     "a_over_h": a / h, "indentation_over_d": float(-r.x[centre, 2] / d)})
    return res, rows


def linear_centre_displacement(cm, *, R: float, d: float, E: float, nu: float, quad: int = 6) -> float:
    """The mesh's own stiffness under Hertz's load: the centre displacement [units of d] of the
    linear (small-strain) solution K u = f of ``cm``'s block (K the elastic Hessian at rest, the
    supports and symmetry planes of ``cm.free``) under the Hertz pressure of indentation d,
    p(r) = p0 sqrt(1 - r^2 / a^2), p0 = 3 F / (2 pi a^2), on its top face (quarter: a quarter of
    the load). On a half-space the centre moves exactly d; a mesh that gives s d is stiffer, and a
    rigid sphere driven to travel d meets about F_Hertz s^-1.5 (docs/decisions.md, "Verification:
    the Hertz check").
    The pressure is integrated per top triangle by the midpoint rule on quad^2 sub-triangles."""
    import scipy.sparse.linalg as spl


    fem = cm.fem
    P = fem.rest
    a = np.sqrt(R * d)
    p0 = 3.0 * float(hertz_force(d, R, E, nu)) / (2.0 * np.pi * a * a)
    facets = np.asarray(fem.boundary_facets)
    top = facets[np.all(np.abs(P[facets][:, :, 2]) <= 1e-12 * R, axis=1)]
    # centroids of the quad^2 equal sub-triangles of each face (barycentric (q, 3)): the midpoint rule
    ij = [(i + o, j + o) for i in range(quad) for j in range(quad - i) for o in (1 / 3, 2 / 3)
          if o < 0.5 or i + j < quad - 1]
    w = np.array([(i / quad, j / quad, 1.0 - (i + j) / quad) for i, j in ij])
    q = np.einsum("pm,fmd->fpd", w, P[top])  # (f, q, 3)
    p = p0 * np.sqrt(np.clip(1.0 - (q[:, :, :2] ** 2).sum(-1) / a**2, 0.0, None))  # (f, q)
    area = 0.5 * np.linalg.norm(np.cross(P[top[:, 1]] - P[top[:, 0]], P[top[:, 2]] - P[top[:, 0]]), axis=1)
    f = np.zeros((len(P), 3))
    np.add.at(f[:, 2], top, -(area[:, None, None] * p[:, :, None] * w[None]).mean(axis=1))
    _, _, K = energy_gradient_hessian(fem, P, project_psd=False)
    free = np.asarray(cm.free)
    u = np.zeros(3 * len(P))
    u[free] = spl.spsolve(K[free][:, free].tocsc(), f.ravel()[free])
    centre = int(np.argmin(np.linalg.norm(P, axis=1)))
    return float(-u[3 * centre + 2] / d)
