"""Compliant coupling: quasi-static insertion of a rigid object O into a compliant part A.

``simfab.coupling.run(scene, ...)`` simulates a scene and returns a typed
:class:`~simfab.coupling.insertion.CouplingResult` (figures with units, the typed profile, the run);
``simfab.couple.simulate`` is the same from the top level.

- :mod:`simfab.coupling.insertion` - :func:`run` and :class:`CouplingResult` (one insertion run)
- :mod:`simfab.coupling.scene` - scenes (MJCF + companion TOML) -> :class:`CouplingModel`
- :mod:`simfab.coupling.simulate` - the insertion loop (predictor, barrier Newton, refinement)
- :mod:`simfab.coupling.profile` - deformation-profile analysis (E_max, E_ss, category, forces), :class:`Profile`
- :mod:`simfab.coupling.outputs` - CSV/JSON profile, plot, USD stage, MJCF for the viewer (``write_all``)
- :mod:`simfab.coupling.converge` - mesh-convergence study of a scene
- :mod:`simfab.coupling.geometry` - procedural parts of the bundled scenes

Rest-shape design of the part is :mod:`simfab.design`.
"""

__all__ = ["run", "CouplingResult", "Profile"]


def __getattr__(name: str):
    """Lazy exports: importing the package loads no solver."""
    if name in ("run", "CouplingResult"):
        from simfab.coupling import insertion

        return getattr(insertion, name)
    if name == "Profile":
        from simfab.coupling.profile import Profile

        return Profile
    raise AttributeError(f"module 'simfab.coupling' has no attribute {name!r}")
