"""MuJoCo scenes: the names of :mod:`simfab.io.mjcf_load` (loading MJCF into a :class:`Scene`),
:mod:`simfab.io.trajectory` (:class:`Trajectory`, keyframe paths) and :mod:`simfab.io.mjcf_builder`
(:class:`MJCFBuilder`, generating MJCF) in one place.
"""

from simfab.io.mjcf_builder import MJCFBuilder, format_attribute
from simfab.io.mjcf_load import (
    MAX_KEYFRAMES,
    Scene,
    geom_mesh,
    load_mjcf,
    load_model,
    mujoco_module,
    mujoco_warnings,
    numeric_config,
    torus_radii,
)
from simfab.io.trajectory import Trajectory, body_radius

__all__ = ["MAX_KEYFRAMES", "MJCFBuilder", "Scene", "Trajectory", "body_radius", "format_attribute", "geom_mesh",
           "load_mjcf", "load_model", "mujoco_module", "mujoco_warnings", "numeric_config",
           "torus_radii"]

