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
    # clip3d ships its tet mesh but has a generator (refined levels mesh it again); without the
    # generator the part is a ready mesh only
    import shutil

    from simfab.coupling.scene import scene_paths

    xml, toml = scene_paths("clip3d")
    for f in (xml, xml.with_name("clip3d_part.npz")):
        shutil.copy(f, tmp_path / f.name)
    text = toml.read_text().replace('generator = "extruded_clamp"', "")
    (tmp_path / "clip3d.toml").write_text(text)
    with pytest.raises(InputError, match="target_elements"):
        run_levels(tmp_path / "clip3d.toml", (1, 2))
