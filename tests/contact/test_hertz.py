"""Contact scale on a graded mesh: a rigid sphere pressed into a block refined toward the contact.
The barrier's activation distance is 1% of the *local* edge length, so the standoff between the
sphere and the block is a fixed small fraction of the contact elements (with the whole mesh's mean
edge length it was ~7% of the travel at d/R = 0.05 and forces read against the travel came out
1.2-1.5x Hertz from it alone)."""

import numpy as np

from simfab.coupling.hertz import sphere_on_block
from simfab.coupling.objective import _point_dhat


def test_standoff_is_a_fraction_of_the_local_element_size():
    res, rows = sphere_on_block(n=8, nz=6, g=2.5, steps=3)
    cm = res.model
    last = res.steps[-1]
    P = cm.fem.rest
    top = np.flatnonzero(P[:, 2] == 0)
    centre = top[np.argmin(np.linalg.norm(P[top, :2], axis=1))]
    # the contact elements are much smaller than the mesh's mean edge length
    from simfab.coupling.points import vertex_points

    pts = vertex_points(np.array([centre]), 3)
    dhat_local = float(_point_dhat(cm, pts)[0])
    assert dhat_local < 0.2 * cm.dhat
    # the block's top surface (dense points on its boundary faces) touches the sphere within the
    # local activation distance (standoff <= 1-2% of the local edge length), far below the travel
    from simfab.coupling.points import face_weights

    facets = np.asarray(cm.fem.boundary_facets)
    on_top = facets[np.all(P[facets][:, :, 2] == 0, axis=1)]
    y = np.einsum("pm,fmd->fpd", face_weights(8), last.x[on_top]).reshape(-1, 3)
    R, p = cm.pose(last.s)
    gaps = -cm.field.evaluate(y, (R, p), hessian=False).psi
    assert 0 < gaps.min() <= 2 * dhat_local  # (the contact points sit on faces: their edge length is interpolated)
    d = rows[-1]["d_over_R"] * 0.01
    assert gaps.min() < 0.02 * d
