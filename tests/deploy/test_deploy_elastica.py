"""The analytic elastica against the published reference table and its own closed forms."""

import sys
from pathlib import Path

import numpy as np
import pytest

from simfab.deploy import elastica
from simfab.errors import InputError

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))
from benchmarks._reference import figures  # noqa: E402


def test_matches_reference_figures():
    ref = figures().get("elastica_first_mode")
    if not ref:
        pytest.skip("shared reference figures not available")
    for row in ref["rows"]:
        for support in elastica.SUPPORTS:
            sol = elastica.solve(row["g_over_L"], support)
            # the reference is rounded to 5 decimals (delta/L) and 2 decimals (alpha in degrees)
            assert sol.delta_over_L == pytest.approx(row["delta_over_L"], abs=6e-6)
            assert np.degrees(sol.alpha) == pytest.approx(row["alpha_deg"], abs=6e-3)


@pytest.mark.parametrize("support", elastica.SUPPORTS)
@pytest.mark.parametrize("r", [0.99, 0.8, 0.3])
def test_shape_closes_the_gap_with_the_right_rise_and_length(support, r):
    sol = elastica.solve(r, support)
    xz = sol.shape(1.0, 4001)
    assert xz[0] == pytest.approx([0, 0], abs=1e-14)
    assert xz[-1] == pytest.approx([r, 0], abs=1e-12)
    assert xz[:, 1].max() == pytest.approx(sol.delta_over_L, rel=1e-6)
    length = np.sum(np.linalg.norm(np.diff(xz, axis=0), axis=1))
    assert length == pytest.approx(1.0, rel=1e-6)  # inextensible: arc length L
    assert sol.force_factor == pytest.approx((4.0 if support == "pinned" else 16.0) * sol.K**2)


def test_bad_ratio_is_input_error():
    with pytest.raises(InputError):
        elastica.solve(1.2)
    with pytest.raises(InputError):
        elastica.solve(0.5, "hinged")
