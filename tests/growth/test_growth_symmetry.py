"""Mirror-symmetric growth."""

import numpy as np
import pytest

from simfab.errors import InputError
from simfab.growth import grow, load_growth_scene


def _mirror_distance(nodes, p0, n):
    R = nodes - 2.0 * ((nodes - p0) @ n)[:, None] * n
    from scipy.spatial import cKDTree

    d, _ = cKDTree(nodes).query(R)
    return d.max()


@pytest.mark.parametrize("seed", [0, 1])
def test_symmetric_scene_gives_a_mirror_symmetric_skeleton(scenes_dir, seed):
    r = grow(scenes_dir / "symmetric_stand.xml", seed=seed)
    assert r.symmetric
    sk = r.skeleton
    assert _mirror_distance(sk.nodes, np.zeros(3), np.array([1.0, 0, 0])) < 1e-12
    # the split root: two roots nudged to either side of the plane, within r_max (halves fuse)
    roots = sk.nodes[sk.parent < 0]
    assert len(roots) == 2
    assert roots[0][0] == pytest.approx(-roots[1][0], abs=1e-15) and 0 < abs(roots[0][0]) < r.resolved.r_max
    # radii mirror too; segments map onto segments
    E = {tuple(sorted(map(tuple, np.round(sk.nodes[e], 12)))) for e in sk.edges}
    R = sk.nodes * np.array([-1.0, 1, 1])
    E2 = {tuple(sorted(map(tuple, np.round(R[e], 12)))) for e in sk.edges}
    assert E == E2


def test_symmetric_flag_on_a_plain_scene(scenes_dir):
    # egg holder targets are mirror pairs about x = 0 (the plane through the root)
    plain = grow(scenes_dir / "egg_holder_volume.xml", seed=0)
    sym = grow(scenes_dir / "egg_holder_volume.xml", seed=0, symmetric=True)
    assert not plain.symmetric and sym.symmetric
    assert _mirror_distance(plain.skeleton.nodes, np.zeros(3), np.array([1.0, 0, 0])) > 1e-3
    assert _mirror_distance(sym.skeleton.nodes, np.zeros(3), np.array([1.0, 0, 0])) < 1e-12
    assert sym.summary()["targets_reached"] == 4


def test_asymmetric_targets_are_rejected(scenes_dir):
    scene = load_growth_scene(scenes_dir / "phone_stand.xml")
    from simfab.growth.config import SymmetryConfig

    with pytest.raises(InputError, match="mirror-symmetric"):
        grow(scene, symmetry=SymmetryConfig(point=(0.01, 0, 0), normal=(1.0, 0, 0)))
