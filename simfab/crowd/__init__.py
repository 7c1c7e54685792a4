"""Wisdom of micro-crowds: aggregate small crowds' ratings of candidate designs.

Modules (import them directly; this package imports nothing heavy):

- :mod:`simfab.crowd.data` -- long-form ratings (``worker, task, label``) and truth CSVs, validated.
- :mod:`simfab.crowd.aggregate` -- arithmetic/geometric mean, median, majority vote.
- :mod:`simfab.crowd.model` -- the Bayesian expertise/difficulty model's log densities.
- :mod:`simfab.crowd.sampler` -- blocked Metropolis-within-Gibbs over batches of crowds
  (Warp kernel in :mod:`simfab.crowd._kernels`, numpy reference).
- :mod:`simfab.crowd.analysis` -- one crowd, every aggregator, scored against truth.
- :mod:`simfab.crowd.diagnostics` -- rank-normalized split R-hat and bulk ESS.
- :mod:`simfab.crowd.synth` -- synthetic crowds drawn from the model.
- :mod:`simfab.crowd.metrics` -- RMS errors and percentile ranks.
- :mod:`simfab.crowd.study` -- the micro-crowd (sub-crowd size) study.
- :mod:`simfab.crowd.truth` -- computed ground truths: support volume, overhang area.
- :mod:`simfab.crowd.bracket` -- bracket strength (FEM tip deflection) of 2D designs.
- :mod:`simfab.crowd.plots` -- study plot and expert-network figure.
- :mod:`simfab.crowd.survey` -- the bundled 3D-printing survey example.

Scales: ratings live on an integer survey scale ``[lo, hi]`` (e.g. 1..10); the model and all
RMS figures work on the unit scale ``(label - lo) / (hi - lo)`` in [0, 1], as the thesis does.
"""
