"""``simfab.grow``: the ``simfab grow`` command as functions.

    import simfab
    r = simfab.grow.run("phone_stand")       # grow a support structure (typed result)
    c = simfab.grow.check("skeleton.json")   # check a grown skeleton
    e = simfab.grow.edit("skeleton.json", stroke="stroke.json", camera="camera.json")  # sketch edit

They forward to :func:`simfab.growth.run`, :func:`simfab.growth.check` and :func:`simfab.growth.edit`.
"""

from __future__ import annotations

__all__ = ["run", "check", "edit"]


def run(scene, *, check: bool = False, out=None, seed: int = 0, device: str = "cpu", progress: bool | None = None,
        **overrides):
    """Grow a support structure for a growth scene (and with ``check`` check it).

    Args:
        scene: a growth scene: its MJCF path or a bundled name (``"phone_stand"``).
        check: also run the structural check of the grown structure.
        out: output folder; None writes nothing.
        seed: the growth's seed.
        device: Warp device.
        progress: True shows log lines and progress bars.
        **overrides: scene parameters (see :func:`simfab.growth.run`).

    Returns:
        The growth area's typed result.
    """
    from simfab.growth import run as grow_run

    return grow_run(scene, check=check, out=out, seed=seed, device=device, progress=progress, **overrides)


def check(skeleton, **kwargs):
    """Check a grown skeleton (:func:`simfab.growth.check`).

    Args:
        skeleton: the skeleton file (or object) to check.
        **kwargs: passed to :func:`simfab.growth.check` (``out``, ``seed``, ``device``, ``progress``, ...).

    Returns:
        The check's typed result.
    """
    from simfab.growth import check as grow_check

    return grow_check(skeleton, **kwargs)


def edit(skeleton, **kwargs):
    """Sketch edit of a grown skeleton (:func:`simfab.growth.edit`).

    Args:
        skeleton: the skeleton file (or object) to edit.
        **kwargs: passed to :func:`simfab.growth.edit` (``stroke``, ``camera``, ``chain``, ``out``, ...).

    Returns:
        The edit's typed result.
    """
    from simfab.growth import edit as grow_edit

    return grow_edit(skeleton, **kwargs)
