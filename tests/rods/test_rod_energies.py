"""Rod energies (stretch, bend, twist): gradients and Hessians against finite differences.

The energy of a configuration is evaluated with reference frames time-parallel transported
from the base state (``synchronize``), the same definition the solver uses. Gradients are
checked against central differences of the energy; Hessians against the symmetrized central
differences of the analytic gradient and against directional second differences of the
energy. Step h = 1e-6 (1e-4 for second differences); the truncation error is O(h^2) relative
to the curvature of the energy, so 1e-6 relative tolerances would fail on any wrong term.
"""

import numpy as np
import pytest

from simfab.rods.energy import Evaluator
from simfab.rods.model import NetworkBuilder, RodMaterial, Section, synchronize

TERMS = ["stretch", "bend", "twist"]


def random_network(seed, section):
    rng = np.random.default_rng(seed)
    nb = NetworkBuilder()
    for r in range(2):  # two rods in one batch: checks the batched launch and DOF maps
        P = np.cumsum(rng.normal(scale=0.02, size=(6, 3)) + [0.02, 0, 0], axis=0) + r * 0.1
        rest = P + rng.normal(scale=0.003, size=P.shape)  # curved, non-trivial natural shape
        nb.add_rod(f"r{r}", P, rest_points=rest, section=section, material=RodMaterial(young=1e9, poisson=0.3),
                   director=rng.normal(size=3))
    model, st0 = nb.build()
    # a deformed state with random twist angles and a non-zero reference twist
    x = st0.x + rng.normal(scale=0.003, size=st0.x.shape)
    st = synchronize(model, st0, x, rng.normal(scale=0.5, size=model.n_edges), st0.body_pos, st0.body_rot)
    return model, st


def perturbed(model, st, d):
    N = model.n_nodes
    return synchronize(model, st, st.x + d[: 3 * N].reshape(-1, 3), st.theta + d[3 * N:], st.body_pos, st.body_rot)


SECTIONS = [Section(width=4e-3, thickness=1e-3), Section(shape="circle", radius=1e-3)]


@pytest.mark.parametrize("term", TERMS)
@pytest.mark.parametrize("seed", [0, 1])
def test_gradient_and_hessian_match_finite_differences(term, seed):
    model, st = random_network(seed, SECTIONS[seed % 2])
    ev = Evaluator(model, terms=(term,))
    E, g, H = ev(st)
    assert E > 0
    n = ev.n_dofs
    # scale angle DOFs to lengths so one step size fits all
    scale = np.ones(n)
    scale[3 * model.n_nodes:] = 1.0 / 0.02
    h = 1e-6
    I = np.eye(n)
    gfd = np.array([(ev(perturbed(model, st, h * scale[i] * I[i]), False, False)[0]
                     - ev(perturbed(model, st, -h * scale[i] * I[i]), False, False)[0]) / (2 * h * scale[i])
                    for i in range(n)])
    assert np.max(np.abs(g - gfd)) <= 1e-6 * np.max(np.abs(g))
    Hfd = np.array([(ev(perturbed(model, st, h * scale[i] * I[i]), True, False)[1]
                     - ev(perturbed(model, st, -h * scale[i] * I[i]), True, False)[1]) / (2 * h * scale[i])
                    for i in range(n)])
    Hd = H.toarray()
    assert np.allclose(Hd, Hd.T, rtol=0, atol=1e-12 * np.abs(Hd).max())
    assert np.max(np.abs(Hd - 0.5 * (Hfd + Hfd.T))) <= 1e-5 * np.max(np.abs(Hd))
    # directional second differences of the energy itself
    rng = np.random.default_rng(seed + 10)
    hs = 1e-4
    for _ in range(3):
        v = rng.normal(size=n) * scale
        e2 = (ev(perturbed(model, st, hs * v), False, False)[0] - 2 * E
              + ev(perturbed(model, st, -hs * v), False, False)[0]) / hs**2
        assert v @ Hd @ v == pytest.approx(e2, rel=1e-4, abs=1e-6 * np.abs(Hd).max() * (v @ v))
