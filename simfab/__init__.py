"""simfab: computational fabrication design built around physics simulation.

Scripting API (each a function returning a typed, frozen result with ``to_json()``; files are
written only when ``out`` is given; imported lazily, so ``import simfab`` loads no solver):

- ``simfab.grow.run(scene)``, ``simfab.grow.check(skeleton)``   support structures (space colonization)
- ``simfab.couple.simulate(scene, friction=...)``              insertion of a rigid object into a compliant part
- ``simfab.couple.optimize(scene, ...)``                       rest-shape design for a coupling brief
- ``simfab.deploy.surface(target, ...)``                       flat-pattern deployment with rigid inserts
- ``simfab.validate.buckling(...)``                            discrete elastic rods vs the exact elastica
- ``simfab.crowd.aggregate(ratings, scale=...)``, ``simfab.crowd.study(...)``   wisdom of micro-crowds

Subpackages: ``io`` (USD, MJCF, meshes), ``fem`` (Neo-Hookean elements, Warp), ``contact`` (IMLS
contact field), ``solve`` (sparse solvers, Newton), ``coupling`` (insertion, profiles), ``design``
(rest-shape optimization), ``rods`` (discrete elastic rods), ``deploy`` (deployment), ``growth``
(support structures), ``crowd`` (aggregation, ground truths), ``sweep`` (Dask parameter sweeps),
``verification`` (reference checks), ``results`` (the typed-result base), ``cli`` (the ``simfab``
command). Each area's ``run`` is ``simfab.<area>.run(scene_or_path, *, out=None, seed=0,
device="cpu", progress=None, **overrides)``.

Units are SI (metres, newtons, pascals) inside simfab unless a docstring says otherwise.
"""

from simfab._version import __version__  # noqa: F401
from simfab.errors import ConvergenceError, InputError, SimfabError  # noqa: F401

#: The top-level convenience modules, imported on first use.
_LAZY = ("grow", "couple", "deploy", "validate", "crowd")


def __getattr__(name: str):
    """``simfab.couple`` etc. without importing them (or any solver) at ``import simfab``."""
    if name == "grow":
        import simfab.grow as module

        return module
    if name == "couple":
        import simfab.couple as module

        return module
    if name == "deploy":
        import simfab.deploy as module

        return module
    if name == "validate":
        import simfab.validate as module

        return module
    if name == "crowd":
        import simfab.crowd as module

        return module
    raise AttributeError(f"module 'simfab' has no attribute {name!r}")
