"""Mesh-convergence check of an optimized design: is the brief met by the shape, or only by its
mesh?

The optimizer simulates every candidate on the scene's own (coarse) mesh of linear simplices,
which lock in bending. The same insertion (object, path, steps, support, options) is run again at
finer *levels*, each an element order and a number of uniform subdivisions
(:func:`simfab.fem.subdivide.subdivide`: every edge split, h -> h/2):

    linear 1x (the optimization mesh), P2 1x, P2 refined once (2D 4x, 3D 8x the elements)

(:func:`check_levels`; ``[design] check_refinements`` sets the number of P2 refinements). P2
elements (:func:`simfab.fem.p2.to_p2`) do not lock: the finest P2 level is the reference, or, with
three levels of one order whose changes shrink, f = f_inf + b h^p fitted over them
(:func:`simfab.coupling.converge.extrapolate`). When the P2 level's steps are too coarse for the
profile, :func:`step_check` reruns it with STEP_CHECK_FACTOR times the steps. A refined P2 level
starts its steps from the coarser level's equilibrium, prolonged (two-grid start,
:func:`p2_prolongation`).

Reported per figure: the value at every level, the reference, whether the changes shrink, the
optimization mesh's relative difference from the reference and the reference's own change
between its last two levels (``reference_change``); per constraint, its value at the reference and
whether it is met. :func:`correction_factors` turn the check into the next round's correction of
the coarse figures (:func:`simfab.design.pipeline.run`).

The full notes and the measurements behind the levels: docs/methods.md, "simfab.design.verify".
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import scipy.sparse as sp

from simfab.coupling.converge import extrapolate
from simfab.coupling.guide import CoarseGuide
from simfab.coupling.model import make_coupling_model
from simfab.coupling.simulate import simulate_insertion
from simfab.design import brief as B
from simfab.design.problem import linear_mesh, profile_figures
from simfab.fem.model import make_model
from simfab.fem.p2 import shape_functions, to_p2
from simfab.fem.subdivide import midpoint_mask, subdivide
from simfab.results import field


@dataclasses.dataclass(frozen=True, kw_only=True)
class CheckLevel:
    """One level of a :func:`mesh_check`.

    Args:
        element_order: 1 (linear) or 2 (P2).
        subdivisions: uniform subdivisions of the optimization mesh.
        elements, nodes: the level's mesh size.
        seconds: its simulation's wall time [s].
        category: its coupling category.
        newton_iterations: Newton iterations of its insertion (None: the optimizer's run reused).
        guided_steps: steps started from the coarser level's equilibrium (None: reused).
    """

    element_order: int
    subdivisions: int
    elements: int
    nodes: int
    seconds: float = field(unit="s")
    category: str | None
    newton_iterations: int | None
    guided_steps: int | None


@dataclasses.dataclass(frozen=True, kw_only=True)
class FigureCheck:
    """One figure across the levels of a :func:`mesh_check`.

    Args:
        values: the figure at every level.
        extrapolated: f_inf of f = f_inf + b h^p over three levels of the finest order (None: not fitted).
        order: the fitted p (NaN: not fitted).
        converging: the changes shrink from level to level.
        difference_of_optimization_mesh: (optimization mesh - reference) / reference [-].
        reference_change: the reference order's change between its last two levels, relative [-] (None: one
            level of it).
        step_factor: finer steps / the scene's steps (:func:`step_check`; None where it did not run).
    """

    values: list[float]
    extrapolated: float | None
    order: float
    converging: bool
    difference_of_optimization_mesh: float
    reference_change: float | None
    step_factor: float | None = field(optional=True)


@dataclasses.dataclass(frozen=True, kw_only=True)
class StepCheck:
    """The step check of :func:`step_check`.

    Args:
        steps: the finer run's steps; factor: times the scene's steps.
        seconds: its wall time [s].
        newton_iterations: its Newton iterations; guided_steps: steps guided by the run at the scene's steps.
        factors: per figure, finer steps / the scene's steps.
        category: the finer run's coupling category.
        still_too_coarse: the finer run's own step checks still warn.
    """

    steps: int
    factor: int
    seconds: float = field(unit="s")
    newton_iterations: int
    guided_steps: int
    factors: dict[str, float]
    category: str | None
    still_too_coarse: bool


@dataclasses.dataclass(frozen=True, kw_only=True)
class MeshCheck:
    """A :func:`mesh_check`: the design on refined meshes (entries that are None are left out of its JSON).

    Args:
        profile_force_factor: target matching: c of c F_coarse(s) ~ F_finest(s) (:func:`profile_factor`).
        step_check: the :class:`StepCheck`, where the steps did not resolve the profile.
        levels: one :class:`CheckLevel` each, the optimization mesh first.
        figures: per figure, its :class:`FigureCheck`.
        constraints: the brief's constraints at the reference values (units: ``units``).
        feasible_fine: all of them are satisfied.
        reference: what the reference values are, in words.
        units: figure -> unit.
    """

    profile_force_factor: float | None = field(optional=True)
    step_check: StepCheck | None = field(optional=True)
    levels: tuple[CheckLevel, ...]
    figures: dict[str, FigureCheck]
    constraints: tuple[B.ConstraintReport, ...]
    feasible_fine: bool
    reference: str
    units: dict[str, str]


def check_levels(refinements: int = 1, order: int = 1) -> tuple:
    """The check's levels, (element order, uniform subdivisions): the optimization mesh (linear,
    as annealed), then P2 on it and on its ``refinements`` successive refinements
    (``[design] check_refinements``; the choice: module docstring). A design optimized on P2
    (``order`` 2) starts at P2 on the optimization mesh."""
    return ((1, 0),) * (order == 1) + tuple((2, t) for t in range(int(refinements) + 1))


#: Correction factors are clipped to this range (a coarse linear mesh is too stiff by tens of percent,
#: not by orders of magnitude; a larger ratio means the figure changed character, e.g. a contact
#: that exists on one mesh only).
FACTOR_RANGE = (0.25, 4.0)
#: Step check (:func:`step_check`): the P2 level on the optimization mesh is run again with this many
#: times the scene's steps when its profile is not resolved by them.
STEP_CHECK_FACTOR = 4
#: Target matching: the corrected coarse force profile may differ from the finest level's by this
#: fraction (least-squares scale) before another correction round runs.
PROFILE_TOL = 0.05
FIGURES = ("coupling_ratio", "grip_force", "insertion_force", "removal_force", "hold_force", "von_mises",
           "von_mises_peak")


def refined_model(cm, rest: np.ndarray, times: int, order: int = 1, steps_factor: int = 1):
    """The coupling model of rest shape ``rest`` (n, d) [m] on cm's mesh subdivided ``times`` times,
    with elements of ``order`` (1: linear; 2: the refined mesh lifted to P2 by
    :func:`simfab.fem.p2.to_p2`): the fixed support is every vertex (and P2 edge node) whose
    parents were all fixed; the insertion options are cm's with ``element_order = order`` and
    ``steps_factor`` times its steps along the same path."""
    fem = linear_mesh(cm.fem)  # rest: on the linear mesh (a P2 scene's corners)
    X, el = np.asarray(rest, float), np.asarray(fem.elements)
    fixed = np.zeros(len(X), bool)
    fv = np.asarray(cm.fixed_vertices, np.int64)
    fixed[fv[fv < len(X)]] = True
    for _ in range(times):
        X, el, edges = subdivide(X, el)
        fixed = midpoint_mask(fixed, edges)
    new = make_model(X, el, fem.material, thickness=fem.thickness, device=fem.device)
    if order == 2:
        new = to_p2(new)
        fixed = midpoint_mask(fixed, new.edges)  # P2 edge node n_corners + i sits on edges[i]
    elif order != 1:
        raise ValueError(f"element order {order} is not 1 or 2")
    options = dataclasses.replace(cm.options, element_order=int(order))
    if steps_factor != 1:
        o = cm.options
        options = dataclasses.replace(options, **({"h_in": o.h_in / steps_factor} if o.h_in is not None else
                                                  {"steps": (len(cm.s_steps) - 1) * int(steps_factor)}))
    return make_coupling_model(name=cm.name, fem=new, field=cm.field, path=cm.path,
                               fixed_vertices=np.flatnonzero(fixed), options=options,
                               object_vertices=cm.object_vertices, object_faces=cm.object_faces, contact=cm.contact)


def p2_prolongation(coarse, fine) -> sp.csr_matrix:
    """(n_fine, n_coarse) prolongation from a P2 model ``coarse`` to the P2 model ``fine`` of its
    mesh subdivided once (:func:`refined_model` with one more subdivision): fine node i's position
    is sum_a N_a(L_i) x_a over its parent element's 6 / 10 nodes, L_i its barycentric coordinates
    in the parent's (affine) rest simplex and N_a the P2 shape functions. Every fine node lies in a
    coarse element, so this is exact interpolation of the coarse quadratic field. Parents:
    :func:`simfab.fem.subdivide.subdivide` writes child c of coarse element e as row c m + e (m
    coarse elements); checked here (every fine node inside its parent, to 1e-9)."""
    dim = coarse.dim
    m, fe = coarse.n_elements, np.asarray(fine.elements, np.int64)
    if len(fe) != m * 2 ** dim:
        raise ValueError(f"fine has {len(fe)} elements, not the {m * 2 ** dim} of coarse subdivided once")
    node_el = np.empty(len(fine.rest), np.int64)
    node_el[fe.ravel()] = np.repeat(np.arange(len(fe)), fe.shape[1])  # one element holding each node
    parent = node_el % m
    corners = np.asarray(coarse.rest)[np.asarray(coarse.elements, np.int64)[parent, :dim + 1]]  # (n_f, d+1, d)
    edges = (corners[:, 1:] - corners[:, :1]).transpose(0, 2, 1)  # (n_f, d, d): columns X_a - X_0
    lam = np.linalg.solve(edges, (np.asarray(fine.rest) - corners[:, 0])[..., None])[..., 0]
    L = np.column_stack([1.0 - lam.sum(axis=1), lam])
    if L.min() < -1e-9:
        raise ValueError("fine nodes outside their parent elements: fine is not coarse subdivided once")
    N, _ = shape_functions(L, dim)
    k = N.shape[1]
    cols = np.asarray(coarse.elements, np.int64)[parent]
    return sp.csr_matrix((N.ravel(), (np.repeat(np.arange(len(L)), k), cols.ravel())),
                         shape=(len(fine.rest), len(coarse.rest)))


def level_figures(res, stress_radius: float) -> dict:
    """:func:`simfab.design.problem.profile_figures` of an insertion (on P2 elements the averaged
    stress at quadrature-point resolution, :func:`simfab.design.stress.record_averaged_von_mises`)."""
    return profile_figures(res, stress_radius)


def as_levels(levels, order: int = 1) -> tuple:
    """Normalize check levels: (element order, subdivisions) pairs; a bare int t means linear
    elements subdivided t times. The first level must be the optimization mesh, (``order``, 0)."""
    out = tuple((1, int(lv)) if np.isscalar(lv) else (int(lv[0]), int(lv[1])) for lv in levels)
    if not out or out[0] != (order, 0):
        raise ValueError(f"the first check level must be the optimization mesh ({order}, 0), got {out[:1]}")
    if any(o not in (1, 2) or t < 0 for o, t in out):
        raise ValueError(f"check levels must be (order 1|2, subdivisions >= 0), got {out}")
    return out


def reference_value(fig: FigureCheck) -> float:
    """The reference (mesh-converged) value of a :func:`mesh_check` figure: extrapolated where
    that was possible, else the finest level's; times its step factor where the step check ran."""
    v = fig.values[-1] if fig.extrapolated is None else fig.extrapolated
    return v * (1.0 if fig.step_factor is None else fig.step_factor)


def step_check(problem, rest: np.ndarray, res, figures: dict, *, quiet: bool = True,
               two_grid: bool = True) -> StepCheck | None:
    """The step check: when the insertion ``res`` of the P2 level on the optimization mesh (with
    ``figures``, its :func:`level_figures`) warns that its steps are too coarse for the profile
    (:func:`simfab.coupling.settle.warnings`: a snap skipped between steps, a peak force between
    them), the same level is run with STEP_CHECK_FACTOR times the steps; each figure's ratio
    (finer steps / the scene's steps) is its step factor, which multiplies the reference value
    (the step error and the mesh error taken as independent: the step factor is measured on the
    cheapest level that is not locked). None when the steps resolve the profile. With ``two_grid``
    the run at the scene's steps guides the finer steps' warm starts while it loads (the same
    mesh: :class:`simfab.coupling.guide.CoarseGuide` with the identity as prolongation)."""
    if not _steps_too_coarse(res):
        return None
    t0 = time.perf_counter()
    m = refined_model(problem.base, rest, 0, 2, steps_factor=STEP_CHECK_FACTOR)
    n = len(m.fem.rest)
    same = two_grid and len(res.model.fem.rest) == n  # (the same nodes: P2 on the optimization mesh)
    guide = CoarseGuide.from_records(res.steps, sp.identity(n, format="csr")) if same else None
    fine_res = simulate_insertion(m, quiet=quiet, guide=guide)
    fine = _run_figures(problem, fine_res)
    factors = {k: figure_ratio(k, fine[k], figures[k])
               for k in FIGURES + (("rms_error",) if problem.target is not None else ())}
    return StepCheck(steps=int(len(m.s_steps) - 1), factor=STEP_CHECK_FACTOR, seconds=time.perf_counter() - t0,
                     newton_iterations=int(sum(r.iterations for r in fine_res.steps)),
                     guided_steps=int(fine_res.guided_steps), factors=factors, category=fine["category"],
                     still_too_coarse=_steps_too_coarse(fine_res))


def _steps_too_coarse(res) -> bool:
    """Whether an insertion's own step checks (simfab.coupling.settle.warnings) found its steps too coarse."""
    return any("steps too coarse" in w for w in res.warnings)


def _run_figures(problem, res) -> dict:
    """:func:`level_figures` of an insertion, with the profile-matching RMS error when ``problem`` has a target."""
    f = level_figures(res, problem.brief.stress_radius)
    if problem.target is not None:
        f["rms_error"] = problem.target.rms_error(res.column("s"), res.column("force"))
    return f


def mesh_check(problem, rest: np.ndarray, *, figures0: dict | None = None, result0=None, levels=None,
               quiet: bool = True, two_grid: bool = True) -> MeshCheck:
    """Run the design ``rest`` at each level and compare (see the module docstring).

    figures0 : the optimizer's figures of ``rest`` (level 0), reused instead of simulating again
        (not for target matching: its RMS force error per level needs the profiles)
    result0 : the optimizer's insertion of ``rest`` with ``figures0``: on a P2 optimization mesh the
        step check (:func:`step_check`) reads its warnings (without it, level 0 reused, none runs)
    levels : (element order, subdivisions) pairs (or ints: linear), first the optimization mesh
        (its element order, 0); default :func:`check_levels` of the brief's ``check_refinements``
    two_grid : a P2 level refined t > 0 times starts each step from the P2 level refined t - 1
        times when that level ran just before it (:class:`simfab.coupling.guide.CoarseGuide`, with
        :func:`p2_prolongation`): its Newton solves start near their solutions on the big moves;
        the records stay the level's own equilibria (Newton's tolerance)
    Returns the :class:`MeshCheck`.
    """
    cm = problem.base
    order = int(cm.options.element_order)
    levels = as_levels(check_levels(problem.brief.check_refinements, order) if levels is None else levels, order)
    rows, figs, profiles = [], [], []
    steps = None
    prev_level, prev_res = None, None  # the previous level's (order, subdivisions) and insertion: a coarse guide
    for o, t in levels:
        t0 = time.perf_counter()
        res = None
        if (o, t) == (order, 0) and figures0 is not None and problem.target is None:
            f, n, nodes = figures0, cm.fem.n_elements, cm.fem.n_vertices
            if (o, t) == (2, 0) and result0 is not None:
                res = result0
                steps = step_check(problem, rest, result0, f, quiet=quiet, two_grid=two_grid)
        else:
            m = refined_model(cm, rest, t, o)
            guide = None
            if two_grid and o == 2 and prev_level == (2, t - 1) and prev_res is not None:
                guide = CoarseGuide.from_records(prev_res.steps, p2_prolongation(prev_res.model.fem, m.fem))
            res = simulate_insertion(m, quiet=quiet, guide=guide)
            # (with a target: the profile-matching error, a figure like the others)
            f, n, nodes = _run_figures(problem, res), m.fem.n_elements, m.fem.n_vertices
            if problem.target is not None:
                profiles.append((res.column("s"), res.column("force")))
            if (o, t) == (2, 0):
                steps = step_check(problem, rest, res, f, quiet=quiet, two_grid=two_grid)
        rows.append(CheckLevel(element_order=int(o), subdivisions=int(t), elements=int(n), nodes=int(nodes),
                               seconds=time.perf_counter() - t0, category=f["category"],
                               newton_iterations=None if res is None else int(sum(r.iterations for r in res.steps)),
                               guided_steps=None if res is None else int(res.guided_steps)))
        figs.append(f)
        prev_level, prev_res = (o, t), res
    # the reference run: the trailing levels of the finest level's element order (P2 converges at a
    # higher order than linear elements, so the two orders' values are not one h-sequence)
    top = levels[-1][0]
    k0 = len(levels)
    while k0 > 0 and levels[k0 - 1][0] == top:
        k0 -= 1
    seq = list(range(k0, len(levels)))
    N = np.array([rows[i].elements for i in seq], float)
    out = {}
    for k in FIGURES + (("rms_error",) if problem.target is not None else ()):
        v = np.array([f[k] for f in figs], float)
        d = np.abs(np.diff(v))
        # converging: the changes shrink from level to level (a stress at a sharp re-entrant corner
        # is singular - its maximum grows without bound - and has no mesh-converged value)
        converging = bool(len(v) < 3 or d[-1] < d[-2] or d[-1] <= 1e-9 * max(np.abs(v).max(), 1e-300))
        # f = f_inf + b h^p through three levels of one order (the linear-only check of before)
        f_inf, p = extrapolate(N, v[seq], cm.dim) if len(seq) >= 3 and converging else (None, float("nan"))
        if k == "rms_error" and f_inf is not None and f_inf < 0:  # an error cannot extrapolate below 0
            f_inf, p = None, float("nan")
        ref = float(v[-1]) if f_inf is None else f_inf
        # the reference's own discretization error, as far as the levels show it: the relative change
        # between the last two levels of the reference order (None with one level of it)
        change = float((v[-1] - v[-2]) / ref) if len(seq) >= 2 and ref else None
        out[k] = FigureCheck(values=v.tolist(), extrapolated=f_inf, order=p, converging=converging,
                             difference_of_optimization_mesh=float((v[0] - ref) / ref) if ref else 0.0,
                             reference_change=change,
                             step_factor=None if steps is None else steps.factors.get(k))
    # the mesh-converged answer: extrapolated values where they exist, else the finest level's
    fine = dict(figs[-1], **{k: reference_value(v) for k, v in out.items()})
    cons = B.constraints(fine, problem.limits)
    # target matching: least-squares factor c of c F_coarse(s) ~ F_finest(s), the profile's mesh correction
    pff = profile_factor(profiles[0], profiles[-1], float(cm.s_steps[-1])) if profiles else None
    what = "P2 (quadratic) elements" if top == 2 else "linear elements"
    return MeshCheck(
        profile_force_factor=pff, step_check=steps, levels=tuple(rows), figures=out,
        constraints=tuple(c.report(with_unit=False) for c in cons),
        feasible_fine=all(c.satisfied for c in cons),
        reference=f"{what} on the finest level ({rows[-1].elements} elements); extrapolated where "
                  f"three levels of that order converge" + (
                      f"; times the step factors of P2 on the optimization mesh at {steps.steps} steps"
                      if steps is not None else ""),
        units={"coupling_ratio": "%", "grip_force": "N", "insertion_force": "N", "removal_force": "N",
               "von_mises": "Pa", "von_mises_peak": "Pa", "rms_error": "N"})


def profile_factor(coarse, fine, s_path: float) -> float:
    """Least-squares factor c of c F_coarse(s) ~ F_fine(s) over the coarse run's records on the
    scene's path (s <= ``s_path`` [m]) within the fine run's range; ``coarse``, ``fine``: (s, F)
    arrays. Records past the path's end are left out: they are the search for the rest point
    (:func:`simfab.coupling.settle.to_rest`), micrometres apart around the seat, where the force
    jumps by the full grip within the seat's shift between meshes; one of them would set c."""
    (s0, f0), (s1, f1) = coarse, fine
    on = (s0 <= s_path * (1 + 1e-12)) & (s0 <= s1[-1])
    f0, ref = f0[on], np.interp(s0[on], s1, f1)
    return float(f0 @ ref / (f0 @ f0)) if f0 @ f0 > 0 else 1.0


def check_warnings(check: MeshCheck) -> list[str]:
    """Summary warnings of a :func:`mesh_check`: constraints met only on the optimization mesh."""
    lv = check.levels
    out = []
    st = check.step_check
    if st is not None and st.still_too_coarse:
        out.append(f"the step check's {st.steps} steps do not resolve the profile either, so its step factors "
                   f"({', '.join(f'{k} x{v:.3g}' for k, v in st.factors.items() if v != 1.0)}) are not converged; "
                   "use more steps ([simulation] steps)")
    bad = [c for c in check.constraints if not c.satisfied]
    if not bad:
        return out
    what = ", ".join(f"{c.name} {c.value:.4g} (bounds {c.lo:.4g}..{c.hi:.4g})" for c in bad)
    ref = f"P{lv[-1].element_order} on {lv[-1].elements} elements"
    if st is not None:
        ref += f", with the step factors of {st.steps} steps"
    kind = "P2" if lv[0].element_order == 2 else "linear"
    return out + [f"mesh-converged ({ref}; the optimization mesh: {lv[0].elements} {kind}) "
                  f"the design misses: {what}"]


def figure_unit(name: str) -> float:
    """The constraint unit of a mesh-check figure (:data:`simfab.design.brief.SCALES`; the raw
    stress peak like the averaged stress; 0 for figures without a constraint)."""
    return B.SCALES.get("von_mises" if name.startswith("von_mises") else name, 0.0)


def figure_ratio(name: str, value: float, base: float) -> float:
    """value / base of figure ``name``, clipped to FACTOR_RANGE; 1 when base is below the figure's
    constraint unit (1 N, 1 %, 1 MPa: B.SCALES), which is noise rather than a biased value (its
    ratio, e.g. 1e-8 N / 1e-11 N, says nothing), or when the ratio is not a positive number."""
    if abs(base) < figure_unit(name) or not base:
        return 1.0
    r = value / base
    return float(np.clip(r, *FACTOR_RANGE)) if np.isfinite(r) and r > 0 else 1.0


def correction_factors(check: MeshCheck) -> dict:
    """{figure: reference value / optimization-mesh value} of a :func:`mesh_check` (space mapping
    of the coarse model's outputs: the optimizer multiplies its coarse figures by these, so that
    the next round aims at the mesh-converged values; figures with a zero coarse value keep 1)."""
    out = {k: figure_ratio(k, reference_value(v), v.values[0]) for k, v in check.figures.items()}
    if check.profile_force_factor is not None:  # target matching: the whole force profile, scaled
        out["force_profile"] = check.profile_force_factor
    return out


def needs_correction(check: MeshCheck, applied: dict) -> bool:
    """Another correction round is due when the mesh-converged figures miss the brief, or (target
    matching) when the coarse force profile, as corrected so far, is still more than
    PROFILE_TOL off the finest level's."""
    if not check.feasible_fine:
        return True
    c = check.profile_force_factor
    return c is not None and abs(c / applied.get("force_profile", 1.0) - 1.0) > PROFILE_TOL


def checked_objective(problem, ev, check: MeshCheck) -> float:
    """The design objective with the mesh-converged figures of ``check``: E_L (or, for target
    matching, the squared RMS force error of the finest level) plus the penalties of the
    constraints at the reference values."""
    cons = [B.Constraint(name=c.name, value=c.value, lo=c.lo, hi=c.hi, unit=B.UNITS[c.name],
                         scale=B.SCALES[c.name]) for c in check.constraints]
    if problem.target is not None:
        base = reference_value(check.figures["rms_error"]) ** 2
    else:
        base = ev.E_L
    return float(base + B.penalty(cons))
