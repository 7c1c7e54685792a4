"""Growth lengths far outside the design box are input errors naming the parameter and the box
(simfab.growth.config.check_scale); derived defaults scale with the box and always pass."""

import numpy as np
import pytest

from simfab.errors import InputError
from simfab.growth.config import GrowthSceneConfig, resolve

BOX = np.array([[0.0, 0.0, 0.0], [0.12, 0.13, 0.15]])  # longest side 0.15 m, diagonal 0.2319 m
DIAG = float(np.linalg.norm(BOX[1] - BOX[0]))


@pytest.mark.parametrize("mode", ["volume", "surface"])
def test_defaults_fit_every_box(mode):
    for scale in (1e-3, 1.0, 1e3):
        r = resolve(GrowthSceneConfig.of(mode=mode), BOX * scale, area=None if mode == "volume" else 0.05 * scale**2)
        assert r.branch_length < 0.15 * scale and r.influence < r.diag and r.kill < r.diag


@pytest.mark.parametrize("key, ok, bad, where", [
    ("branch_length", 0.15, 0.1501, "growth.branch_length"),  # up to the longest side
    ("kill", DIAG * 0.999, DIAG * 1.001, "growth.kill"),  # up to the diagonal
    ("influence", DIAG * 0.999, DIAG * 1.001, "growth.influence"),
    ("r_max", DIAG * 0.999, DIAG * 1.001, "radius.r_max"),
])
def test_a_length_beyond_the_box_names_the_parameter_and_the_box(key, ok, bad, where):
    extra = {"kill": 1e-3} if key == "influence" else {"influence": DIAG} if key == "kill" else {}
    resolve(GrowthSceneConfig.of(**{key: ok}, **extra), BOX)
    with pytest.raises(InputError) as e:
        resolve(GrowthSceneConfig.of(**{key: bad}, **extra), BOX)
    assert e.value.where == where and "0.12 x 0.13 x 0.15 m" in str(e.value) and "0.2319 m" in str(e.value)
