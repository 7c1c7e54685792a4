"""Typed results of :func:`simfab.growth.run`, :func:`simfab.growth.check` and
:func:`simfab.growth.edit` (the ``--json`` keys of ``simfab grow``, ``simfab grow check`` and
``simfab grow edit``; units in the field metadata)."""

from __future__ import annotations

import dataclasses

from simfab.results import Result, field


@dataclasses.dataclass(frozen=True, kw_only=True)
class CheckResult(Result):
    """Structural check of one support (:mod:`simfab.growth.structure`): figures, per-target
    contacts and loads, the supported objects' masses, and the files written.

    Args:
        skeleton, scene: the files checked (None when checked right after growing).
        safety_factor: yield stress / max_von_mises_Pa [-].
        max_von_mises_Pa: the peak of the critical-distance mean of the von Mises stress [Pa].
        peak_point_m: (3,) where that peak is [m].
        max_point_von_mises_Pa: the largest element-corner von Mises stress, unaveraged [Pa].
        deflection_m: load point name -> magnitude of the mean displacement of its facets [m].
        max_deflection_m: the largest of those [m].
        mass_kg, volume_m3: the support's mass [kg] and volume [m³].
        material: the material's name; yield_stress_Pa: its yield stress [Pa].
        critical_distance_m: the radius the stress is averaged over [m].
        target_forces_N: load point -> the force on it (3,) [N].
        targets: load point -> object, touching, gap_m [m], contact_area_m2 [m²], min_contact_area_m2 [m²],
            load_N [N].
        supported_objects: object -> mass_kg [kg], mass_source, weight_N [N], carried_by (load points).
        dropped_weight_N: object -> weight without a load path [N] (``best_effort`` only).
        mesher: the tet mesher used ("gmsh" or a fallback); tets, fem_nodes: the P2 mesh's sizes.
        seconds_check: wall time of skin, mesh, solve and stress [s].
        check_usd, check_png: the stress stage and picture written (None without ``out``).
        buckling_factor: the critical-load factor of the linear buckling analysis [-] (None unless asked).
        strengthened: the strengthened design's check (None unless asked).
        structure: the :class:`simfab.growth.structure.StructureCheck` (model, displacements, stresses).
        outputs: label -> path of the files written.
    """

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
    """The strengthened design's check (the :class:`CheckResult` fields) plus the strengthening's
    figures and files.

    Args:
        target_safety_factor: the safety factor asked for [-]; reached: whether the final one is at least it.
        checks: structural checks run (the first the input's).
        safety_factor_before, safety_factor_after: of the input and of the final design [-].
        volume_before_m3, volume_after_m3: the support's volume before and after [m³].
        volume_change: volume_after / volume_before - 1 [-].
        skeleton_json, skin_stl: the strengthened skeleton and skin written (None without ``out``).
        skeleton_strengthened: the strengthened :class:`simfab.growth.skeleton.Skeleton`.
    """

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
    """One ``simfab grow`` run: growth, skin and (with ``check``) the structural check.

    Args:
        scene: the scene's path or name; mode: the growth mode; symmetric: mirror symmetry used; seed: the seed.
        attractors: random attractors placed (both halves when symmetric).
        influence, kill, branch_length: the space-colonization distances used [m].
        steps: growth steps; stop_reasons: why each stage stopped.
        targets_total, targets_reached: target counts; targets_unreached: their names.
        nodes, segments: the final skeleton's size; nodes_grown: nodes of the unpruned tree.
        collisions_resolved, collisions_unresolved, dead_ends, dropped_oscillating: obstacle-avoidance counts.
        seconds_growth: wall time of placement, colonization, pruning and smoothing [s].
        watertight, is_volume, bodies: the skin's checks (after an STL round trip).
        volume: the skin's volume [m³]; overlap_volume: skin ∩ objects [m³].
        nodes_in_skin: skeleton nodes inside the skin.
        penetration: the deepest skin vertex inside an object that was not carved [m].
        skin_attempts: skins built until one passed the round trip.
        objects_subtracted, objects_not_manifold: objects carved out of the skin / skipped.
        seconds_skin: the skin's wall time [s].
        skin_stl, skin_ply, skeleton_json, usd, mjcf, png, camera_json: the files written (None without ``out``).
        skin_units: the length unit of the skin files.
        check: the structural check (None without ``check``).
        growth: the :class:`simfab.growth.pipeline.Growth` (scene, skeletons, attractors, history).
        mesh: the skin (``trimesh.Trimesh``, metres).
        outputs: label -> path of the files written.
    """

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
    skin's checks and the files written. ``to_json()`` is the ``--json`` object (without
    ``outputs``; ``segments_colliding`` only when the skeleton's scene was read).

    Args:
        chain: index of the moved chain (:func:`simfab.growth.sketch.skeleton_chains`).
        nodes_moved: nodes the stroke moved; nodes_kept_for_collisions: nodes held back to avoid an object.
        max_move: the largest node displacement [m].
        segments_colliding: segments of the edited skeleton crossing an object (None: no scene to test against).
        nodes, segments: the edited skeleton's size.
        watertight, bodies: its skin's checks; volume: the skin's volume [m³]; skin_units: the skin files' unit.
        skeleton_json, skin_stl, skin_ply, png: the files written (None without ``out``).
        skeleton: the edited :class:`simfab.growth.skeleton.Skeleton`; mesh: its skin (``trimesh.Trimesh``, metres).
        outputs: label -> path of the files written.
    """

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
        """The ``--json`` object of ``simfab grow edit``.

        Returns:
            A dict of JSON values (no ``outputs``).
        """
        d = super().to_json()
        d.pop("outputs")
        if d["segments_colliding"] is None:
            del d["segments_colliding"]
        return d
