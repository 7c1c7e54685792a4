"""A cantilever snap-fit: the verification of frictional contact against the wedge formula.

A PLA beam (length L along y, width T along x) is clamped at its root y = 0; its tip corner (0, L)
is pushed by the face of a rigid box inclined at alpha to the insertion direction (-y). Moving down
by delta past first touch the face deflects the tip by delta tan alpha along +x. Force balance of
the box on the face (normal force N, friction mu N opposing the sliding): the lateral force on the
beam is F_lat = N (cos alpha -+ mu sin alpha), the force along the path F = N (sin alpha +- mu cos
alpha), so

    F_in = F_lat (tan alpha + mu) / (1 - mu tan alpha)      on insertion,
    F_out = F_lat (tan alpha - mu) / (1 + mu tan alpha)     pushing the box back out on removal,

tan alpha without friction; at mu tan alpha >= 1 the insertion self-locks (jams). Both F and F_lat
are measured (F_lat is the support's reaction across the beam), so this contact law is checked
exactly. At the same position the frictionless and frictional runs deflect the tip alike, and the
force ratios are F_in(mu) / F_in(0) = (tan alpha + mu) / (tan alpha (1 - mu tan alpha)), removal
(tan alpha - mu) / (tan alpha (1 + mu tan alpha)), as far as F_lat is the same: the axial tip load P
(larger with friction) softens the beam by P / P_cr (P_cr = pi^2 EI / (4 L^2)) and bends it by its
moment P T / 2 about the beam's axis, a few percent at T / L = 0.075 and delta / L = 0.025 (most
at large alpha and mu).

``python tools/bench.py friction`` runs the table of angles and coefficients; a test runs a few."""

import numpy as np

from simfab.contact.sdf import Primitive, build_primitive_field
from simfab.coupling.config import ContactConfig, InsertionConfig
from simfab.coupling.simulate import make_coupling_model
from simfab.fem.materials import PLA
from simfab.fem.meshing import structured_box
from simfab.fem.model import make_model
from simfab.io.mjcf import Trajectory

L, T, GAP, DEFLECTION = 20e-3, 1.5e-3, 0.3e-3, 0.5e-3


def _beam(dim: int, cells_t: int):
    n_y = int(round(cells_t * L / T))
    if dim == 2:
        nx, ny = cells_t, n_y
        xs, ys = np.meshgrid(np.linspace(0, T, nx + 1), np.linspace(0, L, ny + 1), indexing="ij")
        P = np.c_[xs.ravel(), ys.ravel()]
        idx = np.arange((nx + 1) * (ny + 1)).reshape(nx + 1, ny + 1)
        a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
        E = np.r_[np.c_[a, b, c], np.c_[a, c, d]]
        return make_model(P, E, PLA, thickness=2e-3)
    V, E = structured_box((T, L, 2e-3), (cells_t, n_y, 2))
    return make_model(V, E, PLA)


def snapfit_model(alpha_deg: float, mu: float, *, dim: int = 2, steps: int = 24, cells_t: int = 3,
                  lag_tol: float = 0.01):
    """The snap-fit at face angle alpha [deg] and friction mu (see the module docstring): the box
    travels GAP to first touch, then until the tip is deflected by DEFLECTION. ``lag_tol``: the
    friction's lag tolerance (:class:`simfab.coupling.config.ContactConfig`), tighter than the
    default so that the check measures the contact law, not the lag."""
    fem = _beam(dim, cells_t)
    a = np.radians(alpha_deg)
    n = np.array([np.cos(a), -np.sin(a), 0.0])  # the face's outward normal (O on its left)
    touch = np.array([0.0, L + GAP, 0.0])  # a point of the face at the start, GAP above the tip corner
    ex, ey = 10e-3, 30e-3
    Q = np.array([[np.cos(a), np.sin(a), 0.0], [-np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])  # columns: box axes
    centre = touch - ex * n
    size = (ex, ey, np.inf if dim == 2 else 50e-3)
    field = build_primitive_field((Primitive(kind="box", size=size, centre=centre, rotation=Q),), dim)
    travel = GAP + DEFLECTION / np.tan(a)
    path = Trajectory(np.array([[0.0, 0.0, 0.0], [0.0, -travel, 0.0]]), np.array([[1.0, 0, 0, 0]] * 2))
    root = np.flatnonzero(fem.rest[:, 1] < 1e-9)
    opts = InsertionConfig(steps=steps, L_max=travel, fix_all_axes=True)
    return make_coupling_model(name=f"snapfit{dim}d", fem=fem, field=field, path=path, fixed_vertices=root,
                               options=opts, object_vertices=field.vertices,
                               contact=ContactConfig(friction=mu, lag_tol=lag_tol))


def ratio_formula(alpha_deg: float, mu: float, phase: str) -> float:
    """F(mu) / F(0) of the path force on insertion or removal at the same lateral force (module docstring)."""
    return contact_law(alpha_deg, mu, phase) / contact_law(alpha_deg, 0.0, phase)


def contact_law(alpha_deg: float, mu: float, phase: str) -> float:
    """|F| / F_lat: the force along the path over the lateral force on the beam, on insertion or
    removal (module docstring)."""
    t = np.tan(np.radians(alpha_deg))
    if phase == "insert":
        return (t + mu) / (1 - mu * t)
    return (t - mu) / (1 + mu * t)
