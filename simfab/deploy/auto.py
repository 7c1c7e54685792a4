"""Defaults decided from the target: spacing, cuts, insert catalogue, layout and tuning.

What a scene file (or a command-line flag) leaves unset is decided here, before the pipeline runs:

- spacing h: sqrt(A / CELLS) for the surface area A, at most ``CURVATURE_SPACING`` / sqrt(K_med)
  (the median |Gaussian curvature|: a cell spans a bounded angle of the surface), rounded down to
  a millimetre, within ``SPACING_RANGE``; below its lower end (the smallest cell the default beams,
  beam ends, gaps and inserts fit) down to ``FEATURE_SCALE_MIN`` of it, with those features scaled
  by h / ``SPACING_RANGE[0]`` (``FEATURES``, when the scene sets none of them);
- cuts: the growth each interior vertex needs, d = (h/2)(e^{-u} - 1) of the uncut flattening
  (:mod:`simfab.deploy.pattern`), must fit a catalogue of at most ``MAX_SIZES`` sizes between
  ``MIN_INSERT`` and h/2 - beam_width, and the cells' growth e^{-u} the springs' reach
  (``[cuts] max_growth``); if not, cones and cuts (``[cuts] max_cones = MAX_CONES``, seams tied) until
  every vertex's growth is within reach (:func:`simfab.deploy.cuts.place_cones`);
- the catalogue (:func:`catalogue`): from the flattening (cut, with cuts) the target will get,
  the fewest sizes covering every vertex's growth with room for the tuning (``TUNE_ROOM``),
  smallest inserts first; with cuts, sizes for the seams' short edges (``SEAM_EDGE``, ``SEAM_SIZES``);
- layout: ``conforming`` (grid core, regular, growths fitted to the edges) without cuts, ``mesh``
  with them or where the conforming one covers less than ``MIN_COVERED`` of the flat domain;
- tuning: on (``AUTO_TUNE``; the point weight from the share of the area that is not
  saddle-shaped, :func:`point_weight`; a height row beyond the stop's height tolerance), stopping
  once the deviation bound is met, when progress stalls or at its budget of steps.

:func:`complete` returns the scene with these filled in and :class:`Decisions` (what was decided
and why, for the summary).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from simfab.errors import InputError

CELLS = 64  # cells aimed at over the surface
CURVATURE_SPACING = 0.25  # h <= this / sqrt(median |K|) [-]
SPACING_RANGE = (0.02, 0.08)  # [m]
MIN_INSERT = 0.003  # smallest insert half-size [m] (at the features' full size)
#: the pattern's features that scale with a cell below SPACING_RANGE[0] (a strongly curved target: the
#: 3 mm beams, 4 mm beam ends, 1.5 mm gaps and 3 mm inserts leave no gap range in smaller cells), down to this
#: fraction of their size; MIN_INSERT scales with them
FEATURE_SCALE_MIN = 0.6
FEATURES = ("beam_width", "min_beam", "min_gap", "spring_width")
MAX_SIZES = 3  # insert sizes in a catalogue
SIZE_STEP = 0.0005  # catalogue sizes rounded to this [m]
MARGIN = 0.0005  # gap margin kept from either achievable limit [m] (layouts' edges differ from h)
MAX_CONES = 8
#: the largest cell growth e^{-u} of the uncut flattening a target may ask for (cones take a steep cap's ~2x
#: to the springs' reach); beyond it the mesh has a spike or fold and is refused before any heavy work
MAX_PLAUSIBLE_GROWTH = 50.0
#: the share of the (cut) flat domain a decided layout covers at least: a conforming layout below it (a
#: narrow outline its grid core cannot follow) is replaced by the mesh layout (:func:`simfab.deploy.pipeline.run`)
MIN_COVERED = 0.99
#: the fraction of the gap range kept free at either end of every insert's gap when the catalogue is sized
#: (when its sizes can): the tuning moves gaps by millimetres, and an insert whose gap sits at a limit cannot
#: grow or shrink further (a single size fitted to the largest growth left a steep cap's tuned gaps at min_gap)
TUNE_ROOM = 0.2
#: the shortest edges at an insert along a cut's seams, relative to the spacing (the mesh layout divides each
#: seam into equal edges of about the spacing; where seams and the outline meet they run down to ~0.5 h): with
#: cuts the catalogue adds the smaller sizes such an insert needs for its gap to be achievable
SEAM_EDGE = 0.5
#: sizes the seams' short edges may add beyond ``MAX_SIZES`` (a full catalogue left a steep cap's seam insert
#: with no achievable gap: its short edges hold a smaller gap than its size asks for)
SEAM_SIZES = 1
#: the tuning on by default: Gauss-Newton steps, towards the surface, each vertex's own point and (beyond
#: the stop's height tolerance) the target's height, w_h = 0.2 (the surface distance alone lets a saddle's
#: height drift: the point weight is 0 there, :func:`point_weight`); it stops at the bound (RMS 0.75 % of
#: the diameter, three quarters of the deployment bound, and the height within 2 %, two thirds of its bound;
#: both measured as the run's deviation is: a margin, not a second goal - each step past the bound costs an
#: equilibrium per trial for a figure the bound does not ask for), when two steps in a row gain < 2 %, or after 8 steps.
#: Its budget is counted in steps, not seconds, so that the same input gives the same pattern on any machine and load
#: (``[tune] seconds`` sets a wall-clock budget too).
AUTO_TUNE = dict(iterations=8, point_weight=3.0, escalations=2, target_rms=0.0075, target_height=0.02, min_gain=0.02,
                 height_weight=0.2)


@dataclass(frozen=True, kw_only=True)
class Decisions:
    """What :func:`complete` decided: the fields it set (``scene table.field``), whether the target
    needs cuts and why (``uncut_unreachable``: interior vertices no catalogue of ``MAX_SIZES`` sizes
    reaches uncut; ``uncut_growth_max``: the largest cell growth e^{-u} uncut)."""

    decided: tuple
    needs_cuts: bool
    uncut_unreachable: int
    uncut_growth_max: float
    min_insert: float = MIN_INSERT


def spacing(target, *, floor: float = SPACING_RANGE[0]) -> float:
    """The default spacing [m] of a target (see module doc), at least ``floor`` [m]."""
    from simfab.deploy.flatten import face_areas

    V, F = target.V, target.F
    area = float(np.sum(face_areas(V, F)))
    h = np.sqrt(area / CELLS)
    K = _vertex_curvature(V, F)
    k_med = float(np.median(np.abs(K)))
    if k_med > 0:
        h = min(h, CURVATURE_SPACING / np.sqrt(k_med))
    return float(np.clip(np.floor(h * 1e3) / 1e3, floor, SPACING_RANGE[1]))


def point_weight(target) -> float:
    """The tuning's point weight w for a target: ``AUTO_TUNE["point_weight"]`` times the share of its
    area that is not saddle-shaped (K >= -1/(4 A), A the target's area: curvature radii beyond twice
    sqrt(A), about the target's size, count as flat), to a tenth. The point term holds each vertex to
    its own target point where the distance to the surface alone lets the deployed shape slide along
    the target (a cap turns within its sphere, a cylinder slides along and around its axis); a saddle
    holds its place by its shape, and the point term there pulls against tangential offsets the gaps
    cannot remove (w = 0)."""
    from simfab.deploy.flatten import face_areas

    V, F = target.V, target.F
    K = _vertex_curvature(V, F)
    a = np.bincount(F.ravel(), weights=np.repeat(face_areas(V, F) / 3, 3), minlength=len(V))
    inner = K != 0
    if not inner.any():
        return float(AUTO_TUNE["point_weight"])
    saddle = K < -1.0 / (4.0 * np.sum(a))
    return round(float(AUTO_TUNE["point_weight"] * (1.0 - np.sum(a[saddle]) / np.sum(a[inner]))), 1)


def _vertex_curvature(V, F) -> np.ndarray:
    """Angle defect over a third of the incident faces' area at interior vertices [1/m^2] (0 on the boundary)."""
    from simfab.deploy import flatten as bff

    n = len(V)
    ang = bff.corner_angles(V, F)
    area = np.bincount(F.ravel(), weights=np.repeat(bff.face_areas(V, F) / 3, 3), minlength=n)
    K = (2 * np.pi - np.bincount(F.ravel(), weights=ang.ravel(), minlength=n)) / np.maximum(area, 1e-300)
    K[bff.boundary_loop(F, n)] = 0.0
    return K


def catalogue(d: np.ndarray, h: float, pc, *, room: float = 0.0, short: float = 1.0,
              min_insert: float = MIN_INSERT) -> tuple[list, int]:
    """The fewest insert sizes [m] that give every growth ``d`` (n,) [m] an achievable gap
    ``min_gap + m <= r - d <= s h/2 - min_beam - m``, m = MARGIN + ``room`` x (s h/2 - min_beam - min_gap)
    (``room``: the fraction of the gap range kept free at either end for the tuning; s = ``short``: the
    inserts' edges relative to h, e.g. along seams): greedily, the
    largest uncovered growth sets the next (smaller) size r = d + min_gap + m (rounded up to
    ``SIZE_STEP``, at least ``min_insert``). Returns (sizes ascending, growths left uncovered by
    ``MAX_SIZES`` sizes or above the largest size the plates allow, r < h/2 - beam_width)."""
    m = MARGIN + room * (short * h / 2 - pc.min_beam - pc.min_gap)
    lo, hi = pc.min_gap + m, short * h / 2 - pc.min_beam - m
    r_max = h / 2 - pc.beam_width - SIZE_STEP
    left = np.sort(np.asarray(d, dtype=np.float64))[::-1]
    sizes = []
    while len(left) and len(sizes) < MAX_SIZES:
        r = max(np.ceil((left[0] + lo) / SIZE_STEP - 1e-9) * SIZE_STEP, min_insert)
        if r > r_max or (sizes and r >= sizes[-1]):  # a plate larger than the cell allows / no smaller size helps
            break
        g = r - left
        sizes.append(round(float(r), 6))
        left = left[~((g >= lo - 1e-12) & (g <= hi + 1e-12))]
    return sorted(sizes), int(len(left))


def complete(scene, given: dict):
    """The scene with every field that ``given`` ({"pattern": set of field names, "cuts": ...,
    "tune": ...}: set by the scene file or a flag) does not name decided from its target.

    Args:
        scene: a :class:`simfab.deploy.scene.SurfaceScene`.
        given: the fields set explicitly, per table.

    Returns:
        (scene, :class:`Decisions`).
    """
    from simfab.deploy import cuts, flatten, pattern

    tgt = scene.target
    gp, gc, gt = given.get("pattern", set()), given.get("cuts", set()), given.get("tune", set())
    decided = []
    pc, cc, tc = scene.pattern, scene.cuts, scene.tune
    upd = {}
    scale = 1.0
    if "spacing" not in gp:
        free = not ({*FEATURES, "beam_thickness"} & gp)  # the features scale with the cell unless the scene sets them
        upd["spacing"] = spacing(tgt, floor=SPACING_RANGE[0] * (FEATURE_SCALE_MIN if free else 1.0))
        decided.append("pattern.spacing")
        scale = min(1.0, upd["spacing"] / SPACING_RANGE[0])
    if "spring_width" not in gp:
        upd["spring_width"] = 0.001
        decided.append("pattern.spring_width")
    if scale < 1.0:
        for k in FEATURES:
            upd[k] = round(scale * upd.get(k, getattr(pc, k)), 6)
        decided += [f"pattern.{k}" for k in FEATURES if f"pattern.{k}" not in decided]
    pc = dataclasses.replace(pc, **{k: v for k, v in upd.items() if k in FEATURES})
    min_insert = round(scale * MIN_INSERT / SIZE_STEP) * SIZE_STEP
    h = upd.get("spacing", pc.spacing)
    pattern.check_cell_count(float(np.sum(flatten.face_areas(tgt.V, tgt.F))), h)
    sizes_given = bool({"insert_half_size", "insert_half_sizes"} & gp)
    f = flatten.flatten(tgt.V, tgt.F)
    interior = np.ones(len(tgt.V), dtype=bool)
    interior[f.boundary] = False
    d0 = 0.5 * h * np.expm1(-f.u[interior])
    _, left0 = catalogue(d0, h, pc, min_insert=min_insert)
    growth0 = float(np.exp(-f.u.min()))
    if growth0 > MAX_PLAUSIBLE_GROWTH:  # a spike or fold of the mesh, not a surface a pattern can follow
        v = int(np.argmin(f.u))
        raise InputError(f"the flattening grows the cells at vertex {v} ({', '.join(f'{c:.4g}' for c in tgt.V[v])} m) "
                         f"by {growth0:.3g}x (a spike or fold in the mesh?): no pattern deploys beyond "
                         f"{MAX_PLAUSIBLE_GROWTH:g}x", where=getattr(scene, "path", "target"))
    needs = left0 > 0 or growth0 > cc.max_growth
    if "max_cones" not in gc and needs:
        cc = dataclasses.replace(cc, max_cones=MAX_CONES, **({} if "join_seams" in gc else {"join_seams": True}))
        decided += ["cuts.max_cones"] + ([] if "join_seams" in gc else ["cuts.join_seams"])
    cut = cc.max_cones > 0
    if not sizes_given:
        if cut:  # the cones' u: placed with every size the plates allow (the springs' reach decides)
            wide = dataclasses.replace(pc, spacing=h, insert_half_sizes=tuple(
                np.arange(min_insert, h / 2 - pc.beam_width - 1e-9, SIZE_STEP)))
            cones, u = cuts.place_cones(tgt.V, tgt.F, cc, wide)
            d = 0.5 * h * np.expm1(-u[interior & ~np.isin(np.arange(len(u)), cones)])
        else:
            d = d0
        sizes, left = catalogue(d, h, pc, room=TUNE_ROOM, min_insert=min_insert)
        if left:  # no room for the tuning at either end: the achievable range alone
            sizes, _ = catalogue(d, h, pc, min_insert=min_insert)
        if cut and sizes:  # the seams' short edges: smaller sizes where needed
            # (edges so short that no gap fits in them cannot be served: the shortest with a gap range)
            short = max(SEAM_EDGE, 2 * (pc.min_gap + pc.min_beam + 2 * MARGIN + SIZE_STEP) / h)
            g = np.asarray(sizes)[None, :] - d[:, None]
            ok = np.any((g >= pc.min_gap + MARGIN) & (g <= short * h / 2 - pc.min_beam - MARGIN), axis=1)
            if not ok.all():
                extra, _ = catalogue(d[~ok], h, pc, short=short, min_insert=min_insert)
                room = max(MAX_SIZES - len(sizes), SEAM_SIZES)
                sizes = sorted({*sizes, *[r for r in extra[::-1] if r not in sizes][:room]})
        if sizes:
            upd["insert_half_sizes"] = tuple(sizes)
            decided.append("pattern.insert_half_sizes")
        elif not dataclasses.replace(pc, spacing=h).plates_fit():  # no size fits the cell, the default neither
            raise InputError(f"no insert fits a {1e3 * h:.3g} mm cell: an insert's plates (half-side r >= "
                             f"{1e3 * min_insert:.3g} mm) and their {1e3 * pc.beam_width:.3g} mm beams need r + "
                             "beam_width < spacing / 2 (a larger spacing, or narrower beams: pattern.beam_width)",
                             where="pattern.spacing")
    if "layout" not in gp:
        upd["layout"] = "mesh" if cut else "conforming"
        decided.append("pattern.layout")
        if not cut:
            for k, v in (("conforming_core", "regular"), ("growth_fit", "edges")):
                if k not in gp:
                    upd[k] = v
                    decided.append(f"pattern.{k}")
    if "iterations" not in gt or tc.iterations > 0:  # steps given (--tune N): the rest still decided
        auto_tune = {**AUTO_TUNE, "point_weight": point_weight(tgt)}
        tc = dataclasses.replace(tc, **{k: v for k, v in auto_tune.items() if k not in gt})
        decided += [f"tune.{k}" for k in auto_tune if k not in gt]
    pc = dataclasses.replace(pc, **upd)
    return (dataclasses.replace(scene, pattern=pc, cuts=cc, tune=tc),
            Decisions(decided=tuple(decided), needs_cuts=bool(needs), uncut_unreachable=int(left0),
                      uncut_growth_max=growth0, min_insert=float(min_insert)))


def unreachable_size(pat, decisions: Decisions) -> float | None:
    """One more catalogue size [m] for the inserts the layout left with no achievable gap, or None.

    The catalogue is sized before the layout, from the flattening's growths and an estimate of the
    seams' shortest edges (``SEAM_EDGE``); an insert whose laid-out edges hold a smaller gap range
    than that estimate (an outline corner, a seam's end) can still find no size: growth d = r - g_req,
    its gap range [min_gap, g_max] (the layout's cut gap where the required one is beyond it). A size
    r in [min_gap + d + MARGIN, g_max + d - MARGIN], rounded to ``SIZE_STEP`` and at least the
    decided smallest insert, serves it; the one serving the most of them is returned (None when the
    catalogue was given, when the layout left nothing unreachable or when no such size exists).

    Args:
        pat: the laid-out :class:`simfab.deploy.pattern.Pattern`.
        decisions: the :class:`Decisions` the scene was completed with.

    Returns:
        The half-size [m], or None.
    """
    if "pattern.insert_half_sizes" not in decisions.decided or not len(pat.unreachable):
        return None
    v = np.asarray(pat.unreachable)
    min_gap = pat.config.min_gap
    d = pat.insert_size[v] - pat.gap_required[v]
    g_max = np.where(pat.gap_required[v] > pat.gap[v], pat.gap[v], np.inf)  # beyond reach: the gap cut there
    lo = np.maximum(np.ceil((min_gap + d + MARGIN) / SIZE_STEP - 1e-9) * SIZE_STEP, decisions.min_insert)
    hi = np.floor((g_max + d - MARGIN) / SIZE_STEP + 1e-9) * SIZE_STEP
    best, served = None, 0
    for r in np.unique(np.concatenate([lo, hi[np.isfinite(hi)]])):
        n = int(np.sum((lo <= r + 1e-12) & (r <= hi + 1e-12)))
        if n > served and r > 0 and r not in pat.config.sizes:
            best, served = round(float(r), 6), n
    return best
