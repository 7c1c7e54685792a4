"""Where an insertion run stops, and the checks of its profile that a designer relies on.

**Steps to rest.** The keyframe path of a scene is drawn by hand and often ends a little before O
seats: at its last pose A still draws O in (path force > 0) and the energy is still falling, so
E_ss read there is not the steady state. When the path's last segment is a pure translation and
the insertion length is the default one, the run continues past the last keyframe straight on,
with quarter steps, cut short where a new contact (the seat) is predicted to engage or the
force to reach zero, until the path force has gone through zero (O at rest: the energy at its
minimum along the path), at most as far again as the planned path (:func:`to_rest`).

**Checks** (:func:`warnings`, one line each, copied into the run's warnings):

- the run ends while A still draws O in (path cannot be continued, or the extension cap was
  reached): E_ss is then not a stationary point of the energy along the path;
- step resolution: over every step the work of the path force (trapezoidal rule) must match the
  change of stored energy, W_k = -h (P_k + P_{k+1}) / 2 = Delta(E + B)_k, to within
  STEP_WORK_REL * E_max (the trapezoidal error is h^3 |E'''| / 12 per step on a smooth profile,
  larger where the step skips over a feature of the profile); and F_in read at a step must agree
  with the peak of the parabola through it and its neighbours to within STEP_PEAK_REL (else the
  peak falls between steps). Both are skipped on a negligible profile (E_max within the energy
  Newton's force tolerance leaves unresolved over the travel, NEGLIGIBLE_NOISE): a run that barely
  touched O has nothing to resolve, and its work and forces are noise;
- max von Mises stress above the material's yield stress (the model is hyperelastic: a part that
  yields would not spring back as simulated).
"""

from __future__ import annotations

import numpy as np

from simfab.coupling import config as C
from simfab.coupling.layout import point_dhat

#: O is at rest when the path force (A drawing O in, > 0) is at most this fraction of the peak |force|.
from simfab.coupling.profile import REST_FORCE_REL  # noqa: E402 (one definition)

#: Continue past the path's end by at most this many times the planned number of steps (of
#: SETTLE_STEP_REL times the planned size: 4 x 0.25, as far again as the planned path).
SETTLE_MAX_STEPS_REL = 4.0
#: Extension steps are this fraction of the last planned step: the rest point is usually a seat
#: (O meeting a stiff part of A) where a step that overshoots deep costs many Newton iterations
#: (cclamp2d: a full step 18, a quarter step 7).
SETTLE_STEP_REL = 0.25
#: A step over the seat's predicted onset ends this fraction of the way from the onset to the step's end.
SEAT_STEP_REL = 0.5
#: A step towards the rest point predicted by the last records' forces (:func:`_zero_ahead`) is at least this
#: fraction of the extension step.
MIN_SETTLE_STEP_REL = 1 / 16
#: Extension steps are at most the path length over this.
MIN_SETTLE_STEPS = 20
#: The rest point is found when the energy between the bracket's ends is known to within this fraction of E_max.
REST_ENERGY_REL = 1e-3
#: Trials to find the rest point once a step has overshot it.
REST_TRIALS = 16
#: :func:`seat_onset` takes the points' closing rates by a finite difference over this fraction of the step.
SEAT_RATE_REL = 1e-3
#: A secant trial of the rest search lies at least this fraction of the bracket inside its ends.
SECANT_MARGIN = 0.02
#: Largest mismatch between a step's work and its change of stored energy, relative to E_max.
STEP_WORK_REL = 0.05
#: Largest difference between F_in at a step and the peak of the parabola through its neighbours.
STEP_PEAK_REL = 0.1
#: work_energy_mismatch: a step whose barrier energy changes by more than this factor engages a new
#: contact zone (its force has a kink inside the step).
BARRIER_JUMP = 4.0
#: The step checks need a profile to check: they are skipped when E_max is at most this many times
#: the energy Newton's force tolerance f_tol (NEWTON_GRAD_TOL_REL * force_scale) leaves unresolved
#: over the run's travel, f_tol * (s_end - s_0) [J] (a run that barely touched O: E_max 1e-14 J),
#: and a step's work mismatch or its force peak counts only above that many times the same noise
#: (f_tol * h for one step of length h, f_tol for a force).
NEGLIGIBLE_NOISE = 2.0


def can_continue(cm) -> bool:
    """O may move on past the last keyframe: default insertion length reaching the path's end and a
    last segment that is a pure translation."""
    return cm.options.L_max is None and cm.end_direction is not None and \
        float(cm.s_steps[-1]) >= float(cm.path.length) * (1 - 1e-12)


def still_drawn_in(steps) -> bool:
    """The last record's path force still draws O in (above REST_FORCE_REL of the peak force) and
    the energy fell over the last step."""
    if len(steps) < 2:
        return False
    P = np.array([r.path_force for r in steps])
    peak = float(np.abs(P).max())
    E_prev, E_last = steps[-2].energy + steps[-2].barrier_energy, steps[-1].energy + steps[-1].barrier_energy
    return peak > 0 and P[-1] > REST_FORCE_REL * peak and E_last < E_prev


def to_rest(cm, stepper) -> str:
    """Continue the run past the path's end until O comes to rest (see the module docstring).

    stepper : the run's :class:`simfab.coupling.stepper.Stepper` (its ``steps`` so far; ``step`` solves a step from
    the current state, ``undo`` returns to the state before it, ``keep`` appends its record). Steps of SETTLE_STEP_REL
    times the last planned one (at most 1/MIN_SETTLE_STEPS of the path) go on while :func:`still_drawn_in`, each cut
    short when the seat's onset (:func:`seat_onset`) lies inside it (to SEAT_STEP_REL of the way on from the onset:
    a step deep into a stiff seat costs many Newton iterations) or when the line through the last two records' forces
    reaches zero inside it (:func:`_zero_ahead`, at least MIN_SETTLE_STEP_REL of a step). A step that overshoots the
    rest point (path force below -REST_FORCE_REL * peak: O pushed into a stiffer contact, or no solution: undone)
    starts the search; the rest point is bracketed (:func:`_bracket`), every trial solved from the last one's state (a
    step back from past the rest point is short and feasible: O moves away from A). It ends when the path force is
    within REST_FORCE_REL * peak of zero, or when the energy between the bracket's ends is known to within
    REST_ENERGY_REL * E_max (see :func:`_bracket`). With friction (``stepper.history_dependent``) the steps are not
    cut short and the search bisects: the removal starts from where the search stops, and the hold force read on it
    moved by 5 % between two stops within the search's tolerance (docs/decisions.md).

    Returns "rest" (O came to rest), "not continued" (the path cannot be continued or was already
    at rest) or why it stopped short ("cap": the extension limit, "bracket": no rest point found).
    """
    steps = stepper.steps
    if len(steps) < 2 or not can_continue(cm) or not still_drawn_in(steps):
        return "not continued" if len(steps) < 2 or not still_drawn_in(steps) else "cannot continue"
    h = min(SETTLE_STEP_REL * (steps[-1].s - steps[-2].s), float(cm.path.length) / MIN_SETTLE_STEPS)
    peak = float(max(abs(r.path_force) for r in steps))
    E_max = float(max(r.energy for r in steps))
    tol = REST_FORCE_REL * peak
    n_steps = int(np.ceil(SETTLE_MAX_STEPS_REL * (len(cm.s_steps) - 1)))
    s_cap = steps[-1].s + n_steps * h  # as far again as the planned path
    pivot = None  # a seat's onset the last kept step passed (see _zero_ahead)
    for _ in range(2 * n_steps):  # (steps cut short at a predicted seat or rest point: see below)
        if not still_drawn_in(steps):
            return "rest"
        if steps[-1].s >= s_cap - 1e-9 * h:
            break
        s_to = min(steps[-1].s + h, s_cap)
        onset = None if stepper.history_dependent else seat_onset(cm, stepper.state, s_to)
        s_try = s_to if onset is None else onset + SEAT_STEP_REL * (s_to - onset)
        s_zero = None if stepper.history_dependent else _zero_ahead(steps, pivot)
        predicted = s_zero is not None and s_zero < s_try
        if predicted:
            s_try = max(s_zero, steps[-1].s + MIN_SETTLE_STEP_REL * h)
        attempt = stepper.step(s_try, tolerate=True)
        rec = attempt.record
        if rec is not None and rec.path_force >= -tol:
            stepper.keep(rec)
            if onset is not None and onset < rec.s:
                pivot = onset
            continue
        if rec is None or stepper.history_dependent:  # (with friction every trial goes forward from the last kept)
            stepper.undo(attempt)
        return _bracket(steps[-1], rec, s_try, stepper, tol, REST_ENERGY_REL * E_max,
                        onset=None if predicted else onset, secant=predicted)
    return "rest" if not still_drawn_in(steps) else "cap"


def _zero_ahead(steps, pivot: float | None) -> float | None:
    """Where the line through the last two records' path forces crosses zero ahead of the last one,
    when the force falls between them (None otherwise); with a seat's onset ``pivot`` [m] between
    them, the line from (pivot, the earlier force) instead: the force is about flat up to the onset."""
    a, b = steps[-2], steps[-1]
    if not a.path_force > b.path_force > 0:
        return None
    s_a = pivot if pivot is not None and a.s < pivot < b.s else a.s
    return b.s + b.path_force * (b.s - s_a) / (a.path_force - b.path_force)


def seat_onset(cm, state, s_to: float) -> float | None:
    """Where O, moved on from ``state`` towards path length ``s_to`` [m] with A held in place, first
    brings a constraint point that is not in contact yet (distance above its d_hat) within d_hat:
    the onset of a new contact, typically O's seat. Each point's distance is extrapolated linearly
    from its rate of change at ``state.s`` (a finite difference over SEAT_RATE_REL of the step).

    Args:
        cm: the coupling model.
        state: the current :class:`simfab.coupling.state.StepState` (its positions, path length and points).
        s_to: the end of the step [m].

    Returns:
        The predicted onset in (state.s, s_to) [m], or None when no point engages within the step.
    """
    pts = state.points
    y = pts.positions(state.x)
    dh = point_dhat(cm, pts)
    ds = SEAT_RATE_REL * (s_to - state.s)
    if not ds > 0:
        return None
    d = []
    for s in (state.s, state.s + ds):
        ev = cm.field.evaluate(y, cm.pose(s), hessian=False)
        d.append(np.where(ev.near, -ev.psi, np.inf))
    with np.errstate(invalid="ignore", divide="ignore"):  # (far points: inf - inf; rates of 0 are left out)
        rate = (d[0] - d[1]) / ds  # closing speed of each point's gap per metre of path
        t = np.where((d[0] > dh) & (rate > 0) & np.isfinite(d[0]) & np.isfinite(d[1]), (d[0] - dh) / rate, np.inf)
    s_on = state.s + float(t.min(initial=np.inf))
    return s_on if s_on < s_to else None


def _bracket(lo, hi, hi_s, stepper, tol, e_tol, onset=None, secant=False) -> str:
    """Find the rest point between the kept record ``lo`` (path force > 0) and an overshoot at
    ``hi_s`` (record ``hi``, None when unsolvable); see :func:`to_rest`.

    Trials on the path force P = -dW/ds (W = E + B), each solved from the last trial's state, until
    P_lo (s_hi - s_lo) <= e_tol [J]: W falls at most that much from the lower end to the rest point
    (W convex on the bracket, P <= P_lo). The rest point is often a kink (O seating against a stiff
    part of A: P falls from drawing in to pushing back within micrometres), where a secant through
    the bracket's ends lands next to the lower end. With the seat's ``onset`` [m] (:func:`seat_onset`,
    inside the bracket) the trials take the secant from (onset, P_lo) instead while the lower end lies
    before the onset (P is about flat up to it and smooth past it; dropped when two trials in a row
    push back). Secants otherwise between the ends (Illinois: the end two trials in a row did not
    replace has its force halved), a bisection whenever a trial shrank the bracket by less than half,
    and always a bisection towards an unsolvable end.

    The two ends are kept as the last records (the trials' own records; the run's state is then the
    last trial's): force through zero between them, the energy's minimum along the path at the lower
    end. With friction (``stepper.history_dependent``) every trial is solved forward from the lower
    end's state (an overshoot is undone: stepping back would reverse the friction), and only the
    lower end is kept.
    """
    steps_last = lo
    pivot = onset if onset is not None and lo.s < onset < hi_s else None
    f_lo, f_hi = lo.path_force, None if hi is None else hi.path_force  # the secant's values at the ends
    bisect, side, width = pivot is None and not secant, None, hi_s - lo.s  # side: the end the last trial replaced
    for _ in range(REST_TRIALS):
        if lo.path_force * (hi_s - lo.s) <= e_tol:
            break
        s_a = lo.s if pivot is None or lo.s >= pivot else pivot
        if bisect or f_hi is None or stepper.history_dependent:
            s_try = 0.5 * (s_a + hi_s)
        else:  # the secant's zero, kept off the ends
            s_try = float(np.clip(s_a + (hi_s - s_a) * f_lo / (f_lo - f_hi), s_a + SECANT_MARGIN * (hi_s - s_a),
                                  hi_s - SECANT_MARGIN * (hi_s - s_a)))
        attempt = stepper.step(s_try, tolerate=True)
        rec = attempt.record
        if rec is not None and abs(rec.path_force) <= tol:
            stepper.keep(rec)
            return "rest"
        if rec is None or (stepper.history_dependent and rec.path_force <= 0):
            stepper.undo(attempt)
        if rec is not None and rec.path_force > 0:  # still drawn in: the new lower end
            lo, f_lo = rec, rec.path_force
            if side == "lo" and f_hi is not None:
                f_hi *= 0.5
            side = "lo"
        else:
            hi, hi_s, f_hi = rec, s_try, None if rec is None else rec.path_force
            if side == "hi":  # the lower end stays twice: the onset may be late, the secant's pivot is lo
                f_lo *= 0.5
                pivot = None
            side = "hi"
        bisect = (hi_s - lo.s) > 0.5 * width
        width = hi_s - lo.s
    else:
        if lo is not steps_last:
            stepper.keep(lo)
        return "bracket"
    ends = (lo,) if stepper.history_dependent else (lo, hi)
    for end in ends:  # the ends' records, in order (the trials' own: no solve again)
        if end is not None and end is not steps_last:
            stepper.keep(end)
    return "rest"


def step_work(records: list) -> dict:
    """The energy balance of consecutive records (a traversal, either direction): per step k the work
    O does on A, W_k = -h_k (N_k + N_{k+1}) / 2 - h_k F_{k+1} (h_k = s_{k+1} - s_k; N the normal
    part of the path force by the trapezoidal rule, F its friction part taken at the step's end, as
    the incremental potential takes the friction of a step), against the change of stored energy plus
    what friction dissipated over it, Delta(E + B)_k + D_{k+1}. Returns arrays ``work``, ``stored``
    (Delta(E + B)), ``dissipated`` and ``mismatch`` (k,) [J]."""
    s = np.array([r.s for r in records])
    Et = np.array([r.energy + r.barrier_energy for r in records])
    F = np.array([r.path_force_friction for r in records])
    N = np.array([r.path_force for r in records]) - F
    D = np.array([r.dissipated for r in records])
    h = np.diff(s)
    work = -0.5 * h * (N[1:] + N[:-1]) - h * F[1:]
    stored = np.diff(Et)
    return {"work": work, "stored": stored, "dissipated": D[1:], "mismatch": stored + D[1:] - work}


def energy_balance(steps: list, removal: list = ()) -> dict:
    """The energy balance of a run over both traversals (the removal starts from the insertion's
    last record), relative to the peak energy E_max: ``step`` the largest per-step mismatch
    (:func:`step_work`), ``total`` |sum of the work done on A - the net change of stored energy - the
    dissipated energy|; with ``work_J``, ``dissipated_J`` (over both traversals) and ``E_max_J``."""
    E_max = float(max(r.energy for r in steps))
    parts = [step_work(steps)] + ([step_work([steps[-1], *removal])] if len(removal) else [])
    mis = np.concatenate([p["mismatch"] for p in parts])
    work = float(sum(p["work"].sum() for p in parts))
    diss = float(sum(p["dissipated"].sum() for p in parts))
    stored = float(sum(p["stored"].sum() for p in parts))
    scale = E_max if E_max > 0 else 1.0
    return {"step": float(np.abs(mis).max(initial=0.0)) / scale, "total": abs(work - stored - diss) / scale,
            "work_J": work, "dissipated_J": diss, "E_max_J": E_max}


def warnings(cm, steps, rest: str = "not continued", removal: list = ()) -> list:
    """One line per problem found in the profile of ``steps`` (StepResult list), see the module
    docstring; ``rest`` is :func:`to_rest`'s outcome; ``removal`` the frictional removal's records
    (their steps are checked for the same energy balance, and their lagging iterations)."""
    out = []
    if len(steps) < 2:
        return out
    s = np.array([r.s for r in steps])
    E = np.array([r.energy for r in steps])
    P = np.array([r.path_force for r in steps])
    name = cm.name
    if rest != "rest" and still_drawn_in(steps):
        why = {"cap": "it was continued past the last keyframe as far again as the planned path",
               "bracket": "no rest point was found past the last keyframe"}.get(rest)
        if why is None:
            why = ("the insertion length L_max ends it" if cm.options.L_max is not None else
                   "the path ends in a rotation" if cm.end_direction is None else "the path ends there")
        out.append(f"{name}: the run ends at s={s[-1] * 1e3:.4g} mm while the part still draws the object in "
                   f"(path force {P[-1]:+.4g} N, energy still falling; {why}): E_ss is not a stationary point "
                   "and the coupling ratio and category come from an unfinished insertion; extend the keyframes "
                   "(or L_max) to where the object seats")
    E_max = float(E.max())
    f_tol = C.NEWTON_GRAD_TOL_REL * cm.force_scale  # force noise of a converged step [N]
    if E_max > NEGLIGIBLE_NOISE * f_tol * (s[-1] - s[0]):
        for phase, records in (("insertion", steps), ("removal", [steps[-1], *removal] if len(removal) else [])):
            if len(records) < 2:
                continue
            sr = np.array([r.s for r in records])
            h = np.abs(np.diff(sr))
            mis = np.abs(step_work(records)["mismatch"])
            mis = np.where(mis > NEGLIGIBLE_NOISE * f_tol * h, mis, 0.0)
            k = int(np.argmax(mis))
            if mis[k] > STEP_WORK_REL * E_max:
                out.append(f"{name}: steps too coarse to resolve the profile: over the {phase} step to "
                           f"s={sr[k + 1] * 1e3:.4g} mm the work of the path force differs from the change of stored "
                           f"energy (plus friction's dissipation) by {100 * mis[k] / E_max:.3g}% of E_max "
                           f"(> {100 * STEP_WORK_REL:g}%); use more steps")
        n = min(len(cm.s_steps), len(s))  # the planned steps (the rest search past them may push O into its seat)
        i = int(np.argmin(P[:n]))
        if 0 < i < n - 1 and P[i] < -NEGLIGIBLE_NOISE * f_tol:
            F_peak = _parabola_peak(s[i - 1:i + 2], P[i - 1:i + 2])
            if abs(F_peak - P[i]) > STEP_PEAK_REL * abs(P[i]):
                out.append(f"{name}: steps too coarse to resolve the peak insertion force: {-P[i]:.4g} N at a "
                           f"step, {-F_peak:.4g} N at the peak between steps; use more steps")
    unlagged = [r for r in [*steps, *removal] if r.lag_change > cm.contact.lag_tol]
    if unlagged:
        r = max(unlagged, key=lambda r: r.lag_change)
        out.append(f"{name}: at {len(unlagged)} step(s) the friction's normal forces still changed by up to "
                   f"{100 * r.lag_change:.3g}% (> lag_tol {100 * cm.contact.lag_tol:g}%) after "
                   f"{cm.contact.max_lag_iterations} lagging iterations (worst at s={r.s * 1e3:.4g} mm, {r.phase}): "
                   "the friction forces there are not consistent with the normal forces to that tolerance")
    mat = cm.fem.material
    if mat is not None:
        run = [*steps, *removal]  # (a frictional removal can load the part more than the insertion)
        r = run[int(np.argmax([r.max_von_mises for r in run]))]
        if r.max_von_mises > mat.yield_stress:
            at = f"s={r.s * 1e3:.4g} mm" + (", removal" if r.phase == "remove" else "")
            out.append(f"{name}: the max von Mises stress {r.max_von_mises / 1e6:.4g} MPa (at {at}) exceeds "
                       f"the yield stress {mat.yield_stress / 1e6:.4g} MPa of {mat.name}: the part would deform "
                       "plastically (the model is elastic)")
    return out


def work_energy_mismatch(steps, planned: int | None = None) -> dict:
    """How well the profile's forces and energies agree, step by step (quasi-static, frictionless:
    the work of the path force over a step is the change of stored energy, -int P ds = Delta(E + B)).

    Per step k (records k, k+1, the rest search's included): m_k = Delta(E + B)_k + h_k (P_k + P_{k+1}) / 2
    (trapezoidal rule, error h^3 |P''| / 12 on a smooth profile). Returns the largest |m_k| / E_max
    ("work": over all steps, "work_refined": over steps where refinement points were added) and the
    largest |m_k| / (h_k max |P|) ("force": the step's secant -Delta(E + B) / h against its mean
    force; max |P| the peak over the first ``planned`` records, the insertion's, not the seat's push
    at the rest search's trials) over all steps and over "smooth" steps only: among the first ``planned`` records (the
    planned steps, not the rest search's bracket around the seat), the object in contact at both
    ends (B > 0) with the barrier energy within a factor BARRIER_JUMP between them and the force
    keeping its sign (no contact starting, ending, or a new contact zone engaging inside the step,
    where the force has a kink the trapezoidal rule resolves only to first order in h); with the
    worst step's index (1 = the step to record 1)."""
    s = np.array([r.s for r in steps])
    B = np.array([r.barrier_energy for r in steps])
    Et = np.array([r.energy for r in steps]) + B
    P = np.array([r.path_force for r in steps])
    cp = np.array([r.contact_points for r in steps])
    E_max = float(max(r.energy for r in steps))
    P_max = float(np.abs(P[:planned]).max())
    if len(steps) < 2 or E_max <= 0 or P_max <= 0:
        return {"work": 0.0, "work_refined": 0.0, "force": 0.0, "force_smooth": 0.0, "worst_step": None,
                "worst_smooth_step": None}
    h = np.diff(s)
    m = np.diff(Et) + 0.5 * h * (P[1:] + P[:-1])
    refined = np.diff(cp) > 0
    smooth = (B[1:] > 0) & (B[:-1] > 0) & (P[1:] * P[:-1] > 0)
    smooth &= np.maximum(B[1:], B[:-1]) <= BARRIER_JUMP * np.minimum(B[1:], B[:-1])
    smooth[(len(steps) if planned is None else planned) - 1:] = False
    f = np.abs(m) / (h * P_max)
    fs = np.where(smooth, f, 0.0)
    return {"work": float(np.abs(m).max() / E_max),
            "work_refined": float(np.abs(m[refined]).max() / E_max) if refined.any() else 0.0,
            "force": float(f.max()), "force_smooth": float(fs.max()),
            "worst_step": int(np.argmax(f)) + 1, "worst_smooth_step": int(np.argmax(fs)) + 1 if smooth.any() else None}


def _parabola_peak(x: np.ndarray, y: np.ndarray) -> float:
    """Extreme value of the parabola through three points (x (3,), y (3,)); y[1] if it is a line."""
    d0, d2 = float(x[0] - x[1]), float(x[2] - x[1])
    det = d0 * d2 * (d0 - d2)
    if det == 0:
        return float(y[1])
    r0, r2 = float(y[0] - y[1]), float(y[2] - y[1])
    a = (r0 * d2 - r2 * d0) / det
    b = (r2 * d0 * d0 - r0 * d2 * d2) / det
    return float(y[1] - b * b / (4 * a)) if a != 0 else float(y[1])
