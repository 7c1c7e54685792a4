"""Generative support structures: space colonization with target attractors, skinned into
printable meshes (thesis chapter "Generative Interface Structure Design").

Python API (mirrors ``simfab grow``)::

    from simfab.growth import grow, skin
    result = grow("scenes/growth/phone_stand.xml", seed=0, attractors=2000)
    mesh = skin(result)            # trimesh.Trimesh, watertight, objects carved out
    result.summary()               # targets reached, nodes, segments, timings

    from simfab.growth import check, edit, run
    res = run("scenes/growth/phone_stand.xml", out="out/phone", check=True)   # GrowthResult
    res.check.safety_factor, res.to_json()                                     # the --json object
    check("out/phone/phone_stand_skeleton.json", loads={"target_0": (0, 0, -2)})  # CheckResult
    edit("out/phone/phone_stand_skeleton.json", stroke="stroke.json", camera="camera.json")  # EditResult

Modules: :mod:`~simfab.growth.config` (parameters, TOML), :mod:`~simfab.growth.scene`
(MJCF scenes), :mod:`~simfab.growth.attractors`, :mod:`~simfab.growth.obstacles`,
:mod:`~simfab.growth.colonize` (the growth algorithm), :mod:`~simfab.growth.skeleton`
(pruning, smoothing, radii), :mod:`~simfab.growth.skinning`, :mod:`~simfab.growth.sketch`
(sketch edits), :mod:`~simfab.growth.structure` (structural check, strengthening, buckling;
imported on its own: it loads the FEM), :mod:`~simfab.growth.outputs` (files).
"""

from simfab.growth.config import GrowthSceneConfig, ProfileConfig, SymmetryConfig
from simfab.growth.pipeline import Growth, grow, skin_result
from simfab.growth.results import CheckResult, EditResult, GrowthResult, StrengthenedResult
from simfab.growth.scene import GrowthScene, load_growth_scene
from simfab.growth.skeleton import Skeleton, smooth_positions
from simfab.growth.sketch import Camera, edit_chain
from simfab.growth.workflow import check, edit, run


def skin(result: Growth, **kw):
    """Skin of a :class:`Growth` as a watertight ``trimesh.Trimesh`` (objects carved out).

    Use :func:`skin_result` for the checks and timing as well.

    Args:
        result: the growth.
        **kw: ``segments`` (joint-sphere resolution), ``subtract`` (carve the objects).

    Returns:
        The skin, a ``trimesh.Trimesh`` in metres.
    """
    return skin_result(result, **kw)[0]


__all__ = ["GrowthSceneConfig", "ProfileConfig", "SymmetryConfig", "Growth", "grow", "skin", "skin_result", "run",
           "check", "edit", "GrowthResult", "CheckResult", "StrengthenedResult", "EditResult",
           "GrowthScene", "load_growth_scene", "Skeleton", "smooth_positions", "Camera", "edit_chain"]
