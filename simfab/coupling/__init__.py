"""Compliant coupling: quasi-static insertion of a rigid object O into a compliant part A.

- :mod:`simfab.coupling.scene` - scenes (MJCF + companion TOML) -> :class:`CouplingModel`
- :mod:`simfab.coupling.simulate` - the insertion loop (predictor, barrier Newton, refinement)
- :mod:`simfab.coupling.profile` - deformation-profile analysis (E_max, E_ss, category, forces)
- :mod:`simfab.coupling.outputs` - CSV/JSON profile, plot, USD stage, MJCF for the viewer
- :mod:`simfab.coupling.geometry` - procedural parts of the bundled scenes
"""
