"""Convergence-study helper: Richardson extrapolation recovers the limit of a sequence with a known
order, and the study refuses scenes whose part is a ready mesh file."""

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


def test_scenes_with_a_ready_mesh_cannot_be_refined():
    with pytest.raises(InputError, match="target_elements"):
        run_levels("clip3d", (1, 2))
