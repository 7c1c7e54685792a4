"""Where a grown support meets what it holds: aiming targets at objects, contact patches, load paths.

- *ground* objects have a root on them (within ``GROUND_CONTACT`` of their diagonal); the other
  objects are *held*. A held object is *supported* when a target site lies within
  ``AIM_DISTANCE`` D of it (D the objects' bounding-box diagonal), or, in surface mode, when its
  surface is sampled.
- :func:`aim_targets` moves each target site that lies off its supported object (farther than
  half the thinnest branch radius) onto the nearest point of the object's surface, so the final
  branch grows onto the object and the carved skin rests on it.
- :func:`target_contacts`: a load point (a reached target or a surface contact, node i, radius
  r) *touches* the held object nearest to it when the skin within d + 2 r of the node (d the
  node's distance to the object) has a contact patch, facets whose corners all lie within
  ``GAP_PER_R`` r of the object's surface, of at least ``MIN_AREA_FRACTION`` pi r^2. ``gap_m`` is
  the smallest distance from that part of the skin to the object (0 when touching).
- :func:`load_paths`: each supported object's weight goes to the points touching it; a supported
  object with weight that no point touches has no load path (the caller fails or warns).
"""

from __future__ import annotations

import dataclasses

import numpy as np

import simfab.growth.tolerances as tol
from simfab.errors import InputError

#: a skin facet lies on an object when its corners are within this fraction of the branch radius of it
GAP_PER_R = 0.02
#: a contact patch must cover at least this fraction of the branch's section pi r^2
MIN_AREA_FRACTION = 0.25
#: targets within this fraction of the objects' diagonal of a held object belong to it (and are aimed at it)
AIM_DISTANCE = 0.1


@dataclasses.dataclass(frozen=True, kw_only=True)
class TargetContact:
    """Contact of one load point: ``object`` the held object nearest to it (None: no held
    object), ``gap_m`` [m] from the skin near the point to that object, ``contact_area_m2`` [m^2]
    of the patch on its surface, ``min_area_m2`` [m^2] the patch needed, ``touching``."""

    name: str
    node: int
    object: str | None
    gap_m: float
    contact_area_m2: float
    min_area_m2: float
    touching: bool


@dataclasses.dataclass(frozen=True, kw_only=True)
class LoadPaths:
    """Which load points carry which supported object: ``carriers`` object -> point names
    touching it; ``dropped`` the supported objects with weight that no point touches, each with
    the names of the load points nearest to it (its intended carriers)."""

    carriers: dict
    dropped: dict


def ground_objects(scene) -> list:
    """Names of the objects a root stands on (within ``GROUND_CONTACT`` of their diagonal)."""
    out = []
    for name, m in scene.objects.items():
        if not len(scene.roots):
            break
        _, d, _ = m.nearest.on_surface(scene.roots)
        if np.any(d <= tol.GROUND_CONTACT * float(np.linalg.norm(m.extents))):
            out.append(name)
    return out


def require_ground(scene) -> list:
    """:func:`ground_objects`, or InputError naming the scene file and its root sites when no root
    stands on an object (the structural check clamps the support there).

    Args:
        scene: the growth scene.

    Returns:
        The names of the objects a root stands on (at least one).
    """
    ground = ground_objects(scene)
    if not ground:
        where = f"{scene.path}: " if scene.path else ""
        raise InputError(f"no object under the roots to clamp the support to: a root must stand on an object "
                         f"(within {100 * tol.GROUND_CONTACT:g} % of the object's diagonal) for the structural check",
                         where=f"{where}site {', '.join(scene.root_names)}")
    return ground


def _diag(scene) -> float:
    return float(np.linalg.norm(np.ptp(scene.objects_bbox(), axis=0)))


def _nearest_held(scene, points: np.ndarray, held: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per point the index into ``held`` of the nearest held object (-1: none), its distance [m]
    and the nearest surface point (k, 3) [m]."""
    k = len(points)
    best = np.full(k, -1)
    dist = np.full(k, np.inf)
    close = np.zeros((k, 3))
    for j, name in enumerate(held):
        c, d, _ = scene.objects[name].nearest.on_surface(points)
        better = d < dist
        best[better], dist[better], close[better] = j, d[better], c[better]
    return best, dist, close


def supported_objects(scene) -> dict:
    """Held object name -> the target site names that belong to it (within ``AIM_DISTANCE`` D);
    in surface mode also every sampled held object (with no target names)."""
    ground = set(ground_objects(scene))
    held = [n for n in scene.objects if n not in ground]
    out: dict = {}
    if held and len(scene.targets):
        j, d, _ = _nearest_held(scene, scene.targets, held)
        for name, jj, dd in zip(scene.target_names, j, d):
            if jj >= 0 and dd <= AIM_DISTANCE * _diag(scene):
                out.setdefault(held[jj], []).append(name)
    if scene.params.mode == "surface":
        for n in scene.params.surface_objects or held:
            if n in held:
                out.setdefault(n, [])
    return out


def aim_targets(scene, *, min_offset: float = 0.0):
    """``scene`` with every target site that belongs to a held object (:func:`supported_objects`)
    but lies more than ``min_offset`` [m] (and ``GROUND_CONTACT`` of its diagonal) off its
    surface moved onto the nearest surface point (module docstring). A smaller offset is left
    alone: the skin's ball around the target (radius >= 2 ``min_offset``) still reaches the object."""
    ground = set(ground_objects(scene))
    held = [n for n in scene.objects if n not in ground]
    if not held or not len(scene.targets):
        return scene
    j, d, c = _nearest_held(scene, scene.targets, held)
    T = scene.targets.copy()
    for i, (jj, dd) in enumerate(zip(j, d)):
        if jj < 0 or dd > AIM_DISTANCE * _diag(scene):
            continue
        if dd > max(min_offset, tol.GROUND_CONTACT * float(np.linalg.norm(scene.objects[held[jj]].extents))):
            T[i] = c[i]
    if np.array_equal(T, scene.targets):
        return scene
    return dataclasses.replace(scene, targets=T)


def load_points(skeleton) -> dict:
    """Where the support meets what it holds: name -> skeleton node, the reached targets (by
    their site names) and, in surface mode, the contacts (``contact_<node>``)."""
    out = dict(skeleton.target_nodes())
    for i in np.nonzero(skeleton.contact_mask())[0]:
        out.setdefault(f"contact_{int(i)}", int(i))
    return out


def target_contacts(mesh, skeleton, scene) -> tuple:
    """:class:`TargetContact` of every load point (:func:`load_points`) of ``skeleton`` whose
    skin is ``mesh`` (``trimesh.Trimesh``, the objects carved out)."""
    points = load_points(skeleton)
    ground = set(ground_objects(scene))
    held = [n for n in scene.objects if n not in ground]
    names = list(points)
    if not names:
        return ()
    idx = np.array([points[n] for n in names], np.int64)
    P = skeleton.nodes[idx]
    r = skeleton.radius[idx]
    if not held:
        return tuple(TargetContact(name=n, node=int(i), object=None, gap_m=float("inf"), contact_area_m2=0.0,
                                   min_area_m2=float(MIN_AREA_FRACTION * np.pi * rr * rr), touching=False)
                     for n, i, rr in zip(names, idx, r))
    j, d, _ = _nearest_held(scene, P, held)
    V = np.asarray(mesh.vertices, np.float64)
    F = np.asarray(mesh.faces, np.int64)
    area = np.asarray(mesh.area_faces, np.float64)
    cen = V[F].mean(axis=1)
    vdist = {}
    for jj in np.unique(j):
        _, dv, _ = scene.objects[held[jj]].nearest.on_surface(V)
        vdist[int(jj)] = dv
    out = []
    for n, i, p, rr, jj, dd in zip(names, idx, P, r, j, d):
        dv = vdist[int(jj)]
        reach = dd + 2.0 * rr
        near_v = np.linalg.norm(V - p, axis=1) <= reach
        gap = float(dv[near_v].min()) if near_v.any() else float(max(dd - rr, 0.0))
        on = np.all(dv[F] <= GAP_PER_R * rr, axis=1) & (np.linalg.norm(cen - p, axis=1) <= reach)
        a = float(area[on].sum())
        amin = float(MIN_AREA_FRACTION * np.pi * rr * rr)
        touching = a >= amin
        out.append(TargetContact(name=n, node=int(i), object=held[int(jj)], gap_m=0.0 if touching else gap,
                                 contact_area_m2=a, min_area_m2=amin, touching=bool(touching)))
    return tuple(out)


def load_paths(scene, contacts: tuple, masses: dict) -> LoadPaths:
    """Carriers and dropped weights of the supported objects (module docstring); ``masses``
    object name -> mass [kg]."""
    carriers: dict = {}
    for c in contacts:
        if c.touching and c.object is not None:
            carriers.setdefault(c.object, []).append(c.name)
    dropped = {}
    for obj, sites in supported_objects(scene).items():
        if obj not in carriers and masses.get(obj, 0.0) > 0:
            dropped[obj] = [c.name for c in contacts if c.object == obj] or list(sites)
    return LoadPaths(carriers=carriers, dropped=dropped)
