"""Small programmatic coupling models shared by the coupling tests, as factory fixtures (plain
assertion helpers live in _coupling_checks.py)."""

import numpy as np
import pytest

from simfab.coupling.config import InsertionConfig
from simfab.coupling.simulate import make_coupling_model


def _coarse_block_model(refine: bool):
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
    opts = InsertionConfig(steps=4, fix_all_axes=True, refine=refine, samples_per_edge=20)
    return make_coupling_model(name="block", fem=fem, field=fld, path=path, fixed_vertices=[0, 1], options=opts,
                               object_vertices=v)




def _ellipse_in_clamp_model(steps: int = 16):
    """The loose 2D clamp of ``clip2d_loose`` (inner radius 10.6 mm) with an elliptical object
    (semi-axes 11.2 x 8 mm) centred 0.9 mm in front of the clamp's centre, its long axis along the
    path (clear of the clamp), that is rotated by 90 degrees about its centre: the long axis ends
    across the clamp, where it presses the arc by ~0.6 mm (a rotating path; the 0.1 mm translation
    before the rotation only gives the path a direction)."""
    from simfab.contact.imls import build_imls, curve_normals
    from simfab.coupling.scene import load_coupling_scene
    from simfab.io.mjcf import Trajectory

    base = load_coupling_scene("clip2d_loose")
    t = np.linspace(0, 2 * np.pi, 120, endpoint=False)
    v = np.c_[11.2e-3 * np.cos(t), 8.0e-3 * np.sin(t)]
    fld = build_imls(v, curve_normals(v))
    q90 = [np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)]
    path = Trajectory(np.array([[1.0e-3, 0, 0], [0.9e-3, 0, 0], [0.9e-3, 0, 0]]),
                      np.array([[1.0, 0, 0, 0], [1.0, 0, 0, 0], q90]), rot_length_scale=0.01)
    opts = InsertionConfig(steps=steps, fix_all_axes=True)
    return make_coupling_model(name="ellipse", fem=base.fem, field=fld, path=path,
                               fixed_vertices=base.fixed_vertices, options=opts, object_vertices=v)


@pytest.fixture
def coarse_block_model():
    return _coarse_block_model


@pytest.fixture
def ellipse_in_clamp_model():
    return _ellipse_in_clamp_model
