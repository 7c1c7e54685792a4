"""Discrete elastic rods (Bergou et al. 2008) in Warp, float64, with rigid bodies.

- :mod:`simfab.rods.model`: :class:`Material`, :class:`Section`, :class:`NetworkBuilder`,
  :class:`RodModel` (immutable) and :class:`RodState`;
- :mod:`simfab.rods.stretch`, :mod:`simfab.rods.bend`, :mod:`simfab.rods.twist`: one Warp
  kernel per energy (energy, gradient, Hessian side by side), batched over all rods;
- :mod:`simfab.rods.energy`: the sparse full-DOF evaluator;
- :mod:`simfab.rods.statics`: static equilibrium (Newton) with rigid bodies, quasi-static
  driving, loads and the stability (critical load) test.

Importing this package initializes Warp (kept out of ``import simfab``).
"""

import warp as _warp

# Warp 1.19 ignores ``config.quiet`` (used by simfab._warp) and prints its start-up banner and
# module-load lines on stdout, which would corrupt ``--json`` output; its log level governs them.
if getattr(_warp.config, "log_level", None) is not None and hasattr(_warp, "LOG_WARNING"):
    _warp.config.log_level = max(_warp.config.log_level, _warp.LOG_WARNING)

from simfab.rods.model import Material, NetworkBuilder, RodModel, RodState, Section  # noqa: F401
