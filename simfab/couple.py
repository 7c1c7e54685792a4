"""``simfab.couple``: the ``simfab couple`` command as functions.

    import simfab
    r = simfab.couple.simulate("cclamp2d", friction=0.3)
    r.profile.F_in, r.profile.to_pandas()
    d = simfab.couple.optimize("block2d_tight", iterations=20)
    c = simfab.couple.converge("cclamp2d", factors=(0.5, 1, 2))
    c.figures["F_in"].extrapolated, c.error_of_default["F_in"]

:func:`simulate` is :func:`simfab.coupling.run` (one insertion, typed
:class:`~simfab.coupling.insertion.CouplingResult`); :func:`optimize` is :func:`simfab.design.run`
(the rest-shape design, typed :class:`~simfab.design.pipeline.DesignResult`); :func:`converge` is
:func:`simfab.coupling.converge.convergence_study` (a mesh-convergence study, typed
:class:`~simfab.coupling.converge.ConvergenceResult`).
"""

from __future__ import annotations

__all__ = ["simulate", "optimize", "converge"]


def simulate(scene, *, out=None, seed: int = 0, device: str = "cpu", progress: bool | None = None, **overrides):
    """Simulate inserting a coupling scene's object into its compliant part.

    Args:
        scene: NAME.xml (with NAME.toml) or a bundled scene's name.
        out: folder for the outputs (CSV, JSON, PNG, USD, MJCF); None writes nothing.
        seed: no effect, kept for the common signature (the insertion is deterministic; a 3D mesh
            object's surface sampling takes the scene's ``[object] seed``: ``object={"seed": 3}``).
        device: Warp device.
        progress: True shows log lines and progress bars.
        **overrides: scene options, e.g. ``friction=0.3``, ``steps=8``, ``element_order=2``
            (:func:`simfab.coupling.insertion.scene_overrides`).

    Returns:
        A :class:`simfab.coupling.insertion.CouplingResult`.
    """
    from simfab.coupling.insertion import run

    return run(scene, out=out, seed=seed, device=device, progress=progress, **overrides)


def optimize(scene, *, out=None, seed: int = 0, device: str = "cpu", progress: bool | None = None, **overrides):
    """Optimize a design scene's rest shape for its design brief.

    Args:
        scene: a coupling scene with a [design] table (path or bundled name).
        out: folder for the optimized part, scene, plots, history and summary; None writes nothing.
        seed: seed of the handle placement and the annealing.
        device: Warp device.
        progress: True shows log lines and progress bars.
        **overrides: brief entries (``iterations=40``, ``grip="tight"``), scene options (``friction=0.3``,
            ``steps=8``) and run options (``method``, ``mesh_check``, ``restarts``, ...) of :func:`simfab.design.run`.

    Returns:
        A :class:`simfab.design.pipeline.DesignResult`.
    """
    from simfab.design.pipeline import run

    return run(scene, out=out, seed=seed, device=device, progress=progress, **overrides)


def converge(scene, *, factors=(0.25, 0.5, 1.0, 1.5), out=None, seed: int = 0, device: str = "cpu",
             progress: bool | None = None, **overrides):
    """Run a mesh-convergence study of a coupling scene: the profile figures at meshes refined by each
    factor of the scene's element count, their extrapolated values and the error of the scene's own mesh.

    Args:
        scene: NAME.xml (with NAME.toml) or a bundled scene's name.
        factors: refinement factors of the scene's element count (at least two, positive).
        out: folder for the JSON report, CSV and plot; None writes nothing.
        seed: no effect, kept for the common signature (the runs are deterministic).
        device: Warp device.
        progress: True shows log lines and progress bars.
        **overrides: scene options at every level, e.g. ``friction=0.3``, ``element_order=2``
            (:func:`simfab.coupling.insertion.scene_overrides`).

    Returns:
        A :class:`simfab.coupling.converge.ConvergenceResult`.

    Raises:
        InputError: fewer than two factors or a factor that is not positive; an unknown override.
    """
    from simfab._warp import device as check_device  # quiet Warp initialization
    from simfab.coupling.converge import convergence_study
    from simfab.coupling.insertion import scene_overrides
    from simfab.design.scene import check_brief_table
    from simfab.errors import InputError

    del seed  # no effect (see Args)
    factors = tuple(float(f) for f in factors)
    if len(factors) < 2 or not min(factors) > 0:
        raise InputError(f"give at least two positive factors, got {factors}", where="factors")
    check_brief_table(scene)  # the scene's [design] table, though the study does not read it
    return convergence_study(scene, factors, overrides=scene_overrides(overrides), quiet=not progress, out=out,
                             device=check_device(device))
