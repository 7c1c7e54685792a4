"""USD stages with time samples: deforming meshes, curves, points and rigid bodies.

One :class:`StageWriter` collects a whole timeline and writes it atomically on
:meth:`StageWriter.save` (the stage is built in memory, exported to a temporary file in
the target folder, then renamed), so an interrupted run never leaves a half-written
stage. Stages carry ``defaultPrim`` (``/World``), ``upAxis``, ``metersPerUnit``,
``timeCodesPerSecond`` and start/end time codes covering every sample written, and pass
``pxr.UsdUtils.ComplianceChecker`` (see :func:`check_compliance`).

Conventions: ``name`` arguments are slash-separated prim paths below ``/World``
("growth/skeleton"), each component a valid USD identifier (letters, digits, underscore, not
starting with a digit); missing parents are created as ``Xform`` prims.

- Points may be (n, 3) or (n, 2); 2D points are placed in the z = 0 plane.
- Time codes ``t`` are floats (usually the integer step index).
- Quaternions are (w, x, y, z), as in MuJoCo.

Example::

    w = StageWriter("out/insertion.usda", meters_per_unit=1.0)
    w.add_mesh("part", faces, rest_points)
    for k, x in enumerate(states):
        w.set_points("part", x, k)
        w.set_scalar("part", "von_mises", vm[k], k, interpolation="uniform")
    w.save()
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, Vt

from simfab.errors import InputError
from simfab.io.atomic import atomic_path
from simfab.io.usd_read import open_stage, read_curves_at, read_mesh_at, read_scalar_at, stage_time  # noqa: F401

_IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_INTERP = {"vertex", "uniform", "constant", "faceVarying", "varying"}


def as_points3(points) -> np.ndarray:
    """(n, 2) or (n, 3) array -> (n, 3) float64; 2D points go to z = 0."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] not in (2, 3):
        raise ValueError(f"points must be (n, 2) or (n, 3), got shape {p.shape}")
    if p.shape[1] == 2:
        p = np.column_stack([p, np.zeros(len(p))])
    if not np.all(np.isfinite(p)):
        raise ValueError("points contain NaN or infinite values")
    return p


def scalar_colors(values, *, cmap: str = "viridis", vmin: float | None = None, vmax: float | None = None) -> np.ndarray:
    """Map scalars (k,) to RGB (k, 3) in [0, 1] with a matplotlib colormap (non-finite -> grey)."""
    import matplotlib

    v = np.asarray(values, dtype=np.float64).ravel()
    finite = np.isfinite(v)
    lo = float(np.min(v[finite])) if vmin is None and finite.any() else (vmin if vmin is not None else 0.0)
    hi = float(np.max(v[finite])) if vmax is None and finite.any() else (vmax if vmax is not None else 1.0)
    span = hi - lo if hi > lo else 1.0
    u = np.clip((np.where(finite, v, lo) - lo) / span, 0.0, 1.0)
    rgb = matplotlib.colormaps[cmap](u)[:, :3]
    rgb[~finite] = 0.5
    return rgb


def _constant_color(gprim, color) -> None:
    """Constant ``displayColor`` (RGB in [0, 1]) on a gprim; None leaves it unset."""
    if color is None:
        return
    colors = Vt.Vec3fArray.FromNumpy(np.asarray([color], np.float32))
    gprim.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant).Set(colors)


class StageWriter:
    """Build a time-sampled USD stage in memory and write it atomically.

    Parameters
    ----------
    path : output file (``.usda``, ``.usdc`` or ``.usd``).
    up_axis : "Z" (default; simfab and MuJoCo are z-up) or "Y".
    meters_per_unit : stage linear unit; simfab writes SI, so 1.0.
    time_codes_per_second : playback rate of the timeline.
    """

    def __init__(self, path: str | os.PathLike, *, up_axis: str = "Z", meters_per_unit: float = 1.0,
                 time_codes_per_second: float = 24.0):
        self.path = Path(path)
        if self.path.suffix not in (".usda", ".usdc", ".usd"):
            raise InputError("USD output must end in .usda, .usdc or .usd", where=str(path))
        if up_axis not in ("Y", "Z"):
            raise ValueError("up_axis must be 'Y' or 'Z'")
        self.stage = Usd.Stage.CreateInMemory()
        UsdGeom.SetStageUpAxis(self.stage, UsdGeom.Tokens.z if up_axis == "Z" else UsdGeom.Tokens.y)
        UsdGeom.SetStageMetersPerUnit(self.stage, float(meters_per_unit))
        self.stage.SetTimeCodesPerSecond(float(time_codes_per_second))
        self.stage.SetFramesPerSecond(float(time_codes_per_second))
        root = UsdGeom.Xform.Define(self.stage, "/World")
        self.stage.SetDefaultPrim(root.GetPrim())
        self._times: list[float] = []
        self._kinds: dict[str, str] = {}

    # ------------------------------------------------------------------ helpers
    def _path(self, name: str) -> str:
        parts = [p for p in str(name).split("/") if p]
        if not parts:
            raise ValueError("empty prim name")
        for p in parts:
            if not _IDENT.match(p):
                raise ValueError(f"{p!r} is not a valid USD prim name (letters, digits, underscore)")
        acc = "/World"
        for p in parts[:-1]:
            acc += "/" + p
            if not self.stage.GetPrimAtPath(acc).IsValid():
                UsdGeom.Xform.Define(self.stage, acc)
        return acc + "/" + parts[-1]

    def _prim(self, name: str, kind: str | None = None):
        path = self._path(name)
        prim = self.stage.GetPrimAtPath(path)
        if not prim.IsValid():
            raise KeyError(f"no prim {name!r} in the stage; add it first")
        if kind is not None and self._kinds.get(path) != kind:
            raise TypeError(f"prim {name!r} is a {self._kinds.get(path)}, not a {kind}")
        return prim

    def _time(self, t):
        if t is None:
            return Usd.TimeCode.Default()
        t = float(t)
        self._times.append(t)
        return Usd.TimeCode(t)

    def _set_extent(self, prim, pts: np.ndarray, pad: float, tc):
        lo = pts.min(axis=0) - pad if len(pts) else np.zeros(3)
        hi = pts.max(axis=0) + pad if len(pts) else np.zeros(3)
        UsdGeom.Boundable(prim).CreateExtentAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*lo), Gf.Vec3f(*hi)]), tc)

    # ------------------------------------------------------------------ meshes
    def add_mesh(self, name: str, faces, points=None, *, color=None, double_sided: bool = True) -> str:
        """Define a mesh with fixed topology.

        faces : (m, k) int polygon vertex indices (k = 3 triangles, 4 quads).
        points : optional rest/static points (n, 2|3), written as the default (untimed) value.
        color : optional constant RGB in [0, 1].
        """
        f = np.asarray(faces, dtype=np.int64)
        if f.ndim != 2:
            raise ValueError(f"faces must be (m, k), got shape {f.shape}")
        path = self._path(name)
        mesh = UsdGeom.Mesh.Define(self.stage, path)
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray([int(f.shape[1])] * len(f)))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray(f.ravel().tolist()))
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mesh.CreateDoubleSidedAttr(bool(double_sided))
        self._kinds[path] = "mesh"
        if points is not None:
            self.set_points(name, points, None)
        _constant_color(mesh, color)
        return path

    def set_points(self, name: str, points, t=None, *, widths=None) -> None:
        """Positions of a mesh, points or curves prim at time code ``t`` (None = default value).

        widths : (n,) per-point widths [stage units] for points prims.
        """
        prim = self._prim(name)
        pts = as_points3(points)
        tc = self._time(t)
        geom = UsdGeom.PointBased(prim)
        geom.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(pts.astype(np.float32)), tc)
        pad = 0.0
        if widths is not None:
            w = np.broadcast_to(np.asarray(widths, np.float32), (len(pts),))
            UsdGeom.Points(prim).CreateWidthsAttr().Set(Vt.FloatArray.FromNumpy(np.ascontiguousarray(w)), tc)
            UsdGeom.Points(prim).SetWidthsInterpolation(UsdGeom.Tokens.vertex)
            pad = float(w.max(initial=0.0)) / 2
        self._set_extent(prim, pts, pad, tc)

    def set_scalar(self, name: str, primvar: str, values, t=None, *, interpolation: str = "vertex",
                   cmap: str = "viridis", vmin: float | None = None, vmax: float | None = None,
                   units: str | None = None) -> None:
        """A float primvar (per vertex or per face) plus ``displayColor`` from ``cmap``.

        values : (n,) for interpolation "vertex", (m,) for "uniform" (per face).
        vmin, vmax : colormap range (default: this sample's min and max); values beyond it take the
            colormap's end colours, and a sample above vmax marks the primvar ``simfab:clipped``.
        units : the values' unit, kept with the colormap and a fixed range in the primvar's
            customData (``simfab:colormap``, ``simfab:range``, ``simfab:units``) so a renderer can
            draw the colour bar (:func:`read_scalar_at`).
        """
        if interpolation not in _INTERP:
            raise ValueError(f"interpolation must be one of {sorted(_INTERP)}")
        if not _IDENT.match(primvar):
            raise ValueError(f"{primvar!r} is not a valid primvar name")
        prim = self._prim(name)
        v = np.asarray(values, dtype=np.float64).ravel()
        tc = self._time(t)
        api = UsdGeom.PrimvarsAPI(prim)
        pv = api.GetPrimvar(primvar)
        if not pv:
            pv = api.CreatePrimvar(primvar, Sdf.ValueTypeNames.FloatArray, interpolation)
        pv.Set(Vt.FloatArray.FromNumpy(np.nan_to_num(v).astype(np.float32)), tc)
        attr = pv.GetAttr()
        attr.SetCustomDataByKey("simfab:colormap", cmap)
        if vmin is not None and vmax is not None:
            attr.SetCustomDataByKey("simfab:range", Vt.DoubleArray([float(vmin), float(vmax)]))
            if np.nanmax(v, initial=-np.inf) > vmax:  # (once set, for the whole timeline)
                attr.SetCustomDataByKey("simfab:clipped", True)
        if units is not None:
            attr.SetCustomDataByKey("simfab:units", str(units))
        rgb = scalar_colors(v, cmap=cmap, vmin=vmin, vmax=vmax).astype(np.float32)
        dc = UsdGeom.Gprim(prim).GetDisplayColorPrimvar()
        if not dc or not dc.HasAuthoredValue():
            dc = UsdGeom.Gprim(prim).CreateDisplayColorPrimvar(interpolation)
        dc.SetInterpolation(interpolation)
        dc.Set(Vt.Vec3fArray.FromNumpy(rgb), tc)

    # ------------------------------------------------------------------ curves and points
    def add_curves(self, name: str, *, color=None) -> str:
        """Define linear basis curves (skeletons, rods); fill them with :meth:`set_curves`."""
        path = self._path(name)
        c = UsdGeom.BasisCurves.Define(self.stage, path)
        c.CreateTypeAttr(UsdGeom.Tokens.linear)
        c.CreateWrapAttr(UsdGeom.Tokens.nonperiodic)
        self._kinds[path] = "curves"
        _constant_color(c, color)
        return path

    def set_curves(self, name: str, curves, widths=None, t=None) -> None:
        """Curves at time code ``t``: ``curves`` a list of (k_i, 2|3) polylines, ``widths`` a list of (k_i,).

        The number of curves and points may change between time codes (growth replays).
        """
        prim = self._prim(name, "curves")
        c = UsdGeom.BasisCurves(prim)
        pts_list = [as_points3(p) for p in curves]
        counts = [len(p) for p in pts_list]
        if any(k < 2 for k in counts):
            raise ValueError("every curve needs at least 2 points")
        pts = np.concatenate(pts_list) if pts_list else np.zeros((0, 3))
        tc = self._time(t)
        c.GetCurveVertexCountsAttr().Set(Vt.IntArray(counts), tc)
        c.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(pts.astype(np.float32)), tc)
        pad = 0.0
        if widths is not None:
            w = (np.concatenate([np.broadcast_to(np.asarray(wi, np.float64), (k,)) for wi, k in zip(widths, counts)])
                 if counts else np.zeros(0))
            c.CreateWidthsAttr().Set(Vt.FloatArray.FromNumpy(w.astype(np.float32)), tc)
            c.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
            pad = float(w.max(initial=0.0)) / 2
        self._set_extent(prim, pts, pad, tc)

    def add_points(self, name: str, *, color=None) -> str:
        """Define a points prim (samples, attractors); fill with :meth:`set_points`."""
        path = self._path(name)
        p = UsdGeom.Points.Define(self.stage, path)
        self._kinds[path] = "points"
        _constant_color(p, color)
        return path

    # ------------------------------------------------------------------ rigid bodies
    def add_rigid(self, name: str, points=None, faces=None, *, color=None) -> str:
        """Define an animated rigid body: an Xform (translate + orient ops) with an optional child mesh
        ``geom`` given in the body frame."""
        path = self._path(name)
        x = UsdGeom.Xform.Define(self.stage, path)
        x.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble)
        x.AddOrientOp(UsdGeom.XformOp.PrecisionDouble)
        self._kinds[path] = "rigid"
        if points is not None and faces is not None:
            self.add_mesh(f"{name}/geom", faces, points, color=color)
        return path

    def set_pose(self, name: str, pos, quat_wxyz, t=None) -> None:
        """Pose of a rigid body at time code ``t``: position (3,) and unit quaternion (w, x, y, z)."""
        prim = self._prim(name, "rigid")
        q = np.asarray(quat_wxyz, dtype=np.float64)
        q = q / np.linalg.norm(q)
        p = np.asarray(pos, dtype=np.float64)
        tc = self._time(t)
        ops = UsdGeom.Xformable(prim).GetOrderedXformOps()
        ops[0].Set(Gf.Vec3d(*p), tc)
        ops[1].Set(Gf.Quatd(float(q[0]), Gf.Vec3d(*q[1:])), tc)

    def set_visible(self, name: str, visible: bool, t=None) -> None:
        """Show or hide a prim from time code ``t`` on (visibility is held between samples)."""
        prim = self._prim(name)
        UsdGeom.Imageable(prim).CreateVisibilityAttr().Set(
            UsdGeom.Tokens.inherited if visible else UsdGeom.Tokens.invisible, self._time(t))

    def set_attribute(self, name: str, attr: str, value: float, t=None) -> None:
        """A custom double attribute ``simfab:<attr>`` on prim ``name`` at time code ``t`` (e.g. an
        optimization's objective per replayed design)."""
        if not _IDENT.match(attr):
            raise ValueError(f"{attr!r} is not a valid attribute name")
        prim = self._prim(name)
        a = prim.GetAttribute(f"simfab:{attr}")
        if not a:
            a = prim.CreateAttribute(f"simfab:{attr}", Sdf.ValueTypeNames.Double, custom=True)
        a.Set(float(value), self._time(t))

    # ------------------------------------------------------------------ output
    def save(self) -> Path:
        """Set start/end time codes and write the stage atomically; return its path."""
        if self._times:
            self.stage.SetStartTimeCode(min(self._times))
            self.stage.SetEndTimeCode(max(self._times))
        with atomic_path(self.path) as tmp:
            if not self.stage.GetRootLayer().Export(str(tmp)):
                raise OSError(f"could not write USD stage {self.path}")
        return self.path


def check_compliance(path: str | os.PathLike) -> list[str]:
    """Validate a stage; return its compliance errors (empty list = compliant).

    Uses ``pxr.UsdUtils.ComplianceChecker`` where the installed USD still has it; USD 25.x+
    replaced it by the ``UsdValidation`` framework, whose full validator registry (stage
    metadata, composition, attribute types, geometry/shading/physics encapsulation, package
    rules) is run instead. Warnings are not errors.
    """
    from pxr import UsdUtils

    if hasattr(UsdUtils, "ComplianceChecker"):  # USD <= 24.x
        checker = UsdUtils.ComplianceChecker(arkit=False, skipARKitRootLayerCheck=False, rootPackageOnly=False,
                                             skipVariants=False, verbose=False)
        checker.CheckCompliance(str(path))
        return list(checker.GetErrors()) + list(checker.GetFailedChecks())
    from pxr import UsdValidation

    stage = Usd.Stage.Open(str(path))
    if stage is None:
        return [f"{path}: stage does not open"]
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    errors = UsdValidation.ValidationContext(validators).Validate(stage)
    return [f"{e.GetValidator().GetMetadata().name if e.GetValidator() else '?'}: {e.GetMessage()}"
            for e in errors if e.GetType() == UsdValidation.ValidationErrorType.Error]
