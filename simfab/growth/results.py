"""Typed results of :func:`simfab.growth.run`, :func:`simfab.growth.check` and
:func:`simfab.growth.edit` (the ``--json`` keys of ``simfab grow``, ``simfab grow check`` and
``simfab grow edit``; units in the field metadata)."""

from __future__ import annotations

import dataclasses

from simfab.results import Result, field


@dataclasses.dataclass(frozen=True, kw_only=True)
class CheckResult(Result):
    """Structural check of one support (:mod:`simfab.growth.structure`): figures, per-target
    contacts and loads, the supported objects' masses, and the files written (``check_usd``,
    ``check_png``; None without ``out``). ``skeleton`` / ``scene``: the files checked (None when
    checked right after growing)."""

    skeleton: str | None = None
    scene: str | None = None
    safety_factor: float = field(unit="-")
    max_von_mises_Pa: float = field(unit="Pa")
    peak_point_m: list = field(unit="m")
    max_point_von_mises_Pa: float = field(unit="Pa")
    deflection_m: dict = field(unit="m")
    max_deflection_m: float = field(unit="m")
    mass_kg: float = field(unit="kg")
    volume_m3: float = field(unit="m³")
    material: str
    yield_stress_Pa: float = field(unit="Pa")
    critical_distance_m: float = field(unit="m")
    target_forces_N: dict = field(unit="N")
    targets: dict
    supported_objects: dict
    dropped_weight_N: dict = field(unit="N")
    mesher: str
    tets: int
    fem_nodes: int
    seconds_check: float = field(unit="s")
    check_usd: str | None = None
    check_png: str | None = None
    buckling_factor: float | None = field(unit="-", default=None)
    strengthened: StrengthenedResult | None = None
    structure: object = field(json=False, default=None)
    """The :class:`simfab.growth.structure.StructureCheck` (model, displacements, stresses)."""


@dataclasses.dataclass(frozen=True, kw_only=True)
class StrengthenedResult(CheckResult):
    """The strengthened design's check plus the strengthening's figures and files."""

    target_safety_factor: float = field(unit="-")
    reached: bool
    checks: int
    safety_factor_before: float = field(unit="-")
    safety_factor_after: float = field(unit="-")
    volume_before_m3: float = field(unit="m³")
    volume_after_m3: float = field(unit="m³")
    volume_change: float = field(unit="-")
    skeleton_json: str | None = None
    skin_stl: str | None = None
    skeleton_strengthened: object = field(json=False, default=None)
    """The strengthened :class:`simfab.growth.skeleton.Skeleton`."""


@dataclasses.dataclass(frozen=True, kw_only=True)
class GrowthResult(Result):
    """One ``simfab grow`` run: growth, skin and (with ``check``) the structural check; the
    output paths are None without ``out``."""

    scene: str
    mode: str
    symmetric: bool
    seed: int
    attractors: int
    influence: float = field(unit="m")
    kill: float = field(unit="m")
    branch_length: float = field(unit="m")
    steps: int
    stop_reasons: list
    targets_total: int
    targets_reached: int
    targets_unreached: list
    nodes: int
    segments: int
    nodes_grown: int
    collisions_resolved: int
    collisions_unresolved: int
    dead_ends: int
    dropped_oscillating: int
    seconds_growth: float = field(unit="s")
    watertight: bool
    is_volume: bool
    bodies: int
    volume: float = field(unit="m³")
    nodes_in_skin: int
    overlap_volume: float = field(unit="m³")
    penetration: float = field(unit="m")
    skin_attempts: int
    objects_subtracted: list
    objects_not_manifold: list
    seconds_skin: float = field(unit="s")
    skin_stl: str | None = None
    skin_ply: str | None = None
    skeleton_json: str | None = None
    usd: str | None = None
    mjcf: str | None = None
    png: str | None = None
    camera_json: str | None = None
    skin_units: str
    check: CheckResult | None = None
    growth: object = field(json=False, default=None)
    """The :class:`simfab.growth.pipeline.Growth` (scene, skeletons, attractors, history)."""
    mesh: object = field(json=False, default=None)
    """The skin (``trimesh.Trimesh``, metres)."""


@dataclasses.dataclass(frozen=True, kw_only=True)
class EditResult(Result):
    """One sketch edit (``simfab grow edit``): the moved chain, the edited skeleton's size, its
    skin's checks and the files written (None without ``out``). ``to_json()`` is the ``--json``
    object (without ``outputs``; ``segments_colliding`` only when the skeleton's scene was read)."""

    chain: int
    """Index of the moved chain (:func:`simfab.growth.sketch.skeleton_chains`)."""
    nodes_moved: int
    nodes_kept_for_collisions: int
    max_move: float = field(unit="m")
    segments_colliding: int | None = None
    """Segments of the edited skeleton crossing an object (None: no scene to test against)."""
    nodes: int
    segments: int
    watertight: bool
    bodies: int
    volume: float = field(unit="m³")
    skin_units: str
    skeleton_json: str | None = None
    skin_stl: str | None = None
    skin_ply: str | None = None
    png: str | None = None
    skeleton: object = field(json=False, default=None)
    """The edited :class:`simfab.growth.skeleton.Skeleton`."""
    mesh: object = field(json=False, default=None)
    """Its skin (``trimesh.Trimesh``, metres)."""

    def to_json(self) -> dict:
        """The ``--json`` object of ``simfab grow edit``."""
        d = super().to_json()
        d.pop("outputs")
        if d["segments_colliding"] is None:
            del d["segments_colliding"]
        return d
