"""Deployment of flat beam patterns by rigid inserts (thesis chapter "Buckling Behavior Design").

- :mod:`simfab.deploy.elastica`: the exact elastica (analytic reference);
- :mod:`simfab.deploy.buckling`: the elastica validation of the rod solver (direct and
  rigid-insert paths, critical load);
- :mod:`simfab.deploy.unitcell`: the four-beam unit cell deployed by a larger / smaller insert;
- :mod:`simfab.deploy.export`: USD timelines, MJCF of the deployed state, PNG previews.
"""
