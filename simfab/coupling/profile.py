"""Deformation-profile analysis: E_max, E_ss, coupling ratio, forces and the coupling category.

Definitions (thesis, "Fundamentals and Overview"):

- E_max: the largest elastic energy along the insertion [J].
- E_ss: backtracking from the last step, the first local minimum of the energy profile; without a
  dip after the peak there is no steady state and E_ss = E_max. A path that ends in a prescribed
  pose has its steady state at that end pose (``end_pose``).
- coupling ratio = E_ss / E_max * 100 [%].
- Category: **ejects** (no dip), **loose** (E_ss <= LOOSE_REL E_max), **tight** (a dip to a non-zero
  E_ss < E_max); with friction, **held by friction** (ejects, but F_hold > 0) and **jams** (the
  insertion self-locks: O inside the friction cone of a sticking contact); **none** when O never
  touched the part (:func:`touched`): coupling ratio 100 %, the steady state at the path's end.
- Insertion force F along O's motion, resisting = negative, read up to the steady state (over the
  whole run for ejects): F_in = max(0, -min F); F_rm = max(0, max F) [N] (the insertion reversed,
  or with friction the removal records).
- F_grip: grip force at the steady state [N], interpolated to where the force crosses zero when
  the rest search brackets the crossing.
- F_hold: the force to start sliding O out of its seat, max(0, max F) over the removal records up to
  the onset of sliding (:func:`hold_force`); F_rm without friction.
- stationary: E_ss is a local minimum of the energy along the path (the energy rises after it, or
  the force there does not draw O in by more than REST_FORCE_REL of the peak force).

The reasoning behind the grip's interpolation and the hold force's onset of sliding:
docs/methods.md, "simfab.coupling.profile".
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, replace

import numpy as np

from simfab.coupling import config as C
from simfab.results import field

#: The force at a steady state at the run's end is ~0 within this fraction of the peak |force|.
REST_FORCE_REL = 1e-2
#: A profile whose peak energy is below that of a uniform strain of this size over the whole part
#: never really touched the object: its energies are round-off (a category or a steady state read
#: from them is noise, and a design cannot meet a grip constraint with a ratio of two of them).
CONTACT_STRAIN_FLOOR = 1e-5


@dataclass(frozen=True, kw_only=True)
class ProfileSummary:
    """Key figures of a deformation profile (definitions: the module docstring); :class:`Profile` adds
    the per-record arrays they were read from.

    Args:
        category: "tight", "loose", "ejects", "jams", "held by friction" or "none" (no contact).
        E_max: largest elastic energy along the insertion [J].
        E_ss: elastic energy at the steady state [J] (E_max when there is none).
        coupling_ratio: E_ss / E_max [%].
        F_in: largest force needed to push O in [N].
        F_rm: largest force needed to pull O out [N].
        F_grip: grip force at the steady state [N].
        index_max, index_ss: the insertion records of E_max and of the steady state.
        stationary: whether E_ss is a minimum of the energy along the path (not the run's end).
        F_hold: force to start sliding O out of its seat [N] (F_rm without friction).
        friction: Coulomb coefficient the profile was simulated with [-].
    """

    category: str
    E_max: float = field(unit="J")
    E_ss: float = field(unit="J")
    coupling_ratio: float = field(unit="%")
    F_in: float = field(unit="N")
    F_rm: float = field(unit="N")
    F_grip: float = field(unit="N")
    index_max: int
    index_ss: int
    stationary: bool = True
    F_hold: float = field(unit="N", default=0.0)
    friction: float = field(unit="-", default=0.0)


def steady_state_index(energy: np.ndarray, tol: float) -> int:
    """Backtrack from the end while the energy keeps decreasing (by more than ``tol``) going back;
    the index where it stops is the first local minimum seen from the end."""
    E = np.asarray(energy, float)
    k = len(E) - 1
    while k > 0 and E[k - 1] < E[k] - tol:
        k -= 1
    return k


def analyze(s: np.ndarray, energy: np.ndarray, force: np.ndarray, grip: np.ndarray, *,
            end_pose: bool = False, rest_from: int | None = None) -> ProfileSummary:
    """Summarize a profile given per-step insertion distance s [m], energy [J], force [N], grip [N].
    ``end_pose``: the path ends in a prescribed pose, where the steady state is (module docstring);
    ``rest_from``: the index of the first record of the run's search for the rest point (the records
    past the planned steps), None if there is none."""
    E = np.asarray(energy, float)
    F = np.asarray(force, float)
    G = np.asarray(grip, float)
    if E.size == 0:
        raise ValueError("empty profile")
    E_max = float(E.max())
    i_max = int(np.argmax(E))
    tol = C.ENERGY_REL_TOL * max(E_max, 0.0)
    i_ss = E.size - 1 if end_pose else steady_state_index(E, tol)
    if E_max <= 0 or i_ss <= i_max or E[i_ss] >= E_max - tol:
        category, E_ss, i_ss = "ejects", E_max, i_max
    else:
        E_ss = float(E[i_ss])
        category = "loose" if E_ss <= C.LOOSE_REL * E_max else "tight"
    ratio = 100.0 * E_ss / E_max if E_max > 0 else 100.0
    # the insertion ends at the steady state: forces past it (O pushed on into A's seat) are not
    # part of inserting or removing O
    end = len(F) if category == "ejects" else i_ss + 1
    if category != "ejects" and rest_bracket(F, i_ss, rest_from) == i_ss - 1:
        end = i_ss  # E_ss at the rest search's upper end, past the rest point: its force is the seat's push
    Fi = F[:end]
    # E_ss is a stationary point (a minimum along the path) when the energy rises again after it, or
    # the force there no longer draws O in (~0, or pushing back: a minimum at a kink, O seated); at
    # the last step with O still drawn in it is not
    scale = float(np.abs(Fi).max()) if Fi.size else 0.0
    stationary = category == "ejects" or i_ss < len(E) - 1 or F[i_ss] <= REST_FORCE_REL * scale
    grip_ss = float(G[i_ss])
    a = rest_bracket(F, i_ss, rest_from) if category != "ejects" else None
    if a is not None:
        w = F[a] / (F[a] - F[a + 1])  # the rest point, F = 0, between the two records
        grip_ss = float(G[a] + w * (G[a + 1] - G[a]))
    return ProfileSummary(
        category=category, E_max=E_max, E_ss=E_ss, coupling_ratio=ratio,
        F_in=float(max(0.0, -Fi.min())), F_rm=float(max(0.0, Fi.max())), F_grip=grip_ss,
        index_max=i_max, index_ss=i_ss, stationary=bool(stationary),
    )


def rest_bracket(force: np.ndarray, i_ss: int, rest_from: int | None = None) -> int | None:
    """The first record a of the pair (a, a + 1) whose forces bracket the rest point around the
    steady state i_ss (F_a > 0 >= F_(a+1)): a = i_ss (the next record is past it), else a = i_ss - 1
    when both are records of the rest search (index >= ``rest_from``: its bracket spans micrometres;
    a planned record's position is not a bracket of the rest point); None otherwise."""
    F = np.asarray(force, float)
    if i_ss + 1 < len(F) and F[i_ss] > 0 >= F[i_ss + 1]:
        return i_ss
    if rest_from is not None and rest_from <= i_ss - 1 and F[i_ss - 1] > 0 >= F[i_ss]:
        return i_ss - 1
    return None


#: The removal has started sliding where points carrying this fraction of the normal force slip.
SLIDING_REL = 0.99


def hold_force(force: np.ndarray, slipping: np.ndarray, F_rm: float) -> float:
    """F_hold [N] from the removal records' path forces ``force`` (r,) [N] and slipping fractions
    ``slipping`` (r,) [-] (1 where no normal force acts): max(0, max F) up to the onset of sliding,
    where the slipping fraction reaches SLIDING_REL, the force there interpolated linearly in the
    slipping fraction between the records around it (the graded turn steps double in length, so the
    record past the onset may lie well beyond it); F_rm when the contact never slides."""
    k = np.flatnonzero(slipping >= SLIDING_REL)
    if not len(k):
        return F_rm
    k = int(k[0])
    at = float(force[k])
    if k > 0 and slipping[k] > slipping[k - 1]:
        w = (SLIDING_REL - slipping[k - 1]) / (slipping[k] - slipping[k - 1])
        at = float(force[k - 1] + min(max(w, 0.0), 1.0) * (force[k] - force[k - 1]))
    return max(0.0, float(np.max(force[:k], initial=at)), at)


#: The phases of a run's records, in order: the planned insertion steps, the rest search's records
#: past the keyframes' end (its probes may overshoot the rest point), the removal (with friction).
PHASES = ("insert", "rest", "remove")


def record_phases(res) -> list[str]:
    """The phase (:data:`PHASES`) of each record of an insertion result, its steps then its removal."""
    planned = len(res.model.s_steps)
    return ["insert" if k < planned else "rest" for k in range(len(res.steps))] + ["remove"] * len(res.removal)


def touched(fem, E_max: float) -> bool:
    """Whether a profile's largest elastic energy E_max [J] is above round-off: above that of a uniform
    strain CONTACT_STRAIN_FLOOR over the whole part ``fem``, 1/2 E V eps^2 (E Young's modulus, or 3 times
    the mean shear modulus without a material; V the part's volume, or area in 2D)."""
    return E_max > 0.5 * fem.youngs_modulus * float(np.sum(fem.volume)) * CONTACT_STRAIN_FLOOR**2


def analyze_run(res) -> ProfileSummary:
    """:func:`analyze` of an :class:`simfab.coupling.simulate.InsertionResult`, its steady state at
    the end pose when its path ends in a rotation (``model.end_direction`` None); with friction F_rm
    and F_hold from its removal records and the frictional categories; "none" when O never touched
    the part (:func:`touched`; module docstring)."""
    planned = len(res.model.s_steps)
    E = res.column("energy")
    prof = analyze(res.column("s"), E, res.column("force"), res.column("grip"),
                   end_pose=res.model.end_direction is None, rest_from=planned if len(res.steps) > planned else None)
    mu = float(res.model.contact.friction)
    if not touched(res.model.fem, prof.E_max):
        end = min(planned, len(E)) - 1
        return replace(prof, category="none", E_ss=float(E[end]), coupling_ratio=100.0, index_ss=end,
                       F_grip=float(res.column("grip")[end]), stationary=True, F_hold=prof.F_rm, friction=mu)
    if res.jammed_at is not None:
        return replace(prof, category="jams", F_rm=0.0, F_hold=0.0, friction=mu)
    if not res.removal:
        return replace(prof, F_hold=prof.F_rm, friction=mu)
    F_rm_path = res.column("force", "remove")
    F_rm = float(max(0.0, F_rm_path.max()))
    # no normal force: nothing sticks (the part is free there)
    slipping = np.array([r.slipping if r.normal_force > 0 else 1.0 for r in res.removal])
    F_hold = hold_force(F_rm_path, slipping, F_rm)
    peak = float(np.abs(np.r_[res.column("force"), F_rm_path]).max())
    category = prof.category
    if category == "ejects" and F_hold > REST_FORCE_REL * peak:
        category = "held by friction"
    return replace(prof, category=category, F_rm=F_rm, F_hold=F_hold, friction=mu)



#: Per-record columns of a :class:`Profile` and their units (the profile CSV's columns).
PROFILE_COLUMNS = {
    "s": "m", "energy": "J", "force": "N", "path_force": "N", "grip": "N", "max_von_mises": "Pa",
    "penetration": "m", "min_det_F": "-", "iterations": "-", "contact_points": "-", "phase": "-",
    "normal_force": "N", "path_force_friction": "N", "dissipated": "J", "lag_solves": "-",
}


@dataclass(frozen=True, kw_only=True)
class Profile(ProfileSummary):
    """The deformation profile of an insertion: its key figures (the fields of :class:`ProfileSummary`)
    and, per record (the insertion's, then with friction the removal's; ``phase`` says which), the
    arrays they were read from.

    Args:
        s, energy, force, path_force, grip, max_von_mises, penetration, min_det_F, iterations,
            contact_points, phase, normal_force, path_force_friction, dissipated, lag_solves: one entry
            per record, units in :data:`PROFILE_COLUMNS` (force: support reactions along O's
            translation, resisting < 0; path_force: the force on O along the path's forward tangent).
    """

    s: np.ndarray
    energy: np.ndarray
    force: np.ndarray
    path_force: np.ndarray
    grip: np.ndarray
    max_von_mises: np.ndarray
    penetration: np.ndarray
    min_det_F: np.ndarray
    iterations: np.ndarray
    contact_points: np.ndarray
    phase: np.ndarray
    normal_force: np.ndarray
    path_force_friction: np.ndarray
    dissipated: np.ndarray
    lag_solves: np.ndarray

    def to_pandas(self):
        """The per-record table as a :class:`pandas.DataFrame`, one column per entry of
        :data:`PROFILE_COLUMNS` (named ``<name>_<unit>`` when it has a unit, e.g. ``s_m``, ``force_N``).

        Returns:
            A DataFrame with one row per record (the insertion's, then the removal's).
        """
        import pandas as pd  # deferred: only tables need it

        return pd.DataFrame({(k if u == "-" else f"{k}_{u}"): getattr(self, k) for k, u in PROFILE_COLUMNS.items()})


def profile_of(res, summary: ProfileSummary | None = None) -> Profile:
    """The typed :class:`Profile` of an insertion.

    Args:
        res: a :class:`simfab.coupling.simulate.InsertionResult`.
        summary: its :func:`analyze_run`, if already read.

    Returns:
        Its figures (:func:`analyze_run`) and per-record arrays.
    """
    summary = analyze_run(res) if summary is None else summary
    records = [*res.steps, *res.removal]
    cols = {}
    for k in PROFILE_COLUMNS:
        if k == "phase":
            cols[k] = np.array([r.phase for r in records], dtype=str)
        elif k in ("iterations", "contact_points", "lag_solves"):
            cols[k] = np.array([getattr(r, k) for r in records], dtype=int)
        else:
            cols[k] = np.array([getattr(r, k) for r in records], dtype=float)
    figures = {f.name: getattr(summary, f.name) for f in dataclasses.fields(ProfileSummary)}
    return Profile(**figures, **cols)
