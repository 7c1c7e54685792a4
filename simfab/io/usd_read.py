"""Reading USD stages for rendering and inspection: opening with one-line errors, time codes,
meshes, basis curves, points and the scalar fields :class:`simfab.io.usd.StageWriter` wrote."""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import NamedTuple

import numpy as np
from pxr import Usd, UsdGeom

from simfab.errors import InputError


def open_stage(path: str | os.PathLike):
    """Open a USD stage for reading; InputError (one line, naming the file) when it is missing,
    truncated or not USD at all (USD's own multi-line C++ diagnostics are not passed on)."""
    from pxr import Tf

    path = Path(path)
    if not path.is_file():
        raise InputError("file not found", where=str(path))
    try:
        with _quiet_tf():
            stage = Usd.Stage.Open(str(path))
    except Tf.ErrorException as e:
        msg = " ".join(str(e).split())
        m = re.search(r"\.usda?:(\d+):(\d+): ", msg)
        why = (f"parse error at line {m.group(1)}, column {m.group(2)}: truncated or not USD" if m else
               "corrupt binary crate" if "crate" in msg.lower() else "USD could not parse it")
        raise InputError(f"not a readable USD stage ({why})", where=str(path)) from None
    if stage is None:
        raise InputError("not a readable USD stage", where=str(path))
    return stage


class _quiet_tf:
    """Keep USD's diagnostic delegate from printing warnings/errors on stderr while opening."""

    def __enter__(self):
        from pxr import Tf

        self._mark = Tf.Error.Mark()
        return self

    def __exit__(self, *exc):
        self._mark.Clear()
        return False


def stage_time(stage, time: float | None, *, where: str = "--time") -> tuple[float, str | None]:
    """The time code to read: ``time`` (finite) clamped into the stage's [start, end], or the
    end time code when None. Returns (time code, warning or None)."""
    lo, hi = float(stage.GetStartTimeCode()), float(stage.GetEndTimeCode())
    if time is None:
        return hi, None
    t = float(time)
    if not np.isfinite(t):
        raise InputError(f"must be a finite time code, got {time}", where=where)
    if stage.HasAuthoredTimeCodeRange() and not lo <= t <= hi:
        c = min(max(t, lo), hi)
        return c, f"time code {t:g} is outside the stage's range [{lo:g}, {hi:g}]; drawing {c:g}"
    return t, None


def read_curves_at(path_or_stage, time: float | None = None):
    """Basis curves and points of a stage at a time code, in world coordinates.

    Returns ``(curves, points)``: curves a list of ``(prim_path, [polyline (k_i, 3)], [widths (k_i,) or None],
    rgb (3,) or None)``; points a list of ``(prim_path, P (n, 3), widths (n,) or None, rgb (3,) or None)``.
    Widths are diameters [stage units]. Invisible prims are skipped.
    """
    stage = path_or_stage if isinstance(path_or_stage, Usd.Stage) else open_stage(path_or_stage)
    tc = Usd.TimeCode(stage_time(stage, time)[0])
    cache = UsdGeom.XformCache(tc)
    curves, points = [], []
    for prim in stage.Traverse():
        is_curves, is_points = prim.IsA(UsdGeom.BasisCurves), prim.IsA(UsdGeom.Points)
        if not (is_curves or is_points):
            continue
        if UsdGeom.Imageable(prim).ComputeVisibility(tc) == UsdGeom.Tokens.invisible:
            continue
        g = UsdGeom.PointBased(prim)
        pts = g.GetPointsAttr().Get(tc)
        if pts is None or len(pts) == 0:
            continue
        m = np.asarray(cache.GetLocalToWorldTransform(prim), dtype=np.float64)
        pts = np.asarray(pts, dtype=np.float64) @ m[:3, :3] + m[3, :3]
        w = UsdGeom.Curves(prim).GetWidthsAttr().Get(tc) if is_curves else UsdGeom.Points(prim).GetWidthsAttr().Get(tc)
        w = None if w is None or len(w) == 0 else np.broadcast_to(np.asarray(w, np.float64), (len(pts),)) \
            if len(w) in (1, len(pts)) else None
        dc = UsdGeom.Gprim(prim).GetDisplayColorPrimvar()
        rgb = np.asarray(dc.Get(tc), np.float64)[0] if dc and dc.HasValue() and len(dc.Get(tc)) else None
        if is_points:
            points.append((str(prim.GetPath()), pts, w, rgb))
            continue
        counts = np.asarray(UsdGeom.BasisCurves(prim).GetCurveVertexCountsAttr().Get(tc) or [], np.int64)
        if counts.sum() != len(pts):
            continue
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        curves.append((str(prim.GetPath()), [pts[s:s + k] for s, k in zip(starts, counts)],
                       [None if w is None else w[s:s + k] for s, k in zip(starts, counts)], rgb))
    return curves, points


class ScalarField(NamedTuple):
    """A scalar primvar's colouring (:func:`read_scalar_at`).

    Args:
        name: the primvar's name.
        cmap: its matplotlib colormap.
        range: (lo, hi) of the colours: the fixed range the writer was given, else the values' own at the time.
        units: the values' unit, or None.
        clipped: some values of the timeline lie above the fixed range (they take its top colour).
    """

    name: str
    cmap: str
    range: tuple
    units: str | None
    clipped: bool


def read_scalar_at(stage, time: float | None = None) -> ScalarField | None:
    """The first scalar primvar written by :meth:`StageWriter.set_scalar` on a visible prim at the time
    code, or None."""
    tc = Usd.TimeCode(stage_time(stage, time)[0])
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.Gprim) or UsdGeom.Imageable(prim).ComputeVisibility(tc) == UsdGeom.Tokens.invisible:
            continue
        for pv in UsdGeom.PrimvarsAPI(prim).GetPrimvars():
            attr = pv.GetAttr()
            cmap = attr.GetCustomDataByKey("simfab:colormap")
            if not cmap:
                continue
            rng = attr.GetCustomDataByKey("simfab:range")
            if rng is not None and len(rng) == 2:
                lo, hi = float(rng[0]), float(rng[1])
            else:
                v = np.asarray(pv.Get(tc), np.float64)
                if not len(v):
                    continue
                lo, hi = float(v.min()), float(v.max())
            return ScalarField(name=str(pv.GetPrimvarName()), cmap=str(cmap), range=(lo, hi),
                               units=attr.GetCustomDataByKey("simfab:units"),
                               clipped=bool(attr.GetCustomDataByKey("simfab:clipped")))
    return None


def read_mesh_at(path: str | os.PathLike, time: float | None = None):
    """All meshes of a stage at a time code, in world coordinates.

    Returns a list of ``(prim_path, points (n, 3), faces (m, 3) triangulated, rgb (m, 3) or None)``;
    ``time=None`` means the stage's end time code. Invisible prims are skipped.
    """
    stage = path if isinstance(path, Usd.Stage) else open_stage(path)
    tc = Usd.TimeCode(stage_time(stage, time)[0])
    cache = UsdGeom.XformCache(tc)
    out = []
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.Mesh):
            continue
        if UsdGeom.Imageable(prim).ComputeVisibility(tc) == UsdGeom.Tokens.invisible:
            continue
        mesh = UsdGeom.Mesh(prim)
        pts = np.asarray(mesh.GetPointsAttr().Get(tc), dtype=np.float64)
        counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(tc), dtype=np.int64)
        idx = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(tc), dtype=np.int64)
        if len(pts) == 0 or len(counts) == 0:
            continue
        m = np.asarray(cache.GetLocalToWorldTransform(prim), dtype=np.float64)  # row-vector convention
        pts = pts @ m[:3, :3] + m[3, :3]
        tris, owner = _triangulate(counts, idx)
        rgb = None
        dc = UsdGeom.Gprim(prim).GetDisplayColorPrimvar()
        if dc and dc.HasValue():
            col = np.asarray(dc.Get(tc), dtype=np.float64)
            interp = dc.GetInterpolation()
            if interp == "uniform" and len(col) == len(counts):
                rgb = col[owner]
            elif interp in ("vertex", "varying") and len(col) == len(pts):
                rgb = col[tris].mean(axis=1)
            elif len(col) >= 1:
                rgb = np.repeat(col[:1], len(tris), axis=0)
        out.append((str(prim.GetPath()), pts, tris, rgb))
    return out


def _triangulate(counts: np.ndarray, idx: np.ndarray):
    """Fan-triangulate polygons; return triangles (t, 3) and the owning face of each."""
    if np.all(counts == 3):
        return idx.reshape(-1, 3), np.arange(len(counts))
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    tris, owner = [], []
    for f, (s, c) in enumerate(zip(starts, counts)):
        for j in range(1, c - 1):
            tris.append((idx[s], idx[s + j], idx[s + j + 1]))
            owner.append(f)
    return np.asarray(tris, dtype=np.int64).reshape(-1, 3), np.asarray(owner, dtype=np.int64)
