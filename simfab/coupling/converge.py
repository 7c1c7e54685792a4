"""Mesh-convergence study of a coupling scene: the profile figures at successively refined meshes
of the compliant part, their extrapolated (mesh-converged) values and the error of the scene's
own resolution.

The scene is run at ``target_elements`` times each refinement factor (the generator meshes the
part again). An extruded part (``extruded_clamp``) is refined in its section and through its height
alike: ``layers`` times factor^(1/3) (rounded, at least 1), the rest of the factor in the section
(refining the section alone left the error through the height out of the study:
docs/validation/coupling.md). A C-clamp's section (``c_clamp``, ``extruded_clamp``) is refined with its
arcs' default sampling, and the factors multiply the scene mesh's actual element count where the
triangulation's floor made more than its target (:func:`level_mesh`). A 3D scene that ships its
part's mesh (``mesh_file``, e.g. claw3d's stored fTetWild mesh, or the tets ``simfab couple new``
stores beside the part's surface) keeps that mesh at factor 1 (the error of what users run) and is
meshed again from its generator (or surface mesh) at the other factors; a part with no generator
and no surface (a ready mesh only) cannot be refined and raises InputError. With
element counts N_k and a figure f_k, the discretization error of linear elements falls like
h^p ~ N^(-p/dim); the extrapolated value f_inf and the observed order p come from a
least-squares fit of f = f_inf + b h^p to the finest four levels (:func:`extrapolate`). The error
of each level is (f_k - f_inf) / f_inf.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simfab.coupling.geometry import C_CLAMP_SEGMENTS
from simfab.coupling.outputs import summarize
from simfab.coupling.scene import load_coupling_scene, read_scene_toml, scene_paths
from simfab.coupling.simulate import simulate_insertion
from simfab.errors import InputError
from simfab.io.atomic import atomic_paths, save_figure, write_csv, write_json
from simfab.io.outpaths import safe_name
from simfab.results import Result
from simfab.results import field as rfield

FIGURES = ("E_max", "E_ss", "F_in", "F_rm", "F_grip")
#: Each figure's unit (the study's CSV columns and plot).
UNITS = {"E_max": "J", "E_ss": "J", "F_in": "N", "F_rm": "N", "F_grip": "N"}
#: A figure below this fraction of its kind's peak (E_max; the larger of F_in, F_rm) is zero up to
#: the solver's tolerances: its error is reported relative to that peak.
ZERO_REL = 1e-3
#: Two levels whose element counts differ by less than this fraction are the same refinement (the
#: mesher's floor or cap): their difference says nothing about convergence, and the report warns.
SAME_MESH_REL = 0.1
#: The range of orders p the fit searches (:func:`extrapolate`); a fit at either end is no rate.
ORDER_RANGE = (0.5, 4.0)
#: Generators whose section is a triangulated C-clamp outline (:func:`level_mesh`).
CLAMP_GENERATORS = ("c_clamp", "extruded_clamp")


#: A fitted order in h below this (and not at the range's end) is slower than any part without cracks
#: converges in the asymptotic range: there the energy converges at twice the energy norm's rate,
#: h^(2 min(k, lambda)) for elements of order k and a corner or contact singularity of exponent
#: lambda >= 1/2, and the support's reaction (a derivative of the energy) and the contact forces with it.
#: Slower levels are pre-asymptotic (linear elements locked in bending converge this slowly until the mesh
#: resolves the bending), and the report warns: their extrapolation is unreliable.
SLOW_ORDER = 1.0

#: A level's layers more than this fraction off the uniform refinement's (the scene's layers times
#: factor^(1/3): layers are whole) make the levels no uniform refinement of one another: the report warns.
LAYERS_OFF_REL = 0.1


@dataclass(frozen=True, kw_only=True)
class Level:
    """One level of a study.

    Args:
        factor: its refinement: element count over the scene's [-].
        elements: its element count.
        seconds: the run's wall time [s].
        category: the profile's category.
        figures: FIGURES at this level [J for energies, N for forces].
        friction: the Coulomb coefficient [-].
        element_order: the part's element order (1 linear, 2 quadratic).
        layers: an extruded part's layers (None for other parts).
        scene_layers: the scene's own layers (None likewise): uniform refinement would give
            scene_layers * factor^(1/3).
    """

    factor: float = rfield(unit="-")
    elements: int
    seconds: float = rfield(unit="s")
    category: str
    figures: dict = rfield(json=False)
    friction: float = rfield(unit="-", json=False, default=0.0)
    element_order: int = 1
    layers: int | None = rfield(optional=True)
    scene_layers: int | None = rfield(json=False, default=None)


@dataclass(frozen=True, kw_only=True)
class FigureConvergence:
    """One profile figure over a study's levels.

    Args:
        values: the figure at each level [J for energies, N for forces].
        extrapolated: its mesh-converged value (:func:`extrapolate`) [the same unit].
        order: the fitted order in h (nan with fewer than three levels or a flat sequence) [-].
        relative_of: the figure its errors are relative to: itself, or its kind's peak where it is ~0.
        relative_error: (f_k - f_inf) / ref at each level [-].
    """

    values: tuple
    extrapolated: float
    order: float = rfield(unit="-")
    relative_of: str
    relative_error: tuple


@dataclass(frozen=True, kw_only=True)
class ConvergenceResult(Result):
    """A mesh-convergence study (``simfab couple converge``; :func:`convergence_study`).

    Args:
        scene: the scene as given.
        friction: the Coulomb coefficient of its runs [-].
        warnings: one line each: levels that are the same mesh, levels an extrusion's whole layers refine
            unequally, fits that are no power law, figures that converge slower than h (pre-asymptotic).
        levels: the :class:`Level` s, coarsest first.
        figures: FIGURES name -> :class:`FigureConvergence`.
        error_of_default: FIGURES name -> the relative error of the scene's own mesh (factor 1, else the
            first level) [-].
    """

    scene: str
    friction: float = rfield(unit="-")
    warnings: tuple = ()
    levels: tuple = ()
    figures: dict = rfield(default_factory=dict)
    error_of_default: dict = rfield(default_factory=dict)


def run_levels(scene, factors=(1, 2, 4, 8), *, overrides: dict | None = None, quiet: bool = True,
               device: str = "cpu") -> list:
    """One :class:`Level` per refinement factor (element count times the factor), run on Warp's ``device``."""

    _, toml = scene_paths(scene)
    cfg = read_scene_toml(toml)
    comp = cfg.get("compliant", {})
    # a ready mesh_file is the level at factor 1; the other levels need a source to mesh again from: a
    # parametric generator, an outline or a surface mesh (as simfab couple new writes a 3D part)
    remeshable = comp.get("generator") not in (None, "mesh") or "mesh" in comp or "outline" in comp
    if comp.get("target_elements") is None or ("mesh_file" in comp and not remeshable):
        raise InputError("a convergence study needs a scene whose part is meshed from target_elements "
                         "by a generator (not only a ready mesh_file); for a part of your own, give [compliant] "
                         'generator = "mesh", mesh = its surface file, units and target_elements beside (or '
                         "instead of) mesh_file", where=str(toml))
    base = None  # the scene's own model (factor 1): for a C-clamp the factors multiply its element count
    if comp.get("generator") in CLAMP_GENERATORS:
        base = load_coupling_scene(scene, overrides=overrides, quiet=quiet, device=device)
    elements = None if base is None else base.fem.n_elements
    out = []
    for f in factors:
        ov = {k: dict(v) for k, v in (overrides or {}).items()}
        mesh = level_mesh(comp, f, elements=elements)
        ov.setdefault("compliant", {}).update(mesh)
        if f == 1.0 and base is not None:
            cm = base
        else:  # (scene flags logged once)
            cm = load_coupling_scene(scene, overrides=ov, quiet=quiet or base is not None or f != factors[0],
                                     device=device)
        t0 = time.perf_counter()
        res = simulate_insertion(cm, quiet=quiet)
        dt = time.perf_counter() - t0
        prof, d = summarize(res)
        layered = "layers" in mesh
        out.append(Level(factor=float(f), elements=int(cm.fem.n_elements), seconds=dt,
                         figures={k: float(d[k]) for k in FIGURES}, category=prof.category, friction=prof.friction,
                         element_order=int(cm.fem.element_order),
                         layers=int(mesh["layers"]) if layered else None,
                         scene_layers=int(comp.get("layers", 1)) if layered else None))
    return out


def level_mesh(comp: dict, factor: float, *, elements: int | None = None) -> dict:
    """The ``[compliant]`` overrides of the level at ``factor`` for a part table ``comp``: the
    target element count times the factor; an extrusion's layers times factor^(1/3) (rounded, at
    least 1: uniform refinement, the section takes the rest); a shipped mesh file is meshed again
    from the generator except at factor 1.

    A C-clamp's outline (``c_clamp``, ``extruded_clamp``) bounds its triangles' size by its boundary
    edges: below some target the triangulation gives the same mesh whatever is asked (clip3d's
    section: 782 triangles for a target of 450). So for these generators the factor multiplies the
    scene's actual element count (``elements``) where it exceeds the target, and the arcs' default
    sampling (no ``segments`` in the table) follows the section's element size, as the discretization of
    a true arc it is; a given ``segments`` is the part's polygon and is kept.

    Args:
        comp: the scene's ``[compliant]`` table.
        factor: the level's refinement: its element count over the scene's.
        elements: the element count of the scene's own mesh (the level at factor 1), if known.

    Returns:
        The overrides (``target_elements``, and ``layers``, ``segments``, ``mesh_file`` as they apply).
    """
    target = int(comp["target_elements"])
    clamp = comp.get("generator") in CLAMP_GENERATORS
    if clamp and elements is not None and factor != 1.0:
        target = max(target, int(elements))
    out = {"target_elements": int(round(target * factor))}
    section = factor  # the factor of the section's element count
    if comp.get("generator") == "extruded_clamp":
        layers = int(comp.get("layers", 1))
        out["layers"] = max(1, int(round(layers * factor ** (1.0 / 3.0))))
        section = factor * layers / out["layers"]
    if clamp and "segments" not in comp and factor != 1.0:
        out["segments"] = max(4, int(round(C_CLAMP_SEGMENTS * np.sqrt(section))))
    if "mesh_file" in comp and factor != 1.0:
        out["mesh_file"] = None
    return out


def extrapolate(N: np.ndarray, f: np.ndarray, dim: int, finest: int = 4) -> tuple[float, float]:
    """(f_inf, order p in h) of figures f at element counts N (ascending): least-squares fit of
    f = f_inf + b h^p, h = N^(-1/dim), over the ``finest`` levels (exact through three), p searched
    on [0.5, 4] (step 0.01); f[-1] and nan with fewer than three levels or a flat sequence."""
    h = np.asarray(N, float) ** (-1.0 / dim)
    f = np.asarray(f, float)
    if len(f) < 3 or np.ptp(f[-finest:]) == 0:
        return float(f[-1]), float("nan")
    h, f = h[-finest:], f[-finest:]
    best = None
    for p in np.arange(ORDER_RANGE[0], ORDER_RANGE[1] + 1e-4, 0.01):
        A = np.c_[np.ones_like(h), h**p]
        coef, *_ = np.linalg.lstsq(A, f, rcond=None)
        r = float(np.sum((A @ coef - f) ** 2))
        if best is None or r < best[0]:
            best = (r, float(coef[0]), float(p))
    return best[1], best[2]


def convergence_study(scene, factors=(1, 2, 4, 8), *, overrides: dict | None = None, quiet: bool = True,
                      out=None, device: str = "cpu") -> ConvergenceResult:
    """Run the levels and summarize them (:func:`report`); with ``out`` write the study's files there
    (:func:`write_study`).

    Args:
        scene: NAME.xml (with NAME.toml) or a bundled scene's name.
        factors: the levels' refinement factors of the scene's element count.
        overrides: scene table overrides applied at every level.
        quiet: no log lines or progress bars.
        out: folder for the JSON report, CSV and plot; None writes nothing.
        device: Warp device.

    Returns:
        The :class:`ConvergenceResult` (``outputs``: the files written).
    """
    levels = run_levels(scene, factors, overrides=overrides, quiet=quiet, device=device)
    rep = report(str(scene), levels, 2 if _is_2d(scene) else 3)
    return rep if out is None else dataclasses.replace(rep, outputs=write_study(rep, out))


def report(scene: str, levels: list, dim: int) -> ConvergenceResult:
    """Per figure the values, the extrapolated value, the observed order and each level's relative error (a figure
    below ZERO_REL of its kind's peak, e.g. a loose coupling's E_ss, relative to that peak); per level the element
    count and seconds; ``error_of_default``: the errors of the scene's own mesh (factor 1, else the first level);
    ``warnings``: levels that are the same refinement (element counts within SAME_MESH_REL), levels whose whole
    layers are more than LAYERS_OFF_REL off the uniform refinement's, figures whose fitted order is at an end
    of ORDER_RANGE (the levels do not follow h^p: an unreliable extrapolation), and figures whose fitted order is
    below SLOW_ORDER (pre-asymptotic levels: an unreliable extrapolation too)."""
    N = np.array([lv.elements for lv in levels])
    i_default = next((i for i, lv in enumerate(levels) if lv.factor == 1.0), 0)  # the scene's own mesh
    values = {k: np.array([lv.figures[k] for lv in levels]) for k in FIGURES}
    limit, order = {}, {}
    for k in FIGURES:
        limit[k], order[k] = extrapolate(N, values[k], dim)
    # a figure that is ~0 (a loose coupling's E_ss, an ejecting one's F_rm) is relative to its
    # kind's peak: E_max, or the larger of F_in and F_rm
    peak_force = max(("F_in", "F_rm"), key=lambda k: abs(limit[k]))
    figures = {}
    for k in FIGURES:
        peak = "E_max" if k.startswith("E_") else peak_force
        of = peak if abs(limit[k]) < ZERO_REL * abs(limit[peak]) else k
        ref = limit[of]
        figures[k] = FigureConvergence(values=tuple(float(x) for x in values[k]), extrapolated=float(limit[k]),
                                       order=float(order[k]), relative_of=of,
                                       relative_error=tuple(float((x - limit[k]) / ref) if ref else 0.0
                                                            for x in values[k]))
    warnings = []
    for a, b in zip(levels, levels[1:]):
        if abs(b.elements - a.elements) < SAME_MESH_REL * max(a.elements, b.elements):
            warnings.append(f"{scene}: the levels at factors {a.factor:g} and {b.factor:g} have nearly the same mesh "
                            f"({a.elements} and {b.elements} elements: the mesher's floor or cap), so their "
                            "difference says nothing about convergence; choose factors further apart")
    uniform = {i: lv.scene_layers * lv.factor ** (1.0 / 3.0) for i, lv in enumerate(levels) if lv.layers is not None}
    off = [i for i, u in uniform.items() if abs(levels[i].layers - u) > LAYERS_OFF_REL * u]
    if off:
        base = levels[off[0]].scene_layers
        whole = ", ".join(f"{(k / base) ** 3:.4g}" for k in range(base, base + 3))
        warnings.append(f"{scene}: the part is extruded in whole layers, and at factors "
                        f"{', '.join(f'{levels[i].factor:g}' for i in off)} it has "
                        f"{', '.join(str(levels[i].layers) for i in off)} "
                        f"where uniform refinement would give {', '.join(f'{uniform[i]:.2f}' for i in off)}: "
                        "those levels refine the section and the height unequally, and the figures need not follow "
                        f"a power law of the element count; factors {whole} refine uniformly")
    for k, v in figures.items():
        if v.relative_of == k and no_rate(v.order):
            warnings.append(f"{scene}: {k}'s fitted order is at the end of the range searched ({v.order:g}): "
                            "the levels do not follow a power law, so its extrapolation and errors are unreliable")
    slow = [k for k, v in figures.items() if v.relative_of == k and slower_than_h(v.order)]
    if slow:
        linear = all(lv.element_order == 1 for lv in levels)
        verb, noun = ("converges", "order") if len(slow) == 1 else ("converge", "orders")
        warnings.append(f"{scene}: {', '.join(slow)} {verb} slower than h (fitted {noun} "
                        f"{', '.join(f'{figures[k].order:.2f}' for k in slow)}), slower than any part without cracks "
                        "converges once its mesh is fine enough: these levels are pre-asymptotic"
                        + (" (linear elements locked in bending)" if linear else "")
                        + ", so the extrapolation and errors are unreliable; refine further"
                        + (" or study it with element_order = 2 (--element-order 2)" if linear else ""))
    return ConvergenceResult(scene=scene, friction=levels[0].friction if levels else 0.0, warnings=tuple(warnings),
                             levels=tuple(levels), figures=figures,
                             error_of_default={k: v.relative_error[i_default] for k, v in figures.items()})


def no_rate(order: float) -> bool:
    """Whether a fitted order lies at an end of ORDER_RANGE (:func:`extrapolate`): the levels do not
    follow a power law, and the extrapolation and errors are unreliable."""
    return bool(np.isfinite(order)) and min(abs(order - e) for e in ORDER_RANGE) < 1e-9


def slower_than_h(order: float) -> bool:
    """Whether a fitted order is below SLOW_ORDER (and no end of ORDER_RANGE: :func:`no_rate`): pre-asymptotic
    levels, whose extrapolation is unreliable."""
    return bool(np.isfinite(order)) and not no_rate(order) and order < SLOW_ORDER


def _is_2d(scene) -> bool:
    """The refinement is two-dimensional (h ~ N^(-1/2)): a 2D scene."""

    return read_scene_toml(scene_paths(scene)[1]).get("dim", 2) == 2


def format_table(rep: ConvergenceResult) -> str:
    """A compact text table of :func:`convergence_study`'s result (units: J, N; errors in %)."""
    lv = rep.levels
    head = f"{'figure':8s}" + "".join(f"{'N=' + str(x.elements):>12s}" for x in lv) + f"{'extrap.':>12s}{'p':>6s}"
    lines = [f"convergence study: {rep.scene}", head]
    for k, v in rep.figures.items():
        lines.append(f"{k + ' [' + UNITS[k] + ']':8s}" + "".join(f"{x:12.4g}" for x in v.values)
                     + f"{v.extrapolated:12.4g}{v.order:6.2f}")
        lines.append(f"{'  err %':8s}" + "".join(f"{100 * e:12.2f}" for e in v.relative_error)
                     + (f"   (of {v.relative_of})" if v.relative_of != k else ""))
    if any(x.layers is not None for x in lv):  # (an extruded part)
        lines.append(f"{'layers':8s}" + "".join(f"{x.layers:>12}" for x in lv))
    lines.append(f"{'s/run':8s}" + "".join(f"{x.seconds:12.3f}" for x in lv))
    lines.append(f"{'category':8s}" + "".join(f"{x.category:>12s}" for x in lv))
    return "\n".join(lines)


def write_study(rep: ConvergenceResult, out, *, name: str | None = None) -> dict:
    """Write a study into the folder ``out``, the three files together (none on a failure):
    ``NAME_converge.json`` (the result's JSON form, as ``--json`` prints it), ``NAME_converge.csv`` (one row
    per level: factor, elements, layers (an extruded part's, else empty), seconds, category, each figure's
    value and relative error) and ``NAME_converge.png`` (:func:`plot_convergence`).

    Args:
        rep: :func:`convergence_study`'s result.
        out: the output folder.
        name: the files' stem (default: the scene's name).

    Returns:
        {"json", "csv", "png"}: the paths written, as strings.
    """
    stem = safe_name(name or Path(str(rep.scene)).stem) + "_converge"
    paths = {k: Path(out) / f"{stem}.{k}" for k in ("json", "csv", "png")}
    header = ["factor", "elements", "layers", "seconds", "category"]
    for k in FIGURES:
        header += [f"{k}_{UNITS[k]}", f"{k}_relative_error"]
    rows = []
    for i, lv in enumerate(rep.levels):
        row = [lv.factor, lv.elements, "" if lv.layers is None else lv.layers, lv.seconds, lv.category]
        for k in FIGURES:
            row += [rep.figures[k].values[i], rep.figures[k].relative_error[i]]
        rows.append(row)
    with atomic_paths(paths) as tmp:
        write_json(tmp["json"], rep.to_json())
        write_csv(tmp["csv"], header, rows)
        plot_convergence(rep, tmp["png"])
    return {k: str(v) for k, v in paths.items()}


def plain_log_ticks(axis, *, wide: bool = False) -> None:
    """Label the ticks of a logarithmic matplotlib ``axis`` (``ax.xaxis`` / ``ax.yaxis``, its data
    plotted) as plain numbers (3, 5, 10, not 3x10^0): every minor tick where the axis spans at most a
    decade, those at 2 and 5 x 10^k up to three decades (one or two labelled decades are too few to
    read a value from), none beyond (their labels would run into each other). ``wide``: labels too
    wide for every minor tick (five-digit numbers along an x axis) get the 2 and 5 x 10^k rule within a
    decade too."""
    import matplotlib.ticker

    axis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
    lo, hi = sorted(axis.get_view_interval())
    decades = np.log10(hi / lo) if lo > 0 else np.inf
    every = decades <= 1.0 and not wide
    shown = (lambda m: True) if every else (lambda m: m in (2, 5)) if decades <= 3.0 else None
    if shown is None:
        axis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        return

    def label(v, _pos):
        m = int(round(v / 10.0 ** np.floor(np.log10(v) + 1e-9)))  # the tick's leading digit
        return f"{v:g}" if shown(m) else ""

    axis.set_minor_formatter(matplotlib.ticker.FuncFormatter(label))


def plot_convergence(rep: ConvergenceResult, path):
    """Each figure's error against its extrapolated value, |f_k - f_inf| / ref [%], against the element
    count on log-log axes (the legend gives the fitted order p in h, and says where the report warns of it),
    the scene's own mesh marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    N = np.array([lv.elements for lv in rep.levels], dtype=float)
    fig, ax = plt.subplots(figsize=(8.6, 4.2), dpi=120)
    for k in FIGURES:
        v = rep.figures[k]
        e = 100.0 * np.abs(np.asarray(v.relative_error, dtype=float))
        shown = e > 0  # (a level at the extrapolated value exactly has no place on a log axis)
        if not shown.any():
            continue
        p = v.order
        rel = "" if v.relative_of == k else f" of {v.relative_of}"
        fit = "no fit" if not np.isfinite(p) else f"order {p:.2f} in h" + (
            ": no power law" if no_rate(p) else ": pre-asymptotic" if slower_than_h(p) else "")
        label = f"{k}{rel} ({fit})"
        ax.loglog(N[shown], e[shown], "o-", lw=1.5, ms=5, label=label)
    default = [lv.elements for lv in rep.levels if lv.factor == 1.0]
    if default:
        ax.axvline(default[0], color="0.5", ls=":", lw=1.0, label="the scene's mesh")
    ax.set_xlabel("elements [-]")
    ax.set_ylabel("error against the extrapolated value [%]")
    plain_log_ticks(ax.yaxis)
    ax.set_xticks(N, [f"{n:,.0f}" for n in N])  # (the levels' element counts)
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    mu = f", friction {rep.friction:g}" if rep.friction else ""
    ax.set_title(f"{Path(str(rep.scene)).stem}: mesh convergence{mu}")
    ax.grid(True, which="both", color="0.9", lw=0.6)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))  # (beside the axes: off the lines)
    fig.tight_layout()
    try:
        return save_figure(fig, path)
    finally:
        plt.close(fig)
