"""Wisdom of micro-crowds: aggregate small crowds' ratings of candidate designs.

Functions (typed results, files only with ``out``; :mod:`simfab.crowd.pipeline`):
``simfab.crowd.aggregate(ratings, scale=(1, 10), truth=...)`` (also ``run``), ``study``,
``synthesize``; ``simfab.crowd.pipeline.truth`` and ``.bracket`` (modules of those names exist here).
Modules (this package imports nothing heavy):

- :mod:`simfab.crowd.data` -- long-form ratings (``worker, task, label``) and truth CSVs, validated.
- :mod:`simfab.crowd.aggregators` -- arithmetic/geometric mean, median, majority vote.
- :mod:`simfab.crowd.model` -- the Bayesian expertise/difficulty model's log densities.
- :mod:`simfab.crowd.sampler` -- blocked Metropolis-within-Gibbs over batches of crowds
  (Warp kernel in :mod:`simfab.crowd._kernels`, numpy reference).
- :mod:`simfab.crowd.analysis` -- one crowd, every aggregator, scored against truth.
- :mod:`simfab.crowd.diagnostics` -- rank-normalized split R-hat and bulk ESS.
- :mod:`simfab.crowd.synth` -- synthetic crowds drawn from the model.
- :mod:`simfab.crowd.metrics` -- RMS errors and percentile ranks.
- :mod:`simfab.crowd.microcrowd` -- the micro-crowd (sub-crowd size) study.
- :mod:`simfab.crowd.pipeline` -- the actions above as functions with typed results.
- :mod:`simfab.crowd.truth` -- computed ground truths: support volume, overhang area.
- :mod:`simfab.crowd.bracket` -- bracket strength (FEM tip deflection) of 2D designs.
- :mod:`simfab.crowd.plots` -- study plot and expert-network figure.
- :mod:`simfab.crowd.survey` -- the bundled 3D-printing survey example.

Scales: ratings live on an integer survey scale ``[lo, hi]`` (e.g. 1..10); the model and all
RMS figures work on the unit scale ``(label - lo) / (hi - lo)`` in [0, 1], as the thesis does.
"""

_EXPORTS = ("run", "aggregate", "study", "synthesize", "AggregateResult", "StudyResult", "TruthResult",
            "SynthResult", "BracketResult")
__all__ = list(_EXPORTS)


def __getattr__(name: str):
    """Lazy exports of :mod:`simfab.crowd.pipeline` (importing the package loads no sampler)."""
    if name in _EXPORTS:
        from simfab.crowd import pipeline

        return getattr(pipeline, name)
    raise AttributeError(f"module 'simfab.crowd' has no attribute {name!r}")
