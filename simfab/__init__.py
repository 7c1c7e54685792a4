"""simfab: computational fabrication design built around physics simulation.

Subpackages (imported lazily so that ``import simfab`` stays fast):

- ``simfab.io``        USD stages, MJCF scenes and trajectories, mesh loading, rendering
- ``simfab.fem``       Neo-Hookean finite elements (Warp kernels), materials, meshing
- ``simfab.contact``   IMLS signed-distance contact field (Warp)
- ``simfab.solve``     sparse linear solvers and Newton machinery
- ``simfab.coupling``  insertion simulation, deformation profiles, rest-shape optimization
- ``simfab.rods``      discrete elastic rods (Warp), elastica validation
- ``simfab.deploy``    flat-pattern deployment with rigid inserts
- ``simfab.growth``    generative support structures by space colonization
- ``simfab.crowd``     wisdom of micro-crowds: aggregation and ground truths
- ``simfab.cli``       the ``simfab`` command

Units are SI (metres, newtons, pascals) inside simfab unless a docstring says otherwise.
"""

__version__ = "0.1.0"

from simfab.errors import ConvergenceError, InputError, SimfabError  # noqa: E402,F401
