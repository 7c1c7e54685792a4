"""Coupling scenes from a user's own meshes (``simfab couple new``): no hand-written MJCF or TOML.

:func:`new_scene` takes the compliant part A and the rigid object O as mesh files in one common
frame (a CAD assembly: O may sit in its seat), an insertion direction, and writes a scene folder
that ``simfab couple simulate`` and ``couple optimize`` run: ``NAME.xml`` (O as the mocap body
``object`` with two keyframes, the box site ``fixed``, A as a display mesh) and ``NAME.toml``
(``dim``, ``[material]``, ``[compliant]``, ``[object]``, ``[fixed]``, ``[simulation]``, optional
``[contact]`` and ``[design]``), plus A's outline CSV (2D) or tetrahedral mesh NPZ (3D).

The path is a straight line through O's centre along the insertion direction. Its ends come from
the overlap profile of O and A along that line (:func:`overlap_profile`: the deepest point of either
shape inside the other, per position): the start is placed just before the first contact (an O that
starts inside A is moved back, and the run's notes say from where to where); the end, unless
``depth`` is given, just before the seat (the first local minimum of the overlap after the mouth's
peak), from where the simulation continues to the rest point on its own. A ``depth`` that ends
past the seat, inside A's far wall, is refused with the seat's depth in the message.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simfab.coupling.fit import fit_warnings
from simfab.errors import InputError
from simfab.io.mjcf_load import points_in_box
from simfab.io.outpaths import name_from_stem
from simfab.results import Result, field
from simfab.rotations import matrix_to_quat

__all__ = ["AuthoredScene", "CouplingAuthorConfig", "OverlapProfile", "new_scene", "overlap_profile"]

#: Start margin before first contact, relative to O's size along the path [-].
START_MARGIN_REL = 0.05
#: The default (rest-search) end lies this fraction of the way back from the seat to the mouth's peak,
#: at most END_BEFORE_SEAT_MAX [m] before the seat: the simulation draws O the rest of the way in.
END_BEFORE_SEAT_REL = 0.3
END_BEFORE_SEAT_MAX = 0.002
#: Overlap-profile resolution: positions per O size along the path, boundary samples per shape.
PROFILE_POSITIONS_PER_SIZE = 60
BOUNDARY_SAMPLES = {2: 400, 3: 1500}
_AXES = {"x": 0, "y": 1, "z": 2}


@dataclass(frozen=True, kw_only=True)
class CouplingAuthorConfig:
    """What ``simfab couple new`` is asked for (lengths in ``units``).

    Attributes:
        part: mesh file of the compliant part A (STL / OBJ / PLY, watertight).
        object: mesh file of the rigid object O, in the same frame as the part.
        into: the insertion direction, an axis (``-x``, ``+y``, ``z``) or a point ``X,Y,Z`` O's centre moves towards.
        name: the scene's name (file stem); None: the part file's stem.
        dim: 2 (plane strain: the section of both meshes with the plane z = O's centre; the part's extent
            along z is its thickness) or 3.
        units: the meshes' and the lengths' units, "mm" or "m".
        fixed: the region of A held fixed: ``back`` (a slab at A's far side along the insertion direction),
            a face ``-x`` / ``+y`` / ..., or a box ``X0,Y0,Z0,X1,Y1,Z1``.
        depth: the insertion depth past the first contact [units]; None: up to the seat, then to rest.
        friction: Coulomb coefficient between O and A [-] (0: frictionless).
        brief: the ``[design]`` table for ``couple optimize`` (:class:`simfab.design.brief.DesignConfig` keys).
        material: material name (:mod:`simfab.fem.materials`).
        elements: target triangle (2D) / tetrahedron (3D) count; None: 1500 / 3000.
        steps: insertion steps over the path.
        object_samples: surface samples of O for its contact field; None: 100 in 2D, 2000 in 3D.
    """

    part: Path
    object: Path
    into: str
    name: str | None = None
    dim: int = 3
    units: str = "mm"
    fixed: str = "back"
    depth: float | None = None
    friction: float = 0.0
    brief: dict | None = None
    material: str = "PLA"
    elements: int | None = None
    steps: int = 40
    object_samples: int | None = None


@dataclass(frozen=True, kw_only=True)
class OverlapProfile:
    """How deep O and A overlap as O moves along the line ``centre + s * direction``.

    Attributes:
        s: positions along the line [m] (0: O's position in its file).
        depth: the deepest boundary point of either shape inside the other, per position [m] (0: apart).
        where: that point, per position (world frame) [m].
    """

    s: np.ndarray
    depth: np.ndarray
    where: np.ndarray


@dataclass(frozen=True, kw_only=True)
class AuthoredScene(Result):
    """The scene ``simfab couple new`` wrote.

    Args:
        scene: the MJCF scene's path.
        dim: 2 or 3.
        start, end: O's path's start and end position [m].
        path_length: the path's length [m].
        first_contact: path length at O's first contact with A [m].
        seat: path length of the seat (the first overlap minimum after the mouth) [m]; None when none was found.
        to_rest: the simulation draws O on to rest past the path's end.
        notes: one line each (what was corrected or assumed).
        warnings: one line each (what the scene's runs will not resolve: :mod:`simfab.coupling.fit`).
        next_commands: the commands to run next.
        outputs: label -> path of the files written.
    """

    scene: str = field(default="")
    dim: int = field(default=3)
    start: list = field(unit="m", default_factory=list)
    end: list = field(unit="m", default_factory=list)
    path_length: float = field(unit="m", default=0.0)
    first_contact: float = field(unit="m", default=0.0)
    seat: float | None = field(unit="m", default=None)
    to_rest: bool = field(default=True)
    notes: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    next_commands: list = field(default_factory=list)


# ---------------------------------------------------------------------------- shapes
class _Shape2D:
    def __init__(self, polygon):
        import shapely

        self.poly = polygon
        self.boundary = polygon.exterior
        shapely.prepare(self.poly)

    def inside_depth(self, pts: np.ndarray) -> np.ndarray:
        import shapely

        inside = shapely.contains_xy(self.poly, pts[:, 0], pts[:, 1])
        d = np.zeros(len(pts))
        if inside.any():
            d[inside] = shapely.distance(self.boundary, shapely.points(pts[inside, :2]))
        return d

    def samples(self, n: int) -> np.ndarray:
        ring = self.boundary
        t = np.linspace(0.0, ring.length, n, endpoint=False)
        return np.array([ring.interpolate(x).coords[0] for x in t])


class _Shape3D:
    def __init__(self, mesh, seed: int = 0):
        self.mesh = mesh
        self.seed = seed

    def inside_depth(self, pts: np.ndarray) -> np.ndarray:
        import trimesh

        inside = self.mesh.contains(pts)
        d = np.zeros(len(pts))
        if inside.any():
            d[inside] = np.abs(trimesh.proximity.signed_distance(self.mesh, pts[inside]))
        return d

    def samples(self, n: int) -> np.ndarray:
        import trimesh

        p, _ = trimesh.sample.sample_surface(self.mesh, n, seed=self.seed)
        return np.vstack([np.asarray(self.mesh.vertices), p])


def overlap_profile(part, obj, centre, direction, s) -> OverlapProfile:
    """The overlap of O (moved to ``centre + s * direction``) and A at each ``s``.

    Args:
        part: A as a shape (2D section or 3D mesh, as :func:`new_scene` builds them).
        obj: O as a shape of the same kind, in the world frame at ``s = 0``.
        centre: O's centre at ``s = 0`` [m] (2 or 3 coordinates, as the shapes).
        direction: unit insertion direction.
        s: positions along the line [m].

    Returns:
        An :class:`OverlapProfile`.
    """
    dim = len(centre)
    n = BOUNDARY_SAMPLES[dim]
    po, pa = obj.samples(n), part.samples(n)
    depth = np.zeros(len(s))
    where = np.zeros((len(s), dim))
    for k, sk in enumerate(np.asarray(s, float)):
        shift = sk * np.asarray(direction)[:dim]
        d_o = part.inside_depth(po + shift)  # O's boundary inside A
        d_a = obj.inside_depth(pa - shift)  # A's boundary inside O
        i, j = int(np.argmax(d_o)), int(np.argmax(d_a))
        if d_o[i] >= d_a[j]:
            depth[k], where[k] = d_o[i], po[i] + shift
        else:
            depth[k], where[k] = d_a[j], pa[j]
    return OverlapProfile(s=np.asarray(s, float), depth=depth, where=where)


# ---------------------------------------------------------------------------- parsing
def parse_direction(into: str, centre: np.ndarray, scale: float) -> np.ndarray:
    """Unit direction from ``-x`` / ``+y`` / ``z`` or a point ``X,Y,Z`` [units] O's centre moves towards."""
    t = into.strip().lower()
    sign = -1.0 if t.startswith("-") else 1.0
    if t.lstrip("+-") in _AXES:
        d = np.zeros(3)
        d[_AXES[t.lstrip("+-")]] = sign
        return d
    try:
        p = np.array([float(v) for v in t.split(",")]) * scale
    except ValueError:
        p = np.zeros(0)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise InputError(f"must be an axis (-x, +y, z, ...) or a point X,Y,Z, got {into!r}", where="--into")
    v = p - centre
    if np.linalg.norm(v) < 1e-9:
        raise InputError("the point is the object's centre: give an axis (-x, +y, ...) or a point it moves "
                         "towards", where="--into")
    return v / np.linalg.norm(v)


def parse_brief(items) -> dict:
    """``KEY=VALUE`` strings (VALUE a TOML value; a bare word is a string) as a ``[design]`` table."""
    out = {}
    for it in items or ():
        if "=" not in it:
            raise InputError(f"must be KEY=VALUE (e.g. grip=tight, 'insertion_force=[0, 20]'), got {it!r}",
                             where="--brief")
        k, v = (x.strip() for x in it.split("=", 1))
        try:
            out[k] = tomllib.loads(f"v = {v}")["v"]
        except tomllib.TOMLDecodeError:
            out[k] = v
    if out:
        from simfab.design.brief import DesignConfig

        DesignConfig.from_dict(out, where="--brief")
    return out


#: The files' axes are the part's own frame when its bounding box along them is at most this much larger
#: (volume in 3D, area of the section in 2D) than its smallest turned one; else the smallest box's axes are.
FRAME_SLACK_REL = 0.02


@dataclass(frozen=True)
class FixedBox:
    """The fixed box site: centre (3,) [m], half extents (3,) [m] along its axes, axes (3, 3) (columns)."""

    centre: np.ndarray
    half: np.ndarray
    axes: np.ndarray

    def holds(self, pts: np.ndarray) -> np.ndarray:
        """(k,) which points (k, dim) [m] lie in the box (2D: its section with z = 0), as the scene's loader
        will read the site (:func:`simfab.io.mjcf_load.points_in_box`)."""
        return points_in_box(pts, self.centre, self.half, self.axes)


def part_axes(mesh, section=None) -> np.ndarray:
    """The part's own axes (3, 3) (columns): the files' axes, unless a turned box bounds the part more
    tightly (by more than FRAME_SLACK_REL), whose axes then serve: the smallest bounding box (trimesh's
    oriented one) in 3D, the section's smallest turned rectangle about z in 2D. A part turned in the
    assembly is then held on its own back face, as the same part unturned would be.

    Args:
        mesh: the part's mesh (trimesh) [m].
        section: the 2D section (shapely polygon) [m], or None in 3D.

    Returns:
        The rotation whose columns are the axes.
    """
    if section is not None:
        x0, y0, x1, y1 = section.bounds
        rect = section.minimum_rotated_rectangle
        if (x1 - x0) * (y1 - y0) <= (1.0 + FRAME_SLACK_REL) * rect.area:
            return np.eye(3)
        c = np.asarray(rect.exterior.coords)[:2]
        e = c[1] - c[0]
        t = float(np.arctan2(e[1], e[0]))
        R = np.eye(3)
        R[:2, :2] = [[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]]
        return R
    obb = mesh.bounding_box_oriented
    if float(np.prod(mesh.extents)) <= (1.0 + FRAME_SLACK_REL) * float(obb.volume):
        return np.eye(3)
    R = np.asarray(obb.primitive.transform, dtype=np.float64)[:3, :3]
    return R * np.sign(np.linalg.det(R))  # (a proper rotation)


def _fixed_box(spec: str, points: np.ndarray, axes: np.ndarray, direction: np.ndarray, scale: float) -> FixedBox:
    """The fixed box site [m] for ``--fixed``: ``back`` (the part's face farthest along the insertion, in the
    part's own axes: :func:`part_axes`), a face of the files' axes (-x, +y, ...) or a box in the files' frame.

    Args:
        spec: the option's text.
        points: the part's points (k, 3) [m].
        axes: the part's own axes (3, 3) (columns).
        direction: unit insertion direction (3,).
        scale: the files' unit [m].
    """
    t = spec.strip().lower()
    if t == "back" or t.lstrip("+-") in _AXES:
        if t == "back":
            local = axes.T @ direction
            ax = int(np.argmax(np.abs(local)))
            sign = 1.0 if local[ax] > 0 else -1.0
        else:
            axes = np.eye(3)
            ax, sign = _AXES[t.lstrip("+-")], (-1.0 if t.startswith("-") else 1.0)
        q = points @ axes  # (the part in the box's axes)
        lo, hi = q.min(axis=0), q.max(axis=0)
        ext = hi - lo
        c = 0.5 * (lo + hi)
        c[ax] = hi[ax] if sign > 0 else lo[ax]
        half = 0.5 * ext + 0.05 * ext.max()
        half[ax] = 0.03 * ext[ax]
        return FixedBox(centre=axes @ c, half=half, axes=axes)
    try:
        b = np.array([float(v) for v in t.split(",")]) * scale
    except ValueError:
        b = np.zeros(0)
    if b.shape != (6,) or not np.all(np.isfinite(b)) or np.any(b[3:] <= b[:3]):
        raise InputError(f"must be back, a face (-x, +y, ...) or a box X0,Y0,Z0,X1,Y1,Z1 with X0 < X1 ..., "
                         f"got {spec!r}", where="--fixed")
    return FixedBox(centre=0.5 * (b[:3] + b[3:]), half=0.5 * (b[3:] - b[:3]), axes=np.eye(3))


def _section(mesh, z: float, what: str, where: str):
    from shapely.geometry import Polygon

    sec = mesh.section(plane_origin=[0, 0, z], plane_normal=[0, 0, 1])
    polys = [] if sec is None else sec.to_2D(to_2D=np.eye(4))[0].polygons_full
    if not polys:
        raise InputError(f"the {what} does not cross the plane z = {z:.6g} m (a 2D scene uses the section through "
                         "the object's centre) in a closed curve", where=where)
    poly = max(polys, key=lambda p: p.area)
    if len(poly.interiors):
        raise InputError(f"the {what}'s section at z = {z:.6g} m has a hole; a 2D part is one outline", where=where)
    return Polygon(np.asarray(poly.exterior.coords)[:, :2])


def _fmt_pt(p, scale: float, units: str) -> str:
    return "(" + ", ".join(f"{v / scale:.4g}" for v in p) + f") {units}"


# ---------------------------------------------------------------------------- the scene
def new_scene(spec: CouplingAuthorConfig, out) -> AuthoredScene:
    """Write a coupling scene for the user's part and object meshes (see the module docstring).

    Args:
        spec: the request (:class:`CouplingAuthorConfig`).
        out: the folder the scene's files are written to (created).

    Returns:
        An :class:`AuthoredScene`: the files written (``outputs``), the path's ends, the overlap
        profile's first contact and seat, notes on every correction, the command to run next.

    Raises:
        InputError: a missing or unreadable mesh, a bad flag, a path that cannot be placed (no seat
            along the line and no depth given; a depth that ends inside the part).
    """
    from simfab.io.mesh import load_mesh

    if spec.units not in ("mm", "m"):
        raise InputError(f"must be mm or m, got {spec.units!r}", where="--units")
    if spec.dim not in (2, 3):
        raise InputError(f"must be 2 or 3, got {spec.dim!r}", where="--dim")
    if isinstance(spec.steps, bool) or not isinstance(spec.steps, int) or spec.steps < 1:
        raise InputError(f"must be an integer >= 1, got {spec.steps!r}", where="--steps")
    if not 0 <= spec.friction <= 2:
        raise InputError(f"must be a Coulomb coefficient in [0, 2], got {spec.friction}", where="--friction")
    scale = 1e-3 if spec.units == "mm" else 1.0
    A = load_mesh(spec.part, units=spec.units, require_watertight=True)
    O = load_mesh(spec.object, units=spec.units, require_watertight=True)
    name = spec.name or name_from_stem(spec.part)
    if not name.replace("_", "").replace("-", "").isalnum():
        raise InputError(f"must be letters, digits, '_' or '-', got {name!r}", where="--name")
    brief = dict(spec.brief or {})
    if brief:
        from simfab.design.brief import DesignConfig

        DesignConfig.from_dict(brief, where="--brief")
    dim = spec.dim
    lo_o, hi_o = O.bounds
    centre = 0.5 * (lo_o + hi_o)
    d = parse_direction(spec.into, centre, scale)
    notes: list[str] = []
    if dim == 2:
        if abs(d[2]) > 1e-9:
            raise InputError("a 2D scene inserts in the xy-plane: the direction must have no z component",
                             where="--into")
        zc = float(centre[2])
        if zc != 0.0:  # a 2D scene's plane is z = 0: its frame is the files' moved along z by -zc
            A, O = A.copy(), O.copy()
            A.apply_translation([0.0, 0.0, -zc])
            O.apply_translation([0.0, 0.0, -zc])
            centre = centre - np.array([0.0, 0.0, zc])
            notes.append(f"2D: the section through the object's centre (z = {zc / scale:.4g} {spec.units} in the "
                         "files) is the scene's plane z = 0: the scene's frame is the files' moved along z")
            zc = 0.0
        part_shape = _Shape2D(_section(A, zc, "part", str(spec.part)))
        obj_shape = _Shape2D(_section(O, zc, "object", str(spec.object)))
        c2 = centre[:2]
        thickness = float(A.bounds[1][2] - A.bounds[0][2])
    else:
        part_shape, obj_shape, c2 = _Shape3D(A), _Shape3D(O), centre
    # positions: from O entirely before A to O entirely past it (O's points at s project to their
    # projection in the files plus s: O is in the files' frame at s = 0)
    proj_a = np.asarray(A.vertices) @ d
    proj_o = np.asarray(O.vertices) @ d
    size = float(proj_o.max() - proj_o.min())
    s_lo = float(proj_a.min() - proj_o.max()) - 0.1 * size
    s_hi = float(proj_a.max() - proj_o.min()) + 0.1 * size
    n = int(min(2000, max(100, math.ceil((s_hi - s_lo) / size * PROFILE_POSITIONS_PER_SIZE))))
    prof = overlap_profile(part_shape, obj_shape, c2, d, np.linspace(s_lo, s_hi, n))
    touching = np.flatnonzero(prof.depth > 0)
    if len(touching) == 0:
        raise InputError(f"the object never touches the part moving along {spec.into} from "
                         f"{_fmt_pt(centre, scale, spec.units)}: check the direction and the meshes' frame",
                         where="--into")
    k0 = int(touching[0])
    s_contact = float(prof.s[k0])
    s_start = s_contact - START_MARGIN_REL * size
    if prof.depth[np.argmin(np.abs(prof.s))] > 0:
        k = int(np.argmin(np.abs(prof.s)))
        notes.append(f"the object starts inside the part in the files (overlap {prof.depth[k] / scale:.3g} "
                     f"{spec.units} at {_fmt_pt(prof.where[k], scale, spec.units)}): its path starts "
                     f"{-s_start / scale:.4g} {spec.units} back along the axis instead, "
                     f"{START_MARGIN_REL * size / scale:.3g} {spec.units} before first contact")
    # the seat: the first local minimum of the overlap after the mouth's peak
    depth, tol = prof.depth, 1e-3 * size
    k_seat = None
    peak = 0.0
    for k in range(k0, len(depth) - 1):
        peak = max(peak, depth[k])
        if depth[k] <= depth[k + 1] + 1e-15 and depth[k] <= depth[k - 1] and peak - depth[k] > tol:
            j = k  # the end of a flat minimum (a loose seat): its middle
            while j + 1 < len(depth) and abs(depth[j + 1] - depth[k]) <= 1e-12:
                j += 1
            k_seat = (k + j) // 2
            break
    s_seat = None if k_seat is None else float(prof.s[k_seat])
    if spec.depth is None:
        if k_seat is None:
            raise InputError(f"no seat along {spec.into}: past the first contact at "
                             f"{_fmt_pt(prof.where[k0], scale, spec.units)} the overlap only grows (a press fit?); "
                             "give the insertion depth with --depth D", where="--into")
        k_peak = k0 + int(np.argmax(depth[k0:k_seat + 1]))
        back = min(END_BEFORE_SEAT_MAX, END_BEFORE_SEAT_REL * (s_seat - float(prof.s[k_peak])))
        s_end = s_seat - back
        to_rest = True
        notes.append(f"path ends {back / scale:.3g} {spec.units} before the seat (found "
                     f"{(s_seat - s_contact) / scale:.4g} {spec.units} past first contact); the simulation continues "
                     "to the rest point")
    else:
        if not (spec.depth > 0 and math.isfinite(spec.depth)):
            raise InputError(f"must be a positive length [{spec.units}], got {spec.depth}", where="--depth")
        s_end = s_contact + spec.depth * scale
        to_rest = False
        k = int(np.clip(np.searchsorted(prof.s, s_end), 0, len(prof.s) - 1))
        mouth = float(depth[k0:k_seat + 1].max()) if k_seat is not None else np.inf
        past_seat = s_seat is not None and s_end > s_seat and depth[k] > max(mouth, depth[k_seat] + tol)
        if past_seat or s_end >= s_hi or depth[k] > 0.5 * size:
            seat = ("" if s_seat is None else
                    f"; the seat is at --depth {(s_seat - s_contact) / scale:.4g} "
                    "(or leave --depth out to run to rest)")
            raise InputError(f"the path would end inside the part: at depth {spec.depth:g} {spec.units} the object "
                             f"overlaps it by {depth[k] / scale:.3g} {spec.units} at "
                             f"{_fmt_pt(prof.where[k], scale, spec.units)}{seat}", where="--depth")
    p_start, p_end = centre + s_start * d, centre + s_end * d
    return _write(spec, out, name=name, A=A, O=O, centre=centre, d=d, p_start=p_start, p_end=p_end,
                  thickness=thickness if dim == 2 else None, outline=part_shape.poly if dim == 2 else None,
                  brief=brief, to_rest=to_rest, notes=notes, s_contact=s_contact - s_start,
                  deepest=_deepest(prof, s_seat if to_rest else s_end),
                  s_seat=None if s_seat is None else s_seat - s_start)


def _deepest(prof: OverlapProfile, s: float) -> tuple:
    """(s [m], the object's overlap with the part there [m]) at the profile's position nearest ``s``."""
    k = int(np.argmin(np.abs(prof.s - s)))
    return float(prof.s[k]), float(prof.depth[k])


def _write(spec, out, *, name, A, O, centre, d, p_start, p_end, thickness, outline, brief, to_rest, notes,
           s_contact, s_seat, deepest) -> AuthoredScene:
    from simfab.io.atomic import write_csv, write_text
    from simfab.io.mjcf import MJCFBuilder

    out = Path(out)
    dim, scale, units = spec.dim, (1e-3 if spec.units == "mm" else 1.0), spec.units
    box = _fixed_box(spec.fixed, np.asarray(A.vertices, dtype=np.float64), part_axes(A, outline), d, scale)
    comp: dict = {}
    files: dict[str, str] = {}
    warnings: list[str] = []
    if dim == 2:
        ring = np.asarray(outline.exterior.coords)[:-1] / scale
        comp = {"outline": f"{name}_outline.csv", "units": units, "thickness": thickness,
                "target_elements": spec.elements or 1500}
        inside = box.holds(ring * scale)
    else:
        from simfab.coupling.scene import stored_part_table
        from simfab.fem.meshing import tetrahedralize

        V, T = tetrahedralize(np.asarray(A.vertices), np.asarray(A.faces), target_tets=spec.elements or 3000)
        # the stored tets make runs reproducible; the surface they were meshed from, in the scene's frame,
        # lets a convergence study mesh the part again at multiples of their count (simfab couple converge;
        # the mesher's count is near the target asked, or above it at its floor)
        comp = stored_part_table(f"{name}_part.npz", f"{name}_part.ply", "m", len(T))
        warnings += _facet_warning(A, V, T, O, d, deepest, scale, units)
        inside = box.holds(V)
    if not inside.any():
        raise InputError(f"the fixed region {_fmt_pt(box.centre - box.half, scale, units)} .. "
                         f"{_fmt_pt(box.centre + box.half, scale, units)} holds no point of the part", where="--fixed")
    b = MJCFBuilder(name)
    b.mesh_asset("part", A.vertices, A.faces)
    b.mesh_asset("object", np.asarray(O.vertices) - centre, O.faces)
    part = b.body("part")
    b.geom(part, type="mesh", mesh="part", rgba=[0.85, 0.55, 0.25, 1], contype=0, conaffinity=0)
    turned = {} if np.array_equal(box.axes, np.eye(3)) else {"quat": list(matrix_to_quat(box.axes))}
    b.site(part, "fixed", pos=list(box.centre), size=list(box.half), type="box", rgba=[0.2, 0.2, 0.9, 0.4], **turned)
    o = b.body("object", pos=p_start, mocap=True)
    b.geom(o, type="mesh", mesh="object", contype=0, conaffinity=0, rgba=[0.5, 0.6, 0.7, 1])
    b.key("k0", mpos=p_start, mquat=[1, 0, 0, 0])
    b.key("k1", mpos=p_end, mquat=[1, 0, 0, 0])
    sim = {"steps": spec.steps}
    if not to_rest:
        sim["L_max"] = float(np.linalg.norm(p_end - p_start))
    tables = {"material": {"name": spec.material}, "compliant": comp,
              "object": {"body": "object", "samples": spec.object_samples or (100 if dim == 2 else 2000)},
              "fixed": {"site": "fixed"}, "simulation": sim}
    if spec.friction > 0:
        tables["contact"] = {"friction": float(spec.friction)}
    if brief:
        tables["design"] = brief
    head = [f"# {name}: written by simfab couple new from {Path(spec.part).name} (part) and "
            f"{Path(spec.object).name} (object), {units}.",
            f"# The object moves along {spec.into} from {_fmt_pt(p_start, scale, units)} to "
            f"{_fmt_pt(p_end, scale, units)}" + ("; the run continues to its rest point." if to_rest else "."), ""]
    lines = head + [f'name = "{name}"', f"dim = {dim}"]
    for t, tab in tables.items():
        lines += ["", f"[{t}]"] + [f"{k} = {_toml(v)}" for k, v in tab.items()]
    toml_text = "\n".join(lines) + "\n"
    b.compile()  # MuJoCo rejects it before anything is written
    out.mkdir(parents=True, exist_ok=True)
    if dim == 2:
        files["outline_csv"] = str(write_csv(out / comp["outline"], [f"x_{units}", f"y_{units}"], ring.tolist()))
    else:
        from simfab.io.atomic import atomic_path
        from simfab.io.mesh import save_mesh

        with atomic_path(out / comp["mesh_file"]) as tmp, open(tmp, "wb") as fh_:
            np.savez_compressed(fh_, points=V, elements=np.asarray(T, dtype=np.int32))
        files["part_npz"] = str(out / comp["mesh_file"])
        files["part_ply"] = str(save_mesh(A, out / comp["mesh"]))  # (binary PLY: float64 vertices, as meshed)
    files["scene_xml"] = str(b.save(out / f"{name}.xml"))
    files["scene_toml"] = str(write_text(out / f"{name}.toml", toml_text))
    xml = files["scene_xml"]
    nxt = [f"simfab couple simulate {xml}"] + ([f"simfab couple optimize {xml}"] if brief else [])
    return AuthoredScene(outputs=files, scene=name, dim=dim, start=[float(v) for v in p_start],
                         end=[float(v) for v in p_end], path_length=float(np.linalg.norm(p_end - p_start)),
                         first_contact=float(s_contact), seat=s_seat, to_rest=to_rest, notes=notes, warnings=warnings,
                         next_commands=nxt)


def _facet_warning(A, V, T, O, d, deepest, scale: float, units: str) -> list:
    """[the warning line] when the tets' surface departs from the part's near the object at its deepest
    pose by more than :data:`simfab.coupling.fit.SURFACE_DEVIATION_REL` of the overlap there, else []."""
    import trimesh

    s, overlap = deepest
    at = O.copy().apply_translation(s * np.asarray(d))
    return fit_warnings(A, V, T, overlap, lambda q, reach: trimesh.proximity.signed_distance(at, q) > -reach,
                        scale=scale, units=units)  # (trimesh: positive inside)


def _toml(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    return str(v)
