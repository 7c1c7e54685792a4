"""Target surfaces: loading and validating disk-topology triangle meshes, procedural targets.

A target is a triangle mesh ``Target(V (n,3) [m], F (m,3))`` of a surface with disk topology
(connected, manifold, one boundary loop, Euler characteristic 1, no degenerate faces).

Procedural targets (all over a disk of radius ``a`` [m] in the xy plane, triangulated by
:func:`disk_mesh` with ``rings`` concentric rings):

- ``spherical_cap``: sphere of radius R, polar angles theta <= theta0 (positive curvature
  K = 1/R^2; radius in the disk maps to theta by arc length, so the mesh is nearly uniform);
- ``saddle``: hyperbolic paraboloid z = (x^2 - y^2) / (2 c) (K = -1/c^2 at the centre, K < 0
  everywhere);
- ``mixed``: a saddle with an off-centre Gaussian bump, z = (x^2 - y^2) / (2 c) + h exp(-|p -
  (x0, 0)|^2 / s^2): K > 0 on the bump, K < 0 on the far side (both signs of Gaussian curvature,
  like the thesis' lily/snail examples);
- ``cylinder``: a patch of a cylinder of radius R (developable, K = 0; for validation);
- ``petal``: a petal with a fold along its midrib, over an ellipse of half-axes a (length, y) and
  b (width, x): z = s (sqrt(x^2 + w^2) - w) + y^2 / (2 c) - a rounded V (slope s either side of a
  fold of width w: curvature s w^2 / (x^2 + w^2)^{3/2}, s / w on the midrib) curled along its
  length (radius c). K = z_xx z_yy / (1 + |grad z|^2)^2 > 0 concentrated on the fold (like the
  thesis' lily petals; the fold is where the flattening shrinks most).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simfab.deploy.flatten import boundary_loop, face_areas
from simfab.errors import InputError
from simfab.io.mesh import read_mesh

KINDS = ("spherical_cap", "saddle", "mixed", "cylinder", "petal")
#: plausible size of a deployable target [m] (its bounding-box diagonal): a laser-cut sheet larger than
#: the upper bound or a pattern smaller than the lower one is a file in other units than declared
SIZE_RANGE_M = (0.005, 10.0)


@dataclass(frozen=True)
class Target:
    """A validated disk-topology target surface (:func:`validate`).

    Args:
        V: (n,3) [m] vertices.
        F: (m,3) int faces.
        name: its name (for messages and outputs).
    """

    V: np.ndarray
    F: np.ndarray
    name: str = "target"

    @property
    def diameter(self) -> float:
        """Largest distance between two boundary-box corners of the surface [m] (bounding-box diagonal)."""
        return float(np.linalg.norm(self.V.max(axis=0) - self.V.min(axis=0)))


def disk_mesh(a: float, rings: int) -> tuple[np.ndarray, np.ndarray]:
    """Triangulated disk: the centre and ``rings`` rings of 6k points (k = 1..rings), Delaunay-triangulated.

    Args:
        a: the radius [m].
        rings: the rings.

    Returns:
        (P (n,2) [m] (boundary: the outer ring), F (m,3) CCW).
    """
    from scipy.spatial import Delaunay

    pts = [np.zeros((1, 2))]
    for k in range(1, rings + 1):
        t = 2 * np.pi * (np.arange(6 * k) + 0.5 * (k % 2)) / (6 * k)
        pts.append(a * k / rings * np.stack([np.cos(t), np.sin(t)], axis=1))
    P = np.concatenate(pts)
    F = Delaunay(P).simplices.astype(np.int64)
    d = P[F]
    cross = ((d[:, 1, 0] - d[:, 0, 0]) * (d[:, 2, 1] - d[:, 0, 1])
             - (d[:, 1, 1] - d[:, 0, 1]) * (d[:, 2, 0] - d[:, 0, 0]))
    F[cross < 0] = F[cross < 0][:, ::-1]
    return P, F


def spherical_cap(R: float, theta0: float, rings: int) -> Target:
    """Cap of a sphere up to a polar angle, apex at the origin (z = (0, 0, R) - R shifted).

    Args:
        R: the sphere's radius [m].
        theta0: the polar half-angle [rad].
        rings: triangulation rings.

    Returns:
        The :class:`Target`.
    """
    P, F = disk_mesh(1.0, rings)
    rho = np.linalg.norm(P, axis=1)
    th = rho * theta0
    phi = np.arctan2(P[:, 1], P[:, 0])
    V = np.stack([R * np.sin(th) * np.cos(phi), R * np.sin(th) * np.sin(phi), R * np.cos(th) - R], axis=1)
    return validate(V, F, "spherical_cap")


def saddle(a: float, c: float, rings: int) -> Target:
    """Hyperbolic paraboloid z = (x^2 - y^2) / (2 c) over a disk.

    Args:
        a: the disk's radius [m].
        c: the curvature radius [m].
        rings: triangulation rings.

    Returns:
        The :class:`Target`.
    """
    P, F = disk_mesh(a, rings)
    z = (P[:, 0] ** 2 - P[:, 1] ** 2) / (2.0 * c)
    return validate(np.column_stack([P, z]), F, "saddle")


def mixed(a: float, c: float, h: float, s: float, x0: float, rings: int) -> Target:
    """Saddle z = (x^2 - y^2) / (2c) plus a bump h exp(-|p - (x0, 0)|^2 / s^2) over a disk.

    Args:
        a: the disk's radius [m].
        c: the saddle's curvature radius [m].
        h: the bump's height [m].
        s: its width [m].
        x0: its offset along x [m].
        rings: triangulation rings.

    Returns:
        The :class:`Target`.
    """
    P, F = disk_mesh(a, rings)
    z = (P[:, 0] ** 2 - P[:, 1] ** 2) / (2.0 * c) + h * np.exp(-((P[:, 0] - x0) ** 2 + P[:, 1] ** 2) / s**2)
    return validate(np.column_stack([P, z]), F, "mixed")


def petal(a: float, b: float, s: float, w: float, c: float, rings: int) -> Target:
    """Folded petal z = s (sqrt(x^2 + w^2) - w) + y^2 / (2 c) over the ellipse x^2/b^2 + y^2/a^2 <= 1
    (see the module doc).

    Args:
        a: half length [m].
        b: half width [m].
        s: fold slope [-].
        w: fold width [m] (rounding).
        c: curl radius [m].
        rings: triangulation rings.

    Returns:
        The :class:`Target`.
    """
    P, F = disk_mesh(1.0, rings)
    x, y = b * P[:, 0], a * P[:, 1]
    z = s * (np.sqrt(x * x + w * w) - w) + y * y / (2.0 * c)
    return validate(np.column_stack([x, y, z]), F, "petal")


def cylinder(R: float, angle: float, length: float, n: int, *, jitter: float = 0.25, seed: int = 0) -> Target:
    """Patch of a cylinder, meshed by Delaunay triangulation of a jittered (n+1)^2 grid of its developed
    rectangle.

    Args:
        R: radius [m].
        angle: opening angle [rad].
        length: axial length [m].
        n: grid cells per side.
        jitter: the grid points' jitter [cells].
        seed: the jitter's random seed.

    Returns:
        The :class:`Target`.
    """
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    s, z = np.meshgrid(np.linspace(0, R * angle, n + 1), np.linspace(0, length, n + 1), indexing="ij")
    h = min(R * angle, length) / n
    inner = (s > 0) & (s < R * angle) & (z > 0) & (z < length)
    s = s + inner * rng.uniform(-jitter, jitter, s.shape) * h
    z = z + inner * rng.uniform(-jitter, jitter, z.shape) * h
    P = np.stack([s.ravel(), z.ravel()], axis=1)
    F = Delaunay(P).simplices.astype(np.int64)
    V = np.stack([R * np.sin(P[:, 0] / R), P[:, 1], R * (1 - np.cos(P[:, 0] / R))], axis=1)
    return validate(V, F, "cylinder")


def procedural(kind: str, params: dict, *, where: str = "target") -> Target:
    """A procedural target by name (see the module doc).

    Args:
        kind: "spherical_cap", "saddle", "mixed", "petal" or "cylinder".
        params: the kind's parameters (the scene's ``[target]`` table without ``kind``).
        where: what an error names (the file and table).

    Returns:
        The :class:`Target`; InputError naming ``where`` on an unknown kind, a missing, bad or unknown
        parameter.
    """
    p = dict(params)
    try:
        rings = int(p.pop("rings", 24))
        if kind == "spherical_cap":
            t = spherical_cap(float(p.pop("radius")), np.radians(float(p.pop("angle_deg"))), rings)
        elif kind == "saddle":
            t = saddle(float(p.pop("disk_radius")), float(p.pop("curvature_radius")), rings)
        elif kind == "mixed":
            t = mixed(float(p.pop("disk_radius")), float(p.pop("curvature_radius")), float(p.pop("height")),
                      float(p.pop("width")), float(p.pop("offset")), rings)
        elif kind == "petal":
            t = petal(float(p.pop("half_length")), float(p.pop("half_width")), float(p.pop("fold_slope")),
                      float(p.pop("fold_width")), float(p.pop("curl_radius")), rings)
        elif kind == "cylinder":
            t = cylinder(float(p.pop("radius")), np.radians(float(p.pop("angle_deg"))), float(p.pop("length")), rings)
        else:
            raise InputError(f"unknown procedural target {kind!r} (use one of {', '.join(KINDS)})",
                             where=f"{where}.kind")
    except KeyError as e:
        raise InputError(f"missing parameter {e.args[0]!r} for target kind {kind!r}", where=where) from None
    except (TypeError, ValueError) as e:
        raise InputError(f"bad parameter for target kind {kind!r}: {e}", where=where) from None
    if p:
        raise InputError(f"unknown parameter(s) {', '.join(sorted(p))} for target kind {kind!r}", where=where)
    return t


def validate(V, F, name: str = "target", *, where: str | None = None) -> Target:
    """Check disk topology.

    Args:
        V: (n,3) [m] vertices.
        F: (m,3) faces.
        name: the target's name.
        where: what an error names (None: ``name``).

    Returns:
        The :class:`Target`; InputError (naming ``where``) on non-finite coordinates, degenerate faces,
        non-manifold edges, no or several boundary loops, several components, Euler characteristic != 1.
    """

    where = where or name
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
        raise InputError("needs vertices (n,3) and at least one triangle", where=where)
    if not np.all(np.isfinite(V)):
        raise InputError("non-finite vertex coordinates", where=where)
    if F.min() < 0 or F.max() >= len(V):
        raise InputError("face indices out of range", where=where)
    used = np.unique(F)
    if len(used) != len(V):
        remap = np.full(len(V), -1)
        remap[used] = np.arange(len(used))
        V, F = V[used], remap[F]
    areas = face_areas(V, F)
    scale = float(np.max(np.ptp(V, axis=0)))
    bad = int(np.sum(areas <= 1e-12 * scale**2))
    if bad:
        raise InputError(f"{bad} degenerate (zero-area) faces", where=where)
    try:
        boundary_loop(F, len(V))
    except InputError as e:
        raise InputError(e.args[0] if e.args else str(e), where=where) from None
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    n = len(V)
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    G = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    ncomp = connected_components(G, directed=False)[0]
    if ncomp != 1:
        raise InputError(f"surface has {ncomp} connected components (needs one)", where=where)
    n_edges = len(np.unique(np.sort(e, axis=1), axis=0))
    chi = n - n_edges + len(F)
    if chi != 1:
        raise InputError(f"surface is not a disk (Euler characteristic {chi}, needs 1: handles or holes)", where=where)
    # consistent winding: every interior edge is traversed once in each direction
    d = np.unique(e, axis=0)
    if len(d) != len(e):
        raise InputError("inconsistent face winding (an edge is traversed twice in the same direction)", where=where)
    return Target(V=V, F=F, name=name)


def check_size(target: Target, *, units: str, where: str) -> None:
    """Refuse a target whose size (bounding-box diagonal) is implausible for its units.

    Args:
        target: the loaded target (coordinates in metres).
        units: the units its coordinates were read in ("m", "mm", "cm"), named in the message.
        where: the file (or scene field) to name.

    Raises:
        InputError: the diagonal is ``<= SIZE_RANGE_M[0]`` or ``>= SIZE_RANGE_M[1]``.
    """
    lo, hi = SIZE_RANGE_M
    d = target.diameter
    if lo < d < hi:
        return
    scale = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}.get(units, 1.0)
    hint = next((f"; read in {u} it would be {d / scale * f * 1e3:.4g} mm across" for u, f in
                 (("mm", 1e-3), ("cm", 1e-2), ("m", 1.0)) if u != units and lo < d / scale * f < hi), "")
    raise InputError(f"target is {d:.4g} m across read in {units} (plausible: {lo * 1e3:g} mm to {hi:g} m){hint}: "
                     f"give its units (--units, or [target] units in a scene file)", where=where)


def load(path, *, units: str = "m") -> Target:
    """Read an OBJ/STL/PLY target and validate it (:func:`validate`).

    Args:
        path: the mesh file.
        units: its units ("m", "mm" or "cm").

    Returns:
        The :class:`Target` (metres).
    """

    mesh, _ = read_mesh(path, units=units)
    return validate(np.asarray(mesh.vertices), np.asarray(mesh.faces), name=str(path), where=str(path))
