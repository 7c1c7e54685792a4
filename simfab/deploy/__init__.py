"""Deployment of flat beam patterns by rigid inserts (thesis chapter "Buckling Behavior Design").

- :mod:`simfab.deploy.elastica`: the exact elastica (analytic reference);
- :mod:`simfab.deploy.buckling`: the elastica validation of the rod solver (direct and
  rigid-insert paths, critical load);
- :mod:`simfab.deploy.unitcell`: the four-beam unit cell deployed by a larger / smaller insert;
- :mod:`simfab.deploy.export`: USD timelines, MJCF of the deployed state, PNG previews.

Inverse design from a target surface (``simfab deploy surface``), one stage per module:

- :mod:`simfab.deploy.surface`: disk-topology targets (validation, procedural cap / saddle /
  mixed / cylinder); :mod:`simfab.deploy.scene`: the scene TOML;
- :mod:`simfab.deploy.flatten`: Boundary First Flattening (u = 0 on the boundary);
- :mod:`simfab.deploy.cuts`: cone singularities placed automatically, cut paths, BFF of the cut
  mesh, seam ties;
- :mod:`simfab.deploy.pattern`: quad layout, beams, Bezier torsional springs, the gap rule;
- :mod:`simfab.deploy.lasercut`: SVG / DXF export (mm);
- :mod:`simfab.deploy.network`: the pattern as a rod network with free inserts, deployment;
- :mod:`simfab.deploy.compare`: deviation from the target after the best rigid alignment;
- :mod:`simfab.deploy.mjcf_sim`: a MuJoCo scene of a rod network that MuJoCo simulates;
- :mod:`simfab.deploy.pipeline`, :mod:`simfab.deploy.surface_outputs`, :mod:`simfab.deploy.outputs`:
  the run and its files; :mod:`simfab.deploy.auto`: the defaults decided from the target;
- ``simfab.deploy.run`` (:func:`simfab.deploy.api.run`): the whole deployment as one call, loaded on
  first use (``import simfab.deploy`` loads no Warp or MuJoCo); ``simfab.deploy.cell``
  (:func:`simfab.deploy.api.cell`): the unit cell deployed by each insert (``simfab deploy``).
  ``simfab.deploy.surface`` stays the target-surface module (:mod:`simfab.deploy.surface`): a lazy
  alias of the same name would be shadowed by the module as soon as anything imports it.
"""

__all__ = ["run", "cell"]


def __getattr__(name: str):
    if name in ("run", "cell"):
        from simfab.deploy import api

        return getattr(api, name)
    raise AttributeError(f"module 'simfab.deploy' has no attribute {name!r}")
