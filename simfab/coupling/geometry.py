"""Procedural geometry of the bundled coupling scenes (compliant parts A and rigid objects O).

All lengths in metres. 2D outlines are counter-clockwise (k, 2) arrays without the closing
point; 3D surfaces are watertight ``trimesh.Trimesh`` objects.

Compliant parts
- :func:`c_clamp_outline`: an annular arc ("C") around the origin whose mouth opens toward +x,
  joined at the back (-x) to a rectangular base block. A cylinder of radius R pushed along -x into
  the mouth snaps in when the mouth is narrower than 2R and the arc wraps past the cylinder's
  equator; inner radius < R leaves a residual squeeze (tight), > R a clearance (loose), and an arc
  that does not wrap past the equator never retains it (ejects).
- :func:`extruded_clamp`: the clamp outline extruded along z (3D clip), :func:`cross_claw`: two
  perpendicular extruded clamps united into a four-finger claw around the x axis.

Rigid objects (surface samples with outward unit normals for the IMLS field)
- :func:`circle_samples` (2D), :func:`section_samples` (2D cross-section of any mesh at z = 0),
  :func:`mesh_surface_samples` (3D, evenly spaced surface samples with face normals, seeded).
"""

from __future__ import annotations

import numpy as np

from simfab.contact.imls import curve_normals
from simfab.errors import InputError

#: The points on each of a C-clamp's arcs when the part table does not give ``segments``.
C_CLAMP_SEGMENTS = 96


def c_clamp_outline(*, inner_radius: float, width: float, opening_deg: float, base_depth: float,
                    base_height: float, segments: int = C_CLAMP_SEGMENTS) -> np.ndarray:
    """CCW outline (k, 2) of a C-clamp: arc of inner radius r_i and radial width w whose mouth is
    the sector |angle| < ``opening_deg`` around +x, joined to a base block behind the arc
    (x in [-(r_i + w) - base_depth, -(r_i + w) + w/2], |y| <= base_height/2).
    """
    from shapely.geometry import Polygon, box
    from shapely.ops import unary_union

    ri, ro = float(inner_radius), float(inner_radius) + float(width)
    if not (ri > 0 and width > 0 and 0 < opening_deg < 180 and base_depth > 0 and base_height > 0):
        raise InputError("c_clamp needs inner_radius, width, base_depth, base_height > 0 and 0 < opening_deg < 180")
    if not (isinstance(segments, (int, np.integer)) and 4 <= segments <= 10_000):
        raise InputError(f"segments must be an integer in 4 .. 10000, got {segments!r}", where="segments")
    a0 = np.deg2rad(opening_deg)
    t = np.linspace(a0, 2 * np.pi - a0, segments)
    outer = np.c_[ro * np.cos(t), ro * np.sin(t)]
    inner = np.c_[ri * np.cos(t[::-1]), ri * np.sin(t[::-1])]
    arc = Polygon(np.vstack([outer, inner]))
    x1 = -ro + 0.5 * width
    base = box(-ro - base_depth, -0.5 * base_height, x1, 0.5 * base_height)
    shape = unary_union([arc, base]).buffer(0)
    if shape.geom_type != "Polygon":
        raise InputError("c_clamp parameters give a disconnected outline")
    shape = shape.simplify(1e-9 * ro)
    ring = np.asarray(shape.exterior.coords)[:-1]
    if signed_area(ring) < 0:
        ring = ring[::-1]
    return ring


def signed_area(p: np.ndarray) -> float:
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def extrude(outline: np.ndarray, height: float):
    """Extrude a CCW outline (k, 2) along z over [-height/2, height/2] -> watertight trimesh."""
    import trimesh
    from shapely.geometry import Polygon

    m = trimesh.creation.extrude_polygon(Polygon(outline), float(height))
    m.apply_translation([0, 0, -0.5 * float(height)])
    return m


def extruded_clamp(*, height: float, **clamp) -> "object":
    """3D clip: :func:`c_clamp_outline` extruded along z (the cylinder's axis)."""
    return extrude(c_clamp_outline(**clamp), height)


def cross_claw(*, height: float, **clamp):
    """Four-finger claw: two extruded clamps (along z and along y) united; mouth toward +x."""
    import trimesh

    a = extruded_clamp(height=height, **clamp)
    b = a.copy()
    b.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    u = trimesh.boolean.union([a, b], engine="manifold")
    if not u.is_watertight:
        raise InputError("cross_claw: boolean union is not watertight")
    return u


def circle_samples(radius: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """n CCW samples of a circle of ``radius`` centred at the origin and their outward normals."""
    t = np.linspace(0, 2 * np.pi, int(n), endpoint=False)
    nrm = np.c_[np.cos(t), np.sin(t)]
    return float(radius) * nrm, nrm


def resample_closed(points: np.ndarray, n: int) -> np.ndarray:
    """n points evenly spaced by arc length along a closed polyline (k, 2)."""
    p = np.asarray(points, float)
    q = np.vstack([p, p[:1]])
    seg = np.linalg.norm(np.diff(q, axis=0), axis=1)
    cum = np.concatenate([[0], np.cumsum(seg)])
    s = np.linspace(0, cum[-1], int(n), endpoint=False)
    return np.c_[np.interp(s, cum, q[:, 0]), np.interp(s, cum, q[:, 1])]


def section_samples(mesh, n: int) -> tuple[np.ndarray, np.ndarray]:
    """2D object from a 3D mesh: the cross-section with the plane z = 0 (largest loop), resampled to
    n CCW points, with outward curve normals."""

    sec = mesh.section(plane_origin=[0, 0, 0], plane_normal=[0, 0, 1])
    if sec is None:
        raise InputError("the object's geometry does not cross the plane z = 0 (2D scenes use its cross-section)")
    planar, _ = sec.to_2D(to_2D=np.eye(4))
    polys = planar.polygons_full
    if not polys:
        raise InputError("the object's cross-section at z = 0 is not a closed curve")
    poly = max(polys, key=lambda p: p.area)
    ring = np.asarray(poly.exterior.coords)[:-1]
    if signed_area(ring) < 0:
        ring = ring[::-1]
    pts = resample_closed(ring, n)
    return pts, curve_normals(pts)


def mesh_surface_samples(mesh, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """About n evenly spread samples on a 3D surface with their face normals (seeded)."""
    import trimesh

    pts, fid = trimesh.sample.sample_surface_even(mesh, int(n), seed=int(seed))
    return np.asarray(pts), np.asarray(mesh.face_normals[fid])
