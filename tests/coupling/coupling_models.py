"""Small programmatic coupling models shared by the coupling tests."""

import numpy as np

from simfab.coupling.config import InsertionOptions
from simfab.coupling.simulate import make_coupling_model


def coarse_block_model(refine: bool):
    """A 4 x 2 mm PLA block of two triangles (its top edge is a single 4 mm edge) and a circle of
    radius 3 mm pushed down onto the middle of that edge until its vertices are 0.12 mm outside
    the circle while the circle reaches 0.6 mm below the undeformed edge."""
    from simfab.contact.imls import build_imls, curve_normals
    from simfab.coupling.geometry import circle_samples
    from simfab.fem.materials import PLA
    from simfab.fem.model import make_model
    from simfab.io.mjcf import Trajectory

    P = np.array([[-2, -2], [2, -2], [2, 0], [-2, 0]]) * 1e-3
    T = np.array([[0, 1, 2], [0, 2, 3]])
    fem = make_model(P, T, PLA, thickness=1e-3)
    v, _ = circle_samples(3e-3, 200)
    fld = build_imls(v, curve_normals(v))
    path = Trajectory(np.array([[0, 3.3e-3, 0], [0, 2.4e-3, 0]]), np.array([[1.0, 0, 0, 0]] * 2))
    opts = InsertionOptions(steps=4, fix_all_axes=True, refine=refine, samples_per_edge=20)
    return make_coupling_model(name="block", fem=fem, field=fld, path=path, fixed_vertices=[0, 1], options=opts,
                               object_vertices=v)


