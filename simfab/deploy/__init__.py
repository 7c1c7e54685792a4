"""Deployment of flat beam patterns by rigid inserts (thesis chapter "Buckling Behavior Design").

- ``simfab.deploy.run`` (:func:`simfab.deploy.api.run`): a target surface deployed, as one call
  (``simfab deploy surface``); ``simfab.deploy.cell`` (:func:`simfab.deploy.api.cell`): the unit
  cell deployed by each insert (``simfab deploy``). Both load on first use: ``import simfab.deploy``
  loads no Warp or MuJoCo.
- Validation: :mod:`~simfab.deploy.elastica` (the exact elastica), :mod:`~simfab.deploy.buckling`
  (the rod solver against it), :mod:`~simfab.deploy.unitcell` (the four-beam cell),
  :mod:`~simfab.deploy.export` (USD, MJCF, PNG of a deployment).
- Inverse design from a target surface, one stage per module: :mod:`~simfab.deploy.surface`
  (targets) and :mod:`~simfab.deploy.scene` (the scene TOML); :mod:`~simfab.deploy.flatten` (BFF);
  :mod:`~simfab.deploy.cuts` (cones, cuts, seam ties); :mod:`~simfab.deploy.quadmesh` (quad meshes
  of the flat domain) and :mod:`~simfab.deploy.pattern` (beams, inserts, springs, the gap rule;
  :mod:`~simfab.deploy.springs`); :mod:`~simfab.deploy.lasercut` (SVG / DXF);
  :mod:`~simfab.deploy.network` (the rod network, deployment); :mod:`~simfab.deploy.tuning` (gap
  tuning); :mod:`~simfab.deploy.compare` (deviation); :mod:`~simfab.deploy.mjcf_sim` (a MuJoCo
  scene that simulates it); :mod:`~simfab.deploy.pipeline`, :mod:`~simfab.deploy.surface_outputs`,
  :mod:`~simfab.deploy.outputs` (the run and its files); :mod:`~simfab.deploy.auto` (the defaults
  decided from the target).
- ``simfab.deploy.surface`` stays the target-surface module: a lazy alias of that name would be
  shadowed by the module as soon as anything imports it.
"""

__all__ = ["run", "cell"]


def __getattr__(name: str):
    if name in ("run", "cell"):
        from simfab.deploy import api

        return getattr(api, name)
    raise AttributeError(f"module 'simfab.deploy' has no attribute {name!r}")
