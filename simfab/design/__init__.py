"""Rest-shape optimization of a compliant part for a prescribed coupling behaviour.

The user states the behaviour (tight or loose grip, force bounds, no yielding, or a whole target
force profile); simfab changes the part's rest shape as little as possible until the simulated
insertion profile delivers it (thesis, "Rest Shape Optimization").

- :mod:`simfab.design.handles` - bounded biharmonic weights, linear blend skinning: X' = M_LBS T
- :mod:`simfab.design.placement` - where the handles go (displacement or spatial clustering, random)
- :mod:`simfab.design.modification` - the Laplacian editing energy E_L of the boundary
- :mod:`simfab.design.brief` - the design brief ([design] table) and its constraint penalties
- :mod:`simfab.design.anneal` - simulated annealing (seeded, exponential cooling)
- :mod:`simfab.design.gradient` - the default optimizer: a trust-region SQP on adjoint sensitivities
- :mod:`simfab.design.problem` - the design problem and the evaluation of one design (validity ->
  insertion, stopped once provably rejected -> objective); rebuilt from its scene in a worker
- :mod:`simfab.design.optimize` - the annealing loop (``optimize_anneal``), typed history rows
- :mod:`simfab.design.parallel` - speculative evaluation of proposals on worker processes
- :mod:`simfab.design.stress` - the von Mises stress averaged over a critical distance (yield)
- :mod:`simfab.design.verify` - the design on refined meshes: mesh-converged figures, corrections
- :mod:`simfab.design.outputs` - optimized part, scene, plots, history, USD, summary
- :mod:`simfab.design.study` - the handle-placement study
- :mod:`simfab.design.synthesis` - 2D -> 3D: extrusion and revolution of an optimized section
- :mod:`simfab.design.scene` - design scenes (a coupling scene with a [design] table, keep sites)
- :mod:`simfab.design.pipeline` - the entry point :func:`run` (``simfab couple optimize``,
  ``simfab.couple.optimize``): load, place, optimize, mesh check, correct -> typed :class:`DesignResult`
"""

__all__ = ["run", "DesignResult"]


def __getattr__(name: str):
    """Lazy exports: importing the package loads no solver."""
    if name in ("run", "DesignResult"):
        from simfab.design import pipeline

        return getattr(pipeline, name)
    raise AttributeError(f"module 'simfab.design' has no attribute {name!r}")
