"""Discrete elastic rods (Bergou et al. 2008) in Warp, float64, with rigid bodies.

- :mod:`simfab.rods.model`: :class:`RodMaterial`, :class:`Section`, :class:`NetworkBuilder`,
  :class:`RodModel` (immutable) and :class:`RodState`;
- :mod:`simfab.rods.stretch`, :mod:`simfab.rods.bend`, :mod:`simfab.rods.twist`: one Warp
  kernel per energy (energy, gradient, Hessian side by side), batched over all rods;
- :mod:`simfab.rods.energy`: the sparse full-DOF evaluator;
- :mod:`simfab.rods.statics`: static equilibrium (Newton) with rigid bodies, quasi-static
  driving, loads and the stability (critical load) test.

Importing this package initializes Warp (kept out of ``import simfab``).
"""

import simfab._warp  # noqa: F401  (quiet Warp initialization, shared by all kernel modules)
from simfab.rods.model import NetworkBuilder, RodMaterial, RodModel, RodState, Section  # noqa: F401
