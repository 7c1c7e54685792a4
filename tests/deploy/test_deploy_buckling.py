"""Discrete elastic rods vs the exact elastica (fast subset of ``simfab validate buckling``)."""

import numpy as np
import pytest

from simfab.deploy import buckling as bk
from simfab.deploy import tolerances as tol


@pytest.fixture(scope="module")
def setup():
    return bk.load_insert_scene(bk.elastica_scene_path()).setup


@pytest.mark.parametrize("support,ratios", [("pinned", [0.95, 0.8]), ("clamped", [0.9])])
def test_rise_and_force_within_tolerance_at_n80(setup, support, ratios):
    rows = bk.run_continuation(setup, support, tol.VALIDATION_N, ratios)
    for r in rows:
        assert r["rel_err"] <= tol.RISE_RTOL[support], r
        assert r["force_rel_err"] <= tol.FORCE_RTOL, r


def test_second_order_convergence_pinned(setup):
    """Pinned ends: rise error ~ (L/n)^2; halving h divides it by ~4."""
    e = [bk.run_continuation(setup, "pinned", n, [0.9])[0]["rel_err"] for n in (20, 40)]
    assert 1.8 <= np.log2(e[0] / e[1]) <= 2.2


def test_critical_load_pinned(setup):
    """Smallest load where the straight beam's Hessian loses definiteness vs pi^2 B / L^2."""
    c = bk.critical_load(setup, tol.VALIDATION_N, "pinned")
    assert c["rel_err"] <= tol.CRITICAL_LOAD_RTOL
    assert c["critical_load"] < c["euler_load"]  # the discrete chain is slightly softer


@pytest.mark.parametrize("support", ["pinned", "clamped"])
def test_insert_path_equals_direct_path(setup, support):
    """Moving end attached to the MuJoCo insert body and driven through its pose = direct end displacement."""
    a = bk.run_continuation(setup, support, 20, [0.9], path="direct", keep_states=True)[0]
    b = bk.run_continuation(setup, support, 20, [0.9], path="insert", keep_states=True)[0]
    assert b["delta_over_L"] == pytest.approx(a["delta_over_L"], rel=tol.INSERT_VS_DIRECT_RTOL)
    assert b["force"] == pytest.approx(a["force"], rel=tol.INSERT_VS_DIRECT_RTOL)
    assert np.allclose(a["shape"], b["shape"], atol=1e-9 * setup.length)
