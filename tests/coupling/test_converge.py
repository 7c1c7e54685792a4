"""Convergence-study helper: Richardson extrapolation recovers the limit of a sequence with a known
order, and the study refuses scenes whose part is only a ready mesh file."""

import numpy as np
import pytest

from simfab.coupling.converge import extrapolate, run_levels
from simfab.errors import InputError


def test_extrapolation_recovers_the_limit_of_a_power_law():
    # f(N) = 3 + 5 h^2, h = N^(-1/2) (2D): three levels give the limit and the order exactly
    N = np.array([500, 1000, 2000, 4000])
    f = 3.0 + 5.0 * N ** (-1.0)
    f_inf, p = extrapolate(N, f, dim=2)
    assert f_inf == pytest.approx(3.0, rel=1e-9) and p == pytest.approx(2.0, rel=1e-6)


def test_scenes_with_only_a_ready_mesh_cannot_be_refined(tmp_path):
    # a part given only as a ready mesh file (no generator to mesh it again) cannot be refined
    import shutil

    from simfab.coupling.scene import load_coupling_scene, scene_paths
    from simfab.fem.meshing import extrude_triangles, triangulate_polygon

    xml, toml = scene_paths("clip3d")
    shutil.copy(xml, tmp_path / xml.name)
    V, T = extrude_triangles(*triangulate_polygon(np.array([[-0.0163, -0.01], [-0.012, -0.01], [-0.012, 0.01],
                                                            [-0.0163, 0.01]])), -0.004, 0.004)
    np.savez(tmp_path / "part.npz", points=V, elements=T)
    text = toml.read_text().replace('generator = "extruded_clamp"', 'mesh_file = "part.npz"')
    (tmp_path / "clip3d.toml").write_text(text)
    assert load_coupling_scene(tmp_path / "clip3d.toml").fem.n_elements == len(T)  # the file is used
    with pytest.raises(InputError, match="target_elements"):
        run_levels(tmp_path / "clip3d.toml", (1, 2))
