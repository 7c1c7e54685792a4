"""Hertz check at modest size: a rigid sphere pressed into a block graded toward the contact (the
quarter x, y >= 0 with symmetry planes, simfab.verification.hertz).

Hertz: F = 4/3 E* sqrt(R) d^(3/2) on a half-space. At this size (4.2k tets, edge ~ a / 6 at the
contact) linear tets are measurably stiff: the same mesh's linear solution under Hertz's pressure
moves the centre s = 0.94 d instead of d, and a sphere driven to travel d then meets about
F_Hertz s^-1.5 (1.10 F_Hertz). The test holds the contact to that: F / F_Hertz within 3% of
s^-1.5 (the contact itself, its standoff and the barrier, add no stiffness of their own), and
the mesh error bounded. The full-size check (41k tets, within 5% of Hertz at d/R = 0.02-0.05 with
no correction) is ``python tools/bench.py hertz``.
"""

import numpy as np
import pytest

from simfab.coupling.layout import point_dhat
from simfab.verification.hertz import linear_centre_displacement, sphere_on_block

R, E, NU = 0.01, 1e6, 0.3


@pytest.fixture(scope="module")
def pressed(require_gmsh):
    return sphere_on_block(h0=0.01, growth=0.2, W=10.0, D=10.0, R=R, E=E, nu=NU, d_max=0.05, steps=2)


def test_force_follows_hertz_up_to_the_meshs_own_stiffness(pressed):
    res, rows = pressed
    band = [r for r in rows if 0.02 <= r["d_over_R"] <= 0.0501]
    assert len(band) == 2
    for r in band:
        assert r["a_over_h"] >= 5  # the contact radius is resolved by >= 5 elements
        s = linear_centre_displacement(res.model, R=R, d=r["d_over_R"] * R, E=E, nu=NU)
        assert 0.9 < s < 1.0  # the mesh is stiffer than the half-space, by a few percent
        assert r["F_over_Hertz"] == pytest.approx(s**-1.5, rel=0.03), (r, s)


def test_standoff_is_a_fraction_of_the_local_element_size(pressed):
    res, rows = pressed
    cm = res.model
    last = res.steps[-1]
    P = cm.fem.rest
    centre = int(np.argmin(np.linalg.norm(P, axis=1)))
    from simfab.coupling.points import face_weights, vertex_points

    # the contact elements are much smaller than the mesh's mean edge length, and d_hat follows them
    dhat_local = float(point_dhat(cm, vertex_points(np.array([centre]), 3))[0])
    assert dhat_local < 0.2 * cm.dhat
    # the block's top surface (dense points on its boundary faces) touches the sphere within the
    # local activation distance (standoff <= 1-2% of the local edge length), far below the travel
    facets = np.asarray(cm.fem.boundary_facets)
    on_top = facets[np.all(np.abs(P[facets][:, :, 2]) <= 1e-12, axis=1)]
    y = np.einsum("pm,fmd->fpd", face_weights(8), last.x[on_top]).reshape(-1, 3)
    Rm, p = cm.pose(last.s)
    gaps = -cm.field.evaluate(y, (Rm, p), hessian=False).psi
    assert 0 < gaps.min() <= 2 * dhat_local  # (the contact points sit on faces: their edge length is interpolated)
    d = rows[-1]["d_over_R"] * R
    assert gaps.min() < 0.02 * d
    assert rows[-1]["indentation_over_d"] == pytest.approx(1.0, abs=0.01)
