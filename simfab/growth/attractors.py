"""Random attractor placement: in a volume, on object surfaces, or on a swept 2D profile.

Each sampler takes a ``numpy.random.Generator`` (seeded by the caller) and returns
``(points (n, 3) [m], area)`` where ``area`` [m²] is the sampled surface area (None for
volume sampling; it sets the default growth distances, see :func:`simfab.growth.config.resolve`).
Points inside obstacles (watertight objects, spheres) are rejected.
"""

from __future__ import annotations

import numpy as np

from simfab.errors import InputError

#: rejection sampling rounds before giving up on filling the requested count
_ROUNDS = 8


def in_box(x: np.ndarray, box: np.ndarray) -> np.ndarray:
    """(n,) bool: points (n, 3) inside the axis-aligned box (2, 3)."""
    return np.all((x >= box[0]) & (x <= box[1]), axis=1)


def _rejection_sample(draw, n: int, accept, *, error: str, where: str):
    """Draw candidates in rounds of about twice the shortfall until ``n`` are accepted.

    draw(m) -> (m, 3) candidate points; accept(x) -> (m,) bool. Gives up after ``_ROUNDS``
    rounds with what it has. Returns ``(points (<= n, 3), acceptance fraction)``; raises
    InputError(error, where) when nothing was accepted.
    """
    out, have, tried, accepted = [], 0, 0, 0
    for _ in range(_ROUNDS):
        x = draw(max(n - have, 16) * 2)
        ok = accept(x)
        tried += len(x)
        accepted += int(ok.sum())
        x = x[ok][: n - have]
        out.append(x)
        have += len(x)
        if have >= n:
            break
    pts = np.concatenate(out)
    if len(pts) == 0:
        raise InputError(error, where=where)
    return pts, accepted / tried


def _free(obstacles, keep):
    """Acceptance test: outside the obstacles and where ``keep`` holds."""
    def accept(x):
        ok = ~obstacles.inside(x) if obstacles is not None else np.ones(len(x), bool)
        if keep is not None:
            ok &= keep(x)
        return ok
    return accept


def volume(box: np.ndarray, n: int, rng: np.random.Generator, obstacles, *, keep=None):
    """``n`` points uniform in ``box`` (2, 3), outside obstacles (and where ``keep(x)`` holds)."""
    pts, _ = _rejection_sample(lambda m: rng.uniform(box[0], box[1], size=(m, 3)), n, _free(obstacles, keep),
                               error="no free space for attractors in the design box (it lies inside the objects)",
                               where="growth.box")
    return pts, None


def _surface_points(mesh, n: int, rng: np.random.Generator):
    """Area-weighted uniform samples on a triangle mesh with their face normals."""
    area = mesh.area_faces
    f = rng.choice(len(area), size=n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    w = np.column_stack([1 - s, s * (1 - r2), s * r2])
    tri = mesh.triangles[f]
    return np.einsum("ij,ijk->ik", w, tri), mesh.face_normals[f]


def surface(meshes: list, n: int, rng: np.random.Generator, obstacles, *, lift: float, box=None, keep=None):
    """``n`` points on the union of ``meshes`` surfaces, lifted by ``lift`` [m] along the normal.

    With ``box`` only the parts of the surfaces inside the box are sampled. Returns the
    points and the sampled area [m²] (estimated from the acceptance rate).
    """
    areas = np.array([m.area for m in meshes])
    if not areas.sum() > 0:
        raise InputError("surface mode: the objects have no surface area", where="growth.surface_objects")
    free = _free(obstacles, keep)

    def draw(m):
        counts = rng.multinomial(m, areas / areas.sum())
        xs = []
        for mesh, c in zip(meshes, counts):
            if c:
                x, nrm = _surface_points(mesh, int(c), rng)
                xs.append(x + lift * nrm)
        return np.concatenate(xs)

    def accept(x):
        ok = free(x)
        if box is not None:
            ok &= in_box(x, box)
        return ok

    pts, accepted_fraction = _rejection_sample(
        draw, n, accept, error="surface mode: no attractor could be placed (surfaces outside the box?)",
        where="growth.box")
    return pts, float(areas.sum() * accepted_fraction)


def profile(spec, n: int, rng: np.random.Generator, obstacles, *, keep=None):
    """``n`` points on the closed 2D profile swept along the view direction (see ProfileConfig)."""
    P = np.asarray(spec.points, dtype=np.float64)
    Q = np.roll(P, -1, axis=0)
    seg = np.linalg.norm(Q - P, axis=1)
    perim = float(seg.sum())
    if not perim > 0:
        raise InputError("the profile has zero length", where="profile.points")
    o, u, v = (np.asarray(a, dtype=np.float64) for a in (spec.origin, spec.u, spec.v))
    view = np.cross(u, v)
    view /= np.linalg.norm(view)
    d0, d1 = spec.depth
    cum = np.concatenate([[0.0], np.cumsum(seg)])

    def draw(m):
        s = rng.random(m) * perim
        i = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1)
        f = (s - cum[i]) / np.where(seg[i] > 0, seg[i], 1.0)
        ab = P[i] + f[:, None] * (Q[i] - P[i])
        depth = rng.uniform(d0, d1, size=m) if d1 > d0 else np.full(m, d0)
        return o + ab[:, :1] * u + ab[:, 1:2] * v + depth[:, None] * view

    pts, _ = _rejection_sample(draw, n, _free(obstacles, keep),
                               error="no attractor on the profile lies outside the objects", where="profile")
    # a zero-depth sweep is a curve: its 'area' is such that sqrt(area / n) = perimeter / n
    return pts, perim * max(d1 - d0, perim / n)
