"""Computed ground truths of the 3D-printing surveys: support volume and overhang area.

A part is printed on a plate at its lowest point (z = z_min after rotation, +z up). With a
zero overhang angle every downward-facing triangle (unit normal n_z < -tol) above the plate
needs support down to the plate:

    V = sum_down A_t |n_z,t| (z_mean,t - z_min)      (support volume, m^3)
    S = sum_down A_t                                   (overhang area, m^2)

A_t |n_z| is the triangle's footprint and z_mean - z_min the mean height of the prism under
it (exact: the height is linear over the triangle). Triangles lying on the plate need no
support and are excluded. The volume is cross-checked by ray casting: vertical rays on a
grid over the footprint; every hit on a downward face adds (z_hit - z_min) times the
cell area (midpoint rule of the same integral).

Survey scores scale the values across orientations linearly onto the survey scale:
support volume "more is higher", surface finish "10 = least overhang".
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np

from simfab.crowd.config import TOL, Tolerances
from simfab.errors import InputError
from simfab.io.mesh import read_mesh, unite_overlaps, units_warning

#: Six canonical orientations: each of the part's six axis directions facing down.
SIX = {
    "as_is": (0.0, 0.0, 0.0),
    "x90": (90.0, 0.0, 0.0),
    "x180": (180.0, 0.0, 0.0),
    "x270": (270.0, 0.0, 0.0),
    "y90": (0.0, 90.0, 0.0),
    "y270": (0.0, 270.0, 0.0),
}

_ORIENT = re.compile(r"^(?:(?P<name>[A-Za-z_][\w-]*)=)?(?P<rx>[-+\d.eE]+):(?P<ry>[-+\d.eE]+):(?P<rz>[-+\d.eE]+)$")


@dataclasses.dataclass(frozen=True, kw_only=True)
class Orientation:
    """A named rotation; ``euler_deg`` are extrinsic x, y, z angles in degrees."""

    name: str
    euler_deg: tuple[float, float, float]

    @property
    def matrix(self) -> np.ndarray:
        from scipy.spatial.transform import Rotation

        return Rotation.from_euler("xyz", self.euler_deg, degrees=True).as_matrix()


def parse_orientations(specs) -> list[Orientation]:
    """Orientations from tokens: ``six`` (the canonical six) or ``[name=]RX:RY:RZ`` (degrees,
    extrinsic x then y then z). InputError on anything else or on duplicate names."""
    out: list[Orientation] = []
    for tok in specs:
        tok = str(tok).strip()
        if tok == "six":
            out += [Orientation(name=k, euler_deg=v) for k, v in SIX.items()]
            continue
        m = _ORIENT.match(tok)
        if not m:
            raise InputError(f"{tok!r} is not an orientation (use 'six' or [name=]RX:RY:RZ in degrees, e.g. side=90:0:0)", where="--orientations")
        try:
            ang = tuple(float(m[k]) for k in ("rx", "ry", "rz"))
        except ValueError:
            raise InputError(f"{tok!r}: angles must be numbers", where="--orientations") from None
        if not all(np.isfinite(ang)):
            raise InputError(f"{tok!r}: angles must be finite", where="--orientations")
        out.append(Orientation(name=m["name"] or f"o{len(out) + 1}", euler_deg=ang))
    if not out:
        raise InputError("no orientations given", where="--orientations")
    names = [o.name for o in out]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise InputError(f"duplicate orientation name {sorted(dup)[0]!r}", where="--orientations")
    return out


def _triangles(vertices: np.ndarray, faces: np.ndarray):
    tri = vertices[faces]  # (m, 3, 3)
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.linalg.norm(cross, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        nz = np.where(area2 > 0, cross[:, 2] / area2, 0.0)
    return tri, 0.5 * area2, nz


def _downward(v, f, tol: Tolerances):
    """Triangles needing support: facing down (n_z < -tol) and not lying on the plate."""
    tri, area, nz = _triangles(v, f)
    z_min = float(v[:, 2].min())
    diag = float(np.linalg.norm(v.max(0) - v.min(0)))
    on_plate = tri[:, :, 2].max(axis=1) - z_min <= tol.plate_rel * diag
    return tri, area, nz, (nz < -tol.downward_nz) & ~on_plate, z_min


def support_metrics(vertices, faces, *, tol: Tolerances = TOL) -> dict:
    """Support volume (m^3), overhang area (m^2) of a mesh as placed (+z up, plate at z_min).

    vertices (n, 3) m; faces (m, 3) int, outward normals (counter-clockwise seen from outside).
    """
    v = np.asarray(vertices, float)
    f = np.asarray(faces, np.int64)
    tri, area, nz, down, z_min = _downward(v, f, tol)
    height = tri[down, :, 2].mean(axis=1) - z_min
    volume = float(np.sum(area[down] * -nz[down] * height))
    return {"support_volume": volume, "overhang_area": float(area[down].sum()), "z_min": z_min, "downward_triangles": int(down.sum())}


def raycast_support_volume(vertices, faces, *, grid: int | None = None, tol: Tolerances = TOL) -> float:
    """Ray-cast estimate of :func:`support_metrics`' volume (m^3), for cross-checking.

    Casts one upward ray per cell of a ``grid`` x ``grid``-ish lattice over the footprint
    (cell centres) and sums (z_hit - z_min) * cell area over hits on downward faces.
    """
    import trimesh

    v = np.asarray(vertices, float)
    f = np.asarray(faces, np.int64)
    mesh = trimesh.Trimesh(v, f, process=False)
    _, _, _, down, _ = _downward(v, f, tol)
    lo, hi = v.min(0), v.max(0)
    n = grid or tol.ray_grid
    h = max(hi[0] - lo[0], hi[1] - lo[1]) / n
    xs = np.arange(lo[0] + 0.5 * h, hi[0], h)
    ys = np.arange(lo[1] + 0.5 * h, hi[1], h)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    z0 = lo[2] - 0.1 * (hi[2] - lo[2] + h)
    origins = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, z0)])
    dirs = np.tile([0.0, 0.0, 1.0], (origins.shape[0], 1))
    loc, _, tri_idx = mesh.ray.intersects_location(origins, dirs, multiple_hits=True)
    keep = down[tri_idx]
    return float(np.sum(loc[keep, 2] - lo[2]) * h * h)


def oriented(vertices, orientation: Orientation) -> np.ndarray:
    """Vertices rotated into ``orientation`` (rotation about the origin)."""
    return np.asarray(vertices, float) @ orientation.matrix.T


def scale_to_survey(values, *, lo: float = 1.0, hi: float = 10.0, higher_is_more: bool = True) -> np.ndarray:
    """Map values linearly onto [lo, hi]: min -> lo, max -> hi (reversed when
    ``higher_is_more`` is False). Equal values all map to the middle of the scale."""
    v = np.asarray(values, float)
    span = v.max() - v.min()
    if span <= 1e-12 * max(abs(v.max()), 1e-300):
        return np.full(v.shape, 0.5 * (lo + hi))
    u = (v - v.min()) / span
    return lo + (hi - lo) * (u if higher_is_more else 1.0 - u)


def orientation_table(vertices, faces, orientations, *, raycast: bool = True, scale=(1.0, 10.0), tol: Tolerances = TOL) -> list[dict]:
    """Per orientation: support volume, overhang area, ray-cast volume, and survey scores.

    Returns rows {orientation, euler_deg, support_volume, overhang_area, raycast_volume,
    raycast_rel_diff, support_score (more = higher), finish_score (10 = least overhang)}.
    """
    rows = []
    for o in orientations:
        vo = oriented(vertices, o)
        m = support_metrics(vo, faces, tol=tol)
        row = {"orientation": o.name, "euler_deg": list(o.euler_deg), "support_volume": m["support_volume"], "overhang_area": m["overhang_area"]}
        if raycast:
            rc = raycast_support_volume(vo, faces, tol=tol)
            row["raycast_volume"] = rc
            row["raycast_rel_diff"] = (rc - m["support_volume"]) / m["support_volume"] if m["support_volume"] > 0 else (0.0 if rc == 0 else None)
        rows.append(row)
    sv = scale_to_survey([r["support_volume"] for r in rows], lo=scale[0], hi=scale[1], higher_is_more=True)
    fs = scale_to_survey([r["overhang_area"] for r in rows], lo=scale[0], hi=scale[1], higher_is_more=False)
    for r, a, b in zip(rows, sv, fs):
        r["support_score"] = float(a)
        r["finish_score"] = float(b)
    return rows


def load_part(path, *, units: str = "m"):
    """The printed part of a truth computation: a closed mesh in metres, checked.

    Returns ``(mesh, notes)``; notes are one-line statements of everything that was not taken
    as read (repairs, overlapping bodies united, an implausible size for ``units``) -- the
    caller shows them on stderr and in the summary. InputError for unusable meshes: open,
    implausible coordinates, mostly degenerate, or self-intersecting beyond a union of bodies.
    """
    import warnings


    with warnings.catch_warnings():  # the repairs are reported as notes
        warnings.simplefilter("ignore")
        mesh, report = read_mesh(path, units=units, require_watertight=True)
    notes = [f"{path}: repaired {', '.join(report.repaired)}"] if report.repaired else []
    mesh, note = unite_overlaps(mesh, where=str(path))
    if note:
        notes.append(f"{path}: {note}")
    w = units_warning(mesh.extents, units)
    if w:
        notes.append(f"{path}: {w}")
    return mesh, notes
