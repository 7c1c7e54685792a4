"""The design brief: what behaviour the user asks of the part, and its constraint penalties.

The ``[design]`` table of a coupling scene's TOML (all optional; SI units; :class:`DesignConfig`)::

    [design]
    grip = "tight"                 # "tight" | "loose" | "any" (no coupling-ratio constraint)
    grip_force = [5.0, 40.0]       # [lo, hi] N at the steady state (inf allowed: [5.0, inf])
    insertion_force = [0.0, 20.0]  # [lo, hi] N; removal_force, hold_force alike
    yield_stress = 60e6            # Pa; default: the material's; max von Mises must stay below
    target_profile = "target.csv"  # optional: match a force profile (distance [m], force [N])
    handles = 5                    # active handles; placement = "displacement" | "spatial" | "random"
    keep = ["keep"]                # box sites whose vertices stay unchanged
    iterations = 300               # optimizer iterations at most; patience = 60 (annealing)
    max_translation = 0.25         # |t| bound per axis, fraction of the bounding-box diagonal
    scale_range = [0.5, 1.6]       # bounds of the per-axis handle scales
    stress_radius = 0.0005         # m, the von Mises stress is averaged over this radius
    correction_rounds = 2          # re-optimizations with mesh-corrected figures
    check_refinements = 1          # the mesh check's P2 refinement levels (at most 3)

Constraints (thesis, "Optimization"), each a value within [lo, hi]: the coupling ratio CR = E_ss /
E_max * 100 [%] (tight: <= 95 and > 0 with a seat clearance <= 0; loose: <= 1e-3), the grip,
insertion, removal and hold forces [N], the averaged von Mises maximum [Pa]. The objective is
E = E_L + W * sum_c max(0, c / scale_c)^2 (W = PENALTY_WEIGHT, c = lo - value or value - hi in
SCALES units: %, N, MPa, 0.1 mm). Why these units and the clearance: docs/methods.md, "simfab.design.brief".
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from simfab.coupling import config as C
from simfab.design.stress import STRESS_RADIUS
from simfab.errors import InputError
from simfab.io.companion import read_csv_numbers
from simfab.io.tables import FieldError, flag_overrides, load_table
from simfab.results import field

#: Weight of the squared, scaled constraint violations against E_L.
PENALTY_WEIGHT = 1.0e3
#: Units in which a violation counts one: percent, newtons, megapascals, 0.1 mm.
SCALES = {"coupling_ratio": 1.0, "grip_force": 1.0, "insertion_force": 1.0, "removal_force": 1.0,
          "hold_force": 1.0, "von_mises": 1.0e6, "seat_clearance": 1.0e-4}
UNITS = {"coupling_ratio": "%", "grip_force": "N", "insertion_force": "N", "removal_force": "N", "hold_force": "N",
         "von_mises": "Pa", "seat_clearance": "m"}
#: Correction rounds (simfab.design.pipeline.mesh_corrected) aim this far (relative) inside the
#: force and stress bounds: the annealer settles on a bound, and the factors measured on the checked
#: design are not those of the next design, so a design aimed at the bound itself misses it on its
#: own check about as often as not.
CORRECTION_MARGIN = 0.10
MARGIN_FIGURES = ("grip_force", "insertion_force", "removal_force", "hold_force", "von_mises")
#: The force constraints of a brief ([lo, hi] N).
FORCES = ("grip_force", "insertion_force", "removal_force", "hold_force")
#: kappa_cr of the thesis [%]: the steady state must stay this far below the peak energy.
KAPPA_TIGHT = 95.0
KAPPA_LOOSE = 1.0e-3
PLACEMENTS = ("displacement", "spatial", "random")
GRIPS = ("tight", "loose", "any")


@dataclass(frozen=True, kw_only=True)
class DesignConfig:
    """The ``[design]`` table: the design brief (see the module docstring for meanings and units).

    Args:
        grip: "tight", "loose" or "any" (no coupling-ratio constraint).
        grip_force, insertion_force, removal_force, hold_force: bounds (lo, hi) [N]; None: unconstrained.
        yield_stress: the von Mises bound [Pa]; None: the material's.
        target_profile: a force profile CSV to match (distance [m], force [N]); None: none.
        handles: active handles.
        placement: "displacement", "spatial" or "random".
        keep: box sites whose vertices stay unchanged.
        iterations: optimizer iterations at most.
        patience: annealing stops after this many iterations without improvement.
        max_translation: handle translation bound per axis, fraction of the bounding-box diagonal.
        scale_range: bounds of the per-axis handle scales.
        stress_radius: radius of the stress average [m].
        correction_rounds: re-optimizations with mesh-corrected figures.
        check_refinements: refinements of the mesh check (at most 3).
    """

    grip: str = "any"
    grip_force: tuple[float, float] | None = None
    insertion_force: tuple[float, float] | None = None
    removal_force: tuple[float, float] | None = None
    hold_force: tuple[float, float] | None = None
    yield_stress: float | None = None
    target_profile: str | None = None
    handles: int = 5
    placement: str = "displacement"
    keep: tuple[str, ...] = ()
    iterations: int = 300
    patience: int = 60
    max_translation: float = 0.25
    scale_range: tuple[float, float] = (0.5, 1.6)
    stress_radius: float = STRESS_RADIUS
    correction_rounds: int = 2
    check_refinements: int = 1

    def __post_init__(self):
        self.validate()

    @classmethod
    def from_dict(cls, d: dict, *, where: str = "[design]", overrides: dict | None = None,
                  log=None) -> "DesignConfig":
        """The brief from a ``[design]`` table (:func:`simfab.io.tables.load_table`).

        Args:
            d: the table's keys and values.
            where: ``"FILE [design]"`` (or ``"[design]"``), for messages.
            overrides: {key: value or :class:`simfab.io.tables.Override`} replacing the table's values
                (command-line options; an error names the flag an Override carries).
            log: called with a note for each flag that replaces a value of the file.

        Returns:
            The brief; InputError naming the file, table and key (or the flag) when it is refused.
        """
        file = where.rpartition(" ")[0] if where.endswith("[design]") else where
        return load_table(cls, d, table_name="design", file=file or None, overrides=overrides, parsers=PARSERS,
                          log=log)

    def validate(self, where: str = "[design]") -> None:
        """Check the values (run on construction).

        Args:
            where: the table, prefixed to each key in messages.

        Raises:
            FieldError: naming the key and what is wrong.
        """
        def bad(key, msg):
            raise FieldError(msg, key=key, where=f"{where} {key}")

        if self.grip not in GRIPS:
            bad("grip", f"grip must be one of {GRIPS}, got {self.grip!r}")
        if self.placement not in PLACEMENTS:
            bad("placement", f"placement must be one of {PLACEMENTS}, got {self.placement!r}")
        if not (isinstance(self.stress_radius, (int, float)) and not isinstance(self.stress_radius, bool)
                and 0 < self.stress_radius < 1):
            bad("stress_radius", f"must be a length in (0, 1) m, got {self.stress_radius!r}")
        for k in ("handles", "iterations", "patience", "correction_rounds", "check_refinements"):
            v = getattr(self, k)
            zero_ok = k in ("iterations", "correction_rounds", "check_refinements")
            if not isinstance(v, int) or isinstance(v, bool) or v < (0 if zero_ok else 1):
                bad(k, f"must be a {'non-negative' if zero_ok else 'positive'} integer, got {v!r}")
        if self.check_refinements > 3:
            bad("check_refinements", f"must be at most 3 (each refinement multiplies the check's elements by 4 "
                                     f"in 2D, 8 in 3D), got {self.check_refinements}")
        ys = self.yield_stress
        if ys is not None and not (isinstance(ys, (int, float)) and ys > 0):
            bad("yield_stress", f"must be a positive stress [Pa], got {ys!r}")
        if not (isinstance(self.max_translation, (int, float)) and 0 < self.max_translation <= 1):
            bad("max_translation", f"must be in (0, 1], got {self.max_translation!r}")
        lo, hi = self.scale_range
        if not 0 < lo <= 1 <= hi:
            bad("scale_range", f"must satisfy 0 < lo <= 1 <= hi, got {list(self.scale_range)}")

    def with_overrides(self, **kw) -> "DesignConfig":
        """This brief with command-line values (``None``: not given).

        Args:
            **kw: {key: value}; an error names the flag ``--key-with-dashes``.

        Returns:
            The new brief.
        """
        return self.from_dict({k: v for k, v in dataclasses.asdict(self).items() if v is not None},
                              overrides=flag_overrides(kw))


#: The brief's earlier name (``...Config`` is the package's one suffix for configuration).


def _bounds(v, where: str) -> tuple[float, float]:
    if not isinstance(v, (list, tuple)) or len(v) != 2:
        raise InputError(f"must be a pair [lo, hi], got {v!r}", where=where)
    try:
        lo, hi = float(v[0]), float(v[1])
    except (TypeError, ValueError):
        raise InputError(f"must be two numbers [lo, hi], got {v!r}", where=where) from None
    if math.isnan(lo) or math.isnan(hi) or lo > hi or lo < 0:
        raise InputError(f"need 0 <= lo <= hi, got {v!r}", where=where)
    return lo, hi


def _keep(v, where: str) -> tuple:
    return (v,) if isinstance(v, str) else tuple(str(x) for x in v) if isinstance(v, (list, tuple)) else v


#: Values read by their own functions before the type check (pairs [lo, hi] with their messages).
PARSERS = {**{k: _bounds for k in (*FORCES, "scale_range")}, "keep": _keep}


@dataclass(frozen=True, kw_only=True)
class Constraint:
    """One functional constraint ``lo <= value <= hi``; violations count in ``scale``.

    Args:
        name: the figure (a key of :data:`UNITS`).
        value: its value [unit].
        lo: lower bound [unit].
        hi: upper bound [unit].
        unit: the unit.
        scale: the violation that counts one [unit].
    """

    name: str
    value: float
    lo: float
    hi: float
    unit: str
    scale: float

    @property
    def violation(self) -> float:
        """max(0, lo - value, value - hi) / scale [-] (0 inside the bounds)."""
        return max(0.0, self.lo - self.value, self.value - self.hi) / self.scale

    @property
    def satisfied(self) -> bool:
        return self.violation == 0.0

    def report(self, *, named: bool = True, with_unit: bool = True, initial: float | None = None
               ) -> ConstraintReport:
        """The constraint as a result reports it.

        Args:
            named: include the name (False where the reports are keyed by it).
            with_unit: include the unit (False where the report's table states the units).
            initial: the initial design's value [unit], if reported.

        Returns:
            A :class:`ConstraintReport`.
        """
        return ConstraintReport(name=self.name if named else None, value=self.value, lo=self.lo, hi=self.hi,
                                unit=self.unit if with_unit else None, satisfied=self.satisfied, initial=initial)


@dataclass(frozen=True, kw_only=True)
class ConstraintReport:
    """A constraint ``lo <= value <= hi`` as a result reports it (entries that are None are left out of its JSON).

    Args:
        name: the figure (a key of :data:`UNITS`); None where the reports are keyed by it.
        value: its value [unit].
        lo: lower bound [unit].
        hi: upper bound [unit].
        unit: the unit; None where the report's table states the units.
        satisfied: ``lo <= value <= hi``.
        initial: the initial design's value [unit] (the design result's constraints).
    """

    name: str | None = field(optional=True)
    value: float
    lo: float
    hi: float
    unit: str | None = field(optional=True)
    satisfied: bool
    initial: float | None = field(optional=True)


def constraint_bounds(brief: DesignConfig, yield_stress: float | None) -> dict[str, tuple[float, float]]:
    """The brief's constraint bounds.

    Args:
        brief: the design brief.
        yield_stress: the material's yield stress [Pa] (None: no stress bound unless the brief has one).

    Returns:
        {name: (lo, hi)} in their units (see :data:`UNITS`).
    """
    out = {}
    if brief.grip == "tight":
        out["coupling_ratio"] = (100.0 * C.LOOSE_REL, KAPPA_TIGHT)
        out["seat_clearance"] = (-math.inf, 0.0)
    elif brief.grip == "loose":
        out["coupling_ratio"] = (0.0, KAPPA_LOOSE)
    for k in FORCES:
        if getattr(brief, k) is not None:
            out[k] = getattr(brief, k)
    ys = brief.yield_stress if brief.yield_stress is not None else yield_stress
    if ys is not None:
        out["von_mises"] = (0.0, float(ys))
    return out


def constraints(figures: dict, limits: dict[str, tuple[float, float]]) -> list[Constraint]:
    """Evaluate bounds on a profile's figures.

    Args:
        figures: {coupling_ratio, grip_force, insertion_force, removal_force, hold_force, von_mises,
            seat_clearance} (:func:`simfab.design.problem.profile_figures`).
        limits: {name: (lo, hi)} (:func:`constraint_bounds`).

    Returns:
        One :class:`Constraint` per bound.
    """
    return [Constraint(name=k, value=float(figures[k]), lo=lo, hi=hi, unit=UNITS[k], scale=SCALES[k])
            for k, (lo, hi) in limits.items()]


def penalty(cons: list[Constraint], margin: float = 0.0) -> float:
    """W * sum of squared scaled violations [-] (0 when every constraint holds).

    Args:
        cons: the constraints.
        margin: move the force and stress bounds (MARGIN_FIGURES) this far (relative) inside:
            lo (1 + margin), hi (1 - margin).

    Returns:
        The penalty.
    """
    return PENALTY_WEIGHT * float(sum(aimed(c, margin).violation ** 2 for c in cons))


def aimed(c: Constraint, margin: float) -> Constraint:
    """A constraint with its bounds moved inside (:func:`aimed_bounds`; see :func:`penalty`).

    Args:
        c: the constraint.
        margin: relative margin.

    Returns:
        ``c`` itself when the bounds do not move, else a copy with the moved bounds.
    """
    lo, hi = aimed_bounds(c.name, c.lo, c.hi, margin)
    return c if (lo, hi) == (c.lo, c.hi) else replace(c, lo=lo, hi=hi)


def aimed_bounds(name: str, lo: float, hi: float, margin: float) -> tuple[float, float]:
    """A constraint's bounds moved ``margin`` (relative) inside when it is a force or stress constraint.

    Args:
        name: the figure.
        lo: lower bound.
        hi: upper bound.
        margin: relative margin.

    Returns:
        (lo (1 + margin), hi (1 - margin)) for MARGIN_FIGURES, else (lo, hi).
    """
    if not margin or name not in MARGIN_FIGURES:
        return lo, hi
    return lo * (1.0 + margin), hi * (1.0 - margin)


def read_target_profile(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """A target force profile CSV (distance, force per row; an optional header; distances increasing).

    Args:
        path: the CSV file.

    Returns:
        (s (k,) [m], F (k,) [N]); InputError naming the file when it is unreadable or not increasing.
    """
    a = read_csv_numbers(path, 2, what="target profile (distance_m, force_N per row)", min_rows=2)
    if np.any(np.diff(a[:, 0]) <= 0):
        raise InputError("target profile distances must be strictly increasing", where=str(path))
    return a[:, 0], a[:, 1]


def run_to_rest(s: np.ndarray, force: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A run cut at its rest point.

    When its last two records bracket a zero crossing of the force from above (F_a > 0 >= F_b: the
    rest search's overshoot into the seat, or a planned step past it), the last record becomes the rest
    point s* = s_a + w (s_b - s_a), w = F_a / (F_a - F_b), with force 0 (where O rests;
    :func:`simfab.design.figure_gradients.rest_grip_gradient` reads the grip there too).

    Args:
        s: record positions [m].
        force: record forces [N].

    Returns:
        (s, F) cut at the rest point, or the run unchanged.
    """
    s, force = np.asarray(s, float), np.asarray(force, float)
    if len(s) < 2 or not (force[-2] > 0.0 >= force[-1]):
        return s, force
    w = force[-2] / (force[-2] - force[-1])
    return np.r_[s[:-1], s[-2] + w * (s[-1] - s[-2])], np.r_[force[:-1], 0.0]


@dataclass(frozen=True, kw_only=True)
class TargetProfile:
    """A force profile to match (resisting forces < 0).

    Args:
        s: distances (k,) [m].
        force: forces (k,) [N].
        source: the file it was read from.
    """

    s: np.ndarray
    force: np.ndarray
    source: str = ""

    def rms_error(self, s: np.ndarray, force: np.ndarray) -> float:
        """RMS force error [N] over the target's distance range, sqrt(1/L int (F_sim - F_target)^2 ds).

        Both profiles are linear between their samples (exact for that: per piece of the merged samples,
        h (e0^2 + e0 e1 + e1^2) / 3). A distance integral, not a mean over samples: a densely sampled
        stretch (the rest search's records across the seat's force jump) does not decide the error. The
        run ends where O comes to rest (:func:`run_to_rest`); past its end the force is 0, so a design that
        seats before the target does is charged for the target's forces past its seat.

        Args:
            s: the run's record positions [m].
            force: the run's forces [N].

        Returns:
            The RMS error [N] (inf for an empty run).
        """
        s, force = run_to_rest(s, force)
        if not len(s):
            return float("inf")
        t0, t1 = float(self.s[0]), float(self.s[-1])
        if not t1 > t0:
            return float(np.sqrt(np.mean((np.interp(self.s, s, force) - self.force) ** 2)))
        end = min(float(s[-1]), t1)

        def sq(grid, sim):  # int (sim - target)^2 ds over grid, both linear between grid points
            e = sim - np.interp(grid, self.s, self.force)
            return float(np.sum(np.diff(grid) * (e[:-1] ** 2 + e[:-1] * e[1:] + e[1:] ** 2)) / 3.0)

        total = 0.0
        if end > t0:
            g = np.union1d(np.union1d(self.s[self.s < end], s[(s > t0) & (s < end)]), [end])
            total += sq(g, np.interp(g, s, force))
        if end < t1:  # past the run's end: force 0
            g = np.union1d([max(end, t0)], self.s[self.s > end])
            total += sq(g, np.zeros(len(g)))
        return float(np.sqrt(total / (t1 - t0)))


__all__ = ["DesignConfig", "Constraint", "TargetProfile", "ConstraintReport", "constraint_bounds",
           "constraints", "penalty", "read_target_profile", "run_to_rest", "PENALTY_WEIGHT", "SCALES", "UNITS"]
