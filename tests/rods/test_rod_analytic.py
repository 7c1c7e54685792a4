"""Rod energies against closed forms: zero at rest, uniform twist, uniform curvature, anisotropy."""

import numpy as np
import pytest

from simfab.rods.energy import Evaluator
from simfab.rods.frames import signed_angle
from simfab.rods.model import NetworkBuilder, RodMaterial, Section, synchronize
from simfab.rotations import expmap

MAT = RodMaterial(young=2e9, poisson=0.35)
SEC = Section(width=5e-3, thickness=1e-3)


def bezier(n):
    t = np.linspace(0, 1, n + 1)[:, None]
    P0, P1, P2, P3 = np.array([[0, 0, 0], [0.03, 0.02, 0.01], [0.05, -0.02, 0.0], [0.08, 0.01, 0.02]])
    return (1 - t) ** 3 * P0 + 3 * (1 - t) ** 2 * t * P1 + 3 * (1 - t) * t**2 * P2 + t**3 * P3


@pytest.mark.parametrize("shape", ["straight", "curved"])
def test_zero_energy_and_force_at_rest_and_under_rigid_motion(shape):
    n = 16
    P = np.linspace([0, 0, 0], [0.1, 0, 0], n + 1) if shape == "straight" else bezier(n)
    nb = NetworkBuilder()
    nb.add_rod("r", P, section=SEC, material=MAT)
    model, st = nb.build()
    ev = Evaluator(model)
    E, g, _ = ev(st)
    fscale = MAT.young * SEC.area()  # N, force unit of the stretch term
    assert abs(E) <= 1e-20
    assert np.max(np.abs(g)) <= 1e-12 * fscale
    # rigid rotation + translation of the rest shape, with the material frames rotated along
    # (theta chosen so m1 = R m1_rest in the time-transported reference frame): still stress free
    R = expmap(np.array([[0.3, -0.7, 0.4]]))[0]
    x = st.x @ R.T + [0.01, 0.02, -0.03]
    moved = synchronize(model, st, x, st.theta, st.body_pos, st.body_rot)
    m1_rest, _ = st.material_frames()
    theta = signed_angle(moved.d1, m1_rest @ R.T, moved.t)
    moved = synchronize(model, st, x, theta, st.body_pos, st.body_rot)
    E, g, _ = ev(moved)
    assert abs(E) <= 1e-16
    assert np.max(np.abs(g)) <= 1e-9 * fscale


def test_uniform_twist_energy():
    """Straight rod, theta_i = tau * s_i: E = GJ tau^2 L / 2 with L the summed Voronoi lengths (exact)."""
    n, L = 20, 0.1
    nb = NetworkBuilder()
    nb.add_rod("r", np.linspace([0, 0, 0], [L, 0, 0], n + 1), section=SEC, material=MAT)
    model, st = nb.build()
    tau = 3.0  # rad/m
    s = (np.arange(n) + 0.5) * L / n
    st = st.replace(theta=tau * s)
    E, _, _ = Evaluator(model, terms=("twist",))(st)
    GJ = SEC.stiffness(MAT)["GJ"]
    assert E == pytest.approx(0.5 * GJ * tau**2 * np.sum(model.vor_len), rel=1e-12)


@pytest.mark.parametrize("plane,stiff", [("xz", "B1"), ("xy", "B2")])
def test_uniform_curvature_energy_and_anisotropy(plane, stiff):
    """Straight rest shape bent onto a circular arc of curvature kappa in the plane normal to m2 (xz:
    weak axis B1 = E w t^3/12) or to m1 (xy: strong axis B2 = E t w^3/12).
    Discrete: |kb| = 2 tan(phi/2), phi = kappa h, so E = B kappa^2 L / 2 * (1 + phi^2/6 + ...)."""
    n, L, kappa = 40, 0.1, 8.0
    h = L / n
    nb = NetworkBuilder()
    nb.add_rod("r", np.linspace([0, 0, 0], [L, 0, 0], n + 1), section=SEC, material=MAT, director=(0, 0, 1))
    model, st = nb.build()
    # chord length of each edge = h so the arc is unstretched: radius R with 2 R sin(phi/2) = h
    phi = kappa * h
    Rr = h / (2 * np.sin(phi / 2))
    u, w = np.sin(np.arange(n + 1) * phi) * Rr, (1 - np.cos(np.arange(n + 1) * phi)) * Rr
    x = np.zeros((n + 1, 3))
    x[:, 0] = u
    x[:, 2 if plane == "xz" else 1] = w
    bent = synchronize(model, st, x, st.theta, st.body_pos, st.body_rot)
    ev = Evaluator(model)
    E, _, _ = ev(bent)
    B = SEC.stiffness(MAT)[stiff]
    Lv = np.sum(model.vor_len)
    exact_discrete = 0.5 * B * (2 * np.tan(phi / 2)) ** 2 / h * (n - 1)
    assert ev.parts["stretch"] <= 1e-12 * E
    assert ev.parts["bend"] == pytest.approx(exact_discrete, rel=1e-10)
    assert ev.parts["bend"] == pytest.approx(0.5 * B * kappa**2 * Lv, rel=phi**2 / 3)
    assert ev.parts["twist"] <= 1e-12 * E
