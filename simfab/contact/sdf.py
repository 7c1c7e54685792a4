"""Exact signed distance of objects made of primitive geoms (sphere, capsule, cylinder, box, torus).

For an object whose geoms are all primitives the contact uses their exact signed distance instead
of the IMLS of sampled meshes (whose faceting and curvature bias cost accuracy: docs/methods.md,
"simfab.contact.sdf"): the interface of :class:`simfab.contact.imls.ImlsField` (``evaluate`` ->
ImlsEval with psi > 0 inside, gradient, Hessian), defined everywhere. Per primitive (local
q = Q^T (x - c)):

- sphere radius r: psi = r - |q|; capsule (half-length h along z): psi = r - |q - (0, 0, clamp(q_z, -h, h))|
- cylinder: a = |q_xy| - r, b = |q_z| - h, psi = -(|max((a, b), 0)| + min(max(a, b), 0))
- box half-extents e: u = |q| - e, psi = -(|max(u, 0)| + min(max(u), 0))
- torus (MuJoCo's ``mujoco.sdf.torus`` plugin, R = radius1, r = radius2): w = (|q_xy| - R, q_z), psi = r - |w|

A union of geoms takes the largest psi. 2D objects are cross-sections at z = 0
(:func:`section_primitives`). The gradient is exact; the Hessian is the active primitive's.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from simfab.contact.imls import ImlsEval
from simfab.io.mjcf import torus_radii
from simfab.rotations import pose_matrix, quat_to_matrix

KINDS = ("sphere", "capsule", "cylinder", "box", "torus")


@dataclass(frozen=True, kw_only=True)
class Primitive:
    """kind in KINDS; size: (r,) sphere, (r, h) capsule/cylinder (h half-length along local z),
    (ex, ey, ez) box half-extents, (R, r) torus (major and tube radius, axis local z) [m]; centre
    (3,) [m] and rotation (3, 3) in O's body frame."""

    kind: str
    size: tuple
    centre: np.ndarray
    rotation: np.ndarray

    def area(self) -> float:
        if self.kind == "sphere":
            return 4 * np.pi * self.size[0] ** 2
        if self.kind == "capsule":
            r, h = self.size
            return 4 * np.pi * r * r + 4 * np.pi * r * h
        if self.kind == "cylinder":
            r, h = self.size
            return 2 * np.pi * r * r + 4 * np.pi * r * h
        if self.kind == "torus":
            return 4 * np.pi**2 * self.size[0] * self.size[1]
        ex, ey, ez = self.size
        return 8 * (ex * ey + ey * ez + ez * ex)

    def feature(self) -> float:
        """Smallest radius of curvature or half-extent [m] (the field's length scale)."""
        return float(min(self.size))


def _rigid_pose(pose) -> tuple[np.ndarray, np.ndarray]:
    """:func:`simfab.rotations.pose_matrix` of ``pose``, returning an (R (3, 3), p (3,)) float64 pair as it
    is (the coupling's poses: this runs on every field evaluation)."""
    if type(pose) is tuple and len(pose) == 2:
        R, p = pose
        if (type(R) is np.ndarray and type(p) is np.ndarray and R.shape == (3, 3) and p.shape == (3,)
                and R.dtype == np.float64 and p.dtype == np.float64):
            return R, p
    return pose_matrix(pose)


def _local_sdf(kind: str, size, q: np.ndarray, hessian: bool):
    """(psi (k,), grad (k, 3), hess (k, 3, 3) or None) in the primitive's frame (psi > 0 inside)."""
    k = len(q)
    H = np.zeros((k, 3, 3)) if hessian else None
    if kind in ("sphere", "capsule"):
        r = size[0]
        p = q.copy()
        if kind == "capsule":
            p[:, 2] -= np.clip(q[:, 2], -size[1], size[1])
        n = np.linalg.norm(p, axis=1)
        u = p / np.maximum(n, 1e-300)[:, None]
        psi = r - n
        g = -u
        if hessian:
            # hess |p| = (I - u u^T) / |p| in the directions p moves with q (all three for a
            # sphere; x, y only along a capsule's straight part)
            P = np.eye(3)[None] - u[:, :, None] * u[:, None, :]
            if kind == "capsule":
                side = np.abs(q[:, 2]) < size[1]
                P[side, 2, :] = 0.0
                P[side, :, 2] = 0.0
            H = -P / np.maximum(n, 1e-300)[:, None, None]
        return psi, g, H
    if kind == "cylinder":
        r, h = size
        rho = np.linalg.norm(q[:, :2], axis=1)
        er = np.zeros((k, 3))
        er[:, :2] = q[:, :2] / np.maximum(rho, 1e-300)[:, None]
        ez = np.zeros((k, 3))
        ez[:, 2] = np.sign(q[:, 2])
        a, b = rho - r, np.abs(q[:, 2]) - h
        out = (a > 0) & (b > 0)  # nearest point on the rim
        dist = np.maximum(a, b)
        # gradient of the (unsigned outside / negative inside) distance
        gd = np.where((a >= b)[:, None], er, ez)
        if hessian:
            # side (a >= b): d = rho - r, hess = (I_xy - e_r e_r^T) / rho; caps: 0
            side = (a >= b) & ~out
            Pxy = np.zeros((k, 3, 3))
            Pxy[:, 0, 0] = Pxy[:, 1, 1] = 1.0
            Pxy -= er[:, :, None] * er[:, None, :]
            Hd = np.where(side[:, None, None], Pxy / np.maximum(rho, 1e-300)[:, None, None], 0.0)
        if out.any():  # the rim: the distance to the circle of radius r at z = +-h
            rim = q[out] - np.c_[np.zeros((out.sum(), 2)), np.sign(q[out, 2]) * h]
            dist[out], gd[out], H_rim = _circle_distance(rim, r, hessian)
            if hessian:
                Hd[out] = H_rim
        return -dist, -gd, (-Hd if hessian else None)
    if kind == "torus":
        return _torus_sdf(size, q, hessian)
    return _box_sdf(_extents(size) if type(size) is tuple else np.asarray(size, float), q, hessian)


_DIAG = np.arange(3)


_NEAR = np.ones(0, dtype=bool)


def _near(k: int) -> np.ndarray:
    """(k,) True, read-only: an exact field is defined everywhere (a view of one shared array)."""
    global _NEAR
    if len(_NEAR) < k:
        near = np.ones(max(k, 2 * len(_NEAR), 256), dtype=bool)
        near.flags.writeable = False
        _NEAR = near
    return _NEAR[:k]


@functools.lru_cache(maxsize=64)
def _extents(size: tuple) -> np.ndarray:
    """A box's half-extents as a read-only float64 array (once per size)."""
    e = np.asarray(size, dtype=np.float64)
    e.flags.writeable = False
    return e


def _box_sdf(e: np.ndarray, q: np.ndarray, hessian: bool):
    """:func:`_local_sdf` of a box of half-extents e (3,) [m]."""
    u = np.abs(q)
    u -= e
    pos = np.maximum(u, 0.0)
    n = np.sqrt(np.add.reduce(pos * pos, axis=1))
    if not len(n) or np.minimum.reduce(n) > 0:  # (the usual case: every point outside O)
        psi, n_out, ins = -n, n, None
    else:
        outside = n > 0
        psi = np.where(outside, -n, -u.max(axis=1))
        n_out = np.where(outside, n, 1.0)  # (inside, pos = 0: g's row is set below)
        ins = ~outside
    # -(pos * sign(q)) / n, sign(0) = 1 (pos = 0 where q = 0: the copied sign only signs a zero)
    g = np.copysign(pos, q)
    g /= -n_out[:, None]
    if ins is not None:
        rows = np.flatnonzero(ins)
        j = np.argmax(u[rows], axis=1)
        g[rows, j] = np.where(q[rows, j] >= 0, -1.0, 1.0)
    H = None
    if hessian:
        if ins is not None and np.count_nonzero(ins) == len(q):
            H = np.zeros((len(q), 3, 3))
        else:
            # outside: distance to a face (flat: 0), an edge or a corner: (I - n n^T) / d over the axes
            # that are outside (the others move the nearest point along); every row at once, inside
            # rows zeroed after. P_m = diag(m) with m = 1 on those axes (m m^T I: 0 off the diagonal)
            Pm = np.zeros((len(q), 3, 3))
            Pm[:, _DIAG, _DIAG] = pos > 0
            Pm -= g[:, :, None] * g[:, None, :]
            Pm /= n_out[:, None, None]
            H = np.negative(Pm, out=Pm)
            if ins is not None:
                H[ins] = 0.0
    return psi, g, H


def _torus_sdf(size, q: np.ndarray, hessian: bool):
    """Torus of major radius R and tube radius r about local z: psi = r - d, d the distance to its
    centre circle (:func:`_circle_distance`)."""
    R, r = size
    d, g, H = _circle_distance(q, R, hessian)
    return r - d, -g, (-H if hessian else None)


def _circle_distance(q: np.ndarray, R: float, hessian: bool):
    """(d (k,), grad d (k, 3), hess d (k, 3, 3) or None): distance from local points q (k, 3) to the
    circle of radius R about the z axis in the plane z = 0. With rho = |q_xy|, e_r the radial unit
    vector, t = e_r x e_z the azimuthal one: d = |(rho - R, q_z)|, grad d = n = ((rho - R) e_r +
    q_z e_z) / d, hess d = (e_r e_r^T + e_z e_z^T - n n^T) / d + (rho - R) / (d rho) t t^T.
    (The cylinder's rim and the torus' centre circle.)"""
    k = len(q)
    rho = np.linalg.norm(q[:, :2], axis=1)
    er = np.zeros((k, 3))
    er[:, :2] = q[:, :2] / np.maximum(rho, 1e-300)[:, None]
    ez = np.zeros((k, 3))
    ez[:, 2] = 1.0
    a = rho - R
    d = np.hypot(a, q[:, 2])
    ds = np.maximum(d, 1e-300)
    n = (a[:, None] * er + q[:, 2:3] * ez) / ds[:, None]
    if not hessian:
        return d, n, None
    t = np.cross(er, ez)
    P = er[:, :, None] * er[:, None, :] + ez[:, :, None] * ez[:, None, :]
    H = (P - n[:, :, None] * n[:, None, :]) / ds[:, None, None] + \
        (t[:, :, None] * t[:, None, :]) * (a / (ds * np.maximum(rho, 1e-300)))[:, None, None]
    return d, n, H


def _world_sdf(prim: Primitive, M: np.ndarray, off: np.ndarray, x: np.ndarray, hessian: bool):
    """(psi (k,), grad (k, dim), hess (k, dim, dim) or None) of one primitive at world points x (k, dim)
    whose local coordinates are q = x M - off (:meth:`PrimitiveField._frames`): the local field's
    gradient g and Hessian H mapped back as g M^T and M H M^T (products of (k * 3, dim) arrays)."""
    k, dim = x.shape
    q = x @ M
    q -= off
    psi, g, H = _local_sdf(prim.kind, prim.size, q, hessian)
    grad = g @ M.T
    if not hessian:
        return psi, grad, None
    A = (H.reshape(-1, 3) @ M.T).reshape(k, 3, dim)  # H M^T; then (H M^T)^T M^T = M H M^T (H symmetric)
    return psi, grad, (A.transpose(0, 2, 1).reshape(-1, 3) @ M.T).reshape(k, dim, dim)


@dataclass(kw_only=True, eq=False)
class PrimitiveField:
    """Exact signed distance of a union of primitives in O's body frame (see the module docstring).

    Matches the ImlsField interface used by the coupling: ``evaluate``, ``sigma`` (here the
    smallest feature size / 10 [m], the field's length scale for curvature bounds), ``radius`` =
    inf (every point is near), ``far_distance``, ``vertices`` / ``normals`` (display samples on the
    exact surface), ``dim``."""

    primitives: tuple
    dim: int
    vertices: np.ndarray
    normals: np.ndarray
    sigma: float
    radius: float = np.inf
    far_distance: float = np.inf
    _cache: dict = field(default_factory=dict, repr=False)
    #: |grad psi| = 1 (to round-off) wherever it is evaluated: the coupling need not watch its peak
    unit_gradient = True

    def evaluate(self, points, pose=None, *, hessian: bool = True, hessian_band: float | None = None) -> ImlsEval:
        """psi (> 0 inside), gradient and Hessian (zeros where psi <= -hessian_band) at world points
        (k, dim) for O's ``pose`` (as in :func:`simfab.contact.imls.evaluate_imls`)."""
        dim = self.dim
        pts = np.asarray(points, dtype=np.float64).reshape(-1, dim)
        R, p = _rigid_pose(pose)
        k = len(pts)
        if len(self.primitives) == 1 and self.primitives[0].kind == "sphere":
            return self._sphere(pts, R, p, hessian, hessian_band)
        frames = self._frames(R, p)
        if len(frames) == 1:  # (one primitive: no union's masks)
            psi, grad, hess = _world_sdf(self.primitives[0], *frames[0], pts, hessian)
        else:
            psi = np.full(k, -np.inf)
            grad = np.zeros((k, dim))
            hess = np.zeros((k, dim, dim)) if hessian else None
            for prim, (M, off) in zip(self.primitives, frames):
                ps, g, H = _world_sdf(prim, M, off, pts, hessian)
                better = ps > psi
                psi[better] = ps[better]
                grad[better] = g[better]
                if hessian:
                    hess[better] = H[better]
        if not hessian:
            return ImlsEval(psi=psi, grad=grad, hess=np.zeros((k, dim, dim)), near=_near(k))
        if hessian_band is not None:
            hess[psi <= -hessian_band] = 0.0
        return ImlsEval(psi=psi, grad=grad, hess=hess, near=_near(k))

    def _frames(self, R: np.ndarray, p: np.ndarray) -> list:
        """Per primitive (M (dim, 3), off (3,)) with its local coordinates q = x M - off for world points x
        (k, dim) when O is at (R, p): q = Q^T (R^T (x - p) - c), so M = R_dd Q_d (R's leading (dim, dim)
        block, Q's first dim rows: a 2D object turns about z and its points lie at z = 0) and
        off = p_d M + Q^T c. One product per evaluation instead of a body frame and a local frame.
        (The last pose's, remembered: Newton's evaluations of a step share O's pose.)"""
        key = (R.tobytes(), p.tobytes())
        memo = self._cache.get("frames")
        if memo is not None and memo[0] == key:
            return memo[1]
        dim = self.dim
        out = []
        for prim in self.primitives:
            Q = prim.rotation
            M = R[:dim, :dim] @ Q[:dim]
            out.append((M, p[:dim] @ M + prim.centre @ Q))
        self._cache["frames"] = (key, out)
        return out

    def _sphere(self, pts, R, p, hessian, hessian_band) -> ImlsEval:
        """Fast path of a single sphere (a circle in 2D): psi = r - |x - c|, grad = -u,
        hess = -(I - u u^T) / |x - c| (world frame directly: c mapped by the pose)."""
        dim = self.dim
        prim = self.primitives[0]
        c = (R @ prim.centre + p)[:dim]
        rel = pts - c
        n = np.sqrt(np.einsum("kd,kd->k", rel, rel))
        inv = 1.0 / np.maximum(n, 1e-300)
        u = rel * inv[:, None]
        psi = prim.size[0] - n
        k = len(pts)
        hess = np.zeros((k, dim, dim))
        if hessian:
            sel = slice(None) if hessian_band is None else np.flatnonzero(psi > -hessian_band)
            us, inv_s = u[sel], inv[sel]
            if len(us):
                h = us[:, :, None] * us[:, None, :]
                h[:, range(dim), range(dim)] -= 1.0
                hess[sel] = h * inv_s[:, None, None]
        return ImlsEval(psi=psi, grad=-u, hess=hess, near=_near(k))

    def far_lower_bound(self, points, pose=None) -> np.ndarray:
        return -self.evaluate(points, pose, hessian=False).psi

    def far_bound(self, nearest: np.ndarray) -> np.ndarray:
        return np.asarray(nearest, float)

    def nearest_sample(self, points, pose=None) -> np.ndarray:
        """Distance to O's surface (there are no far points: it is never beyond ``radius``)."""
        return np.abs(self.evaluate(points, pose, hessian=False).psi)


def primitives_of_body(model, body_id: int, plugins: dict | None = None) -> tuple | None:
    """The body's geoms as :class:`Primitive` in the body frame, or None when any of its geoms is not
    a sphere, capsule, cylinder, box or torus (an SDF geom of the ``mujoco.sdf.torus`` plugin; its
    radii from ``plugins``, :attr:`simfab.io.mjcf.Scene.sdf_plugins`), or it has none."""
    import mujoco


    G = mujoco.mjtGeom
    kinds = {int(G.mjGEOM_SPHERE): "sphere", int(G.mjGEOM_CAPSULE): "capsule", int(G.mjGEOM_CYLINDER): "cylinder",
             int(G.mjGEOM_BOX): "box"}
    out = []
    for g in range(model.ngeom):
        if int(model.geom_bodyid[g]) != body_id:
            continue
        kind = kinds.get(int(model.geom_type[g]))
        torus = torus_radii(model, g, plugins)
        if kind is None and torus is None:
            return None
        s = np.asarray(model.geom_size[g], float)
        size = torus or {"sphere": (s[0],), "capsule": (s[0], s[1]), "cylinder": (s[0], s[1]),
                         "box": tuple(s[:3])}[kind]
        kind = kind or "torus"
        out.append(Primitive(kind=kind, size=tuple(float(v) for v in size), centre=np.asarray(model.geom_pos[g], float),
                             rotation=quat_to_matrix(np.asarray(model.geom_quat[g], float))))
    return tuple(out) or None


def section_primitives(prims: tuple) -> tuple | None:
    """The 2D cross-section at z = 0 of ``prims`` as primitives whose section is exact in this
    module (a sphere, or a capsule / cylinder with its axis along z, crossing z = 0 -> a sphere of
    the same radius (a circle); a box with an axis along z -> itself); None when one is not."""
    out = []
    for p in prims:
        Q = p.rotation
        along_z = abs(abs(Q[2, 2]) - 1.0) < 1e-9
        c = p.centre
        if p.kind == "torus":  # its section is an annulus or two discs: sampled instead
            return None
        if p.kind == "sphere":
            r = float(np.sqrt(max(p.size[0] ** 2 - c[2] ** 2, 0.0)))
            if r > 0:
                out.append(Primitive(kind="sphere", size=(r,), centre=np.r_[c[:2], 0.0], rotation=np.eye(3)))
            continue
        if not along_z:
            return None
        if p.kind in ("capsule", "cylinder"):
            if abs(c[2]) <= p.size[1]:
                out.append(Primitive(kind="sphere", size=(p.size[0],), centre=np.r_[c[:2], 0.0], rotation=np.eye(3)))
            continue
        if abs(c[2]) <= p.size[2 if abs(Q[2, 2]) > 0.5 else 0]:
            out.append(Primitive(kind="box", size=(p.size[0], p.size[1], np.inf), centre=np.r_[c[:2], 0.0],
                                 rotation=Q))
    return tuple(out) or None


def primitive_surface_samples(prims: tuple, n: int, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """About n points on the union's exact surface with exact outward normals (deterministic;
    points inside another primitive dropped): display geometry and sample counts."""
    pts, nrm = [], []
    total = sum(_area(p, dim) for p in prims)
    for p in prims:
        m = max(8, int(round(n * _area(p, dim) / total)))
        v, w = _sample(p, m, dim)
        pts.append(v)
        nrm.append(w)
    v, w = np.vstack(pts), np.vstack(nrm)
    if len(prims) > 1:
        fld = PrimitiveField(primitives=prims, dim=3, vertices=v, normals=w, sigma=1.0)
        keep = fld.evaluate(v, hessian=False).psi <= 1e-12 * max(p.feature() for p in prims)
        v, w = v[keep], w[keep]
    return v[:, :dim], w[:, :dim]


def _area(p: Primitive, dim: int) -> float:
    if dim == 3:
        return p.area()
    if p.kind == "sphere":
        return 2 * np.pi * p.size[0]
    return 4 * (p.size[0] + p.size[1])


def _sample(p: Primitive, m: int, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """(m', 3) points and outward normals on one primitive's surface, body frame."""
    if dim == 2:
        if p.kind == "sphere":
            t = np.linspace(0, 2 * np.pi, m, endpoint=False)
            u = np.c_[np.cos(t), np.sin(t), np.zeros(m)]
            return p.centre + p.size[0] * u, u
        ex, ey = p.size[0], p.size[1]
        per = 4 * (ex + ey)
        s = (np.arange(m) + 0.5) / m * per
        q, nq = np.zeros((m, 3)), np.zeros((m, 3))
        for i, si in enumerate(s):
            if si < 2 * ex:
                q[i], nq[i] = (-ex + si, -ey, 0), (0, -1, 0)
            elif si < 2 * ex + 2 * ey:
                q[i], nq[i] = (ex, -ey + si - 2 * ex, 0), (1, 0, 0)
            elif si < 4 * ex + 2 * ey:
                q[i], nq[i] = (ex - (si - 2 * ex - 2 * ey), ey, 0), (0, 1, 0)
            else:
                q[i], nq[i] = (-ex, ey - (si - 4 * ex - 2 * ey), 0), (-1, 0, 0)
        return p.centre + q @ p.rotation.T, nq @ p.rotation.T
    if p.kind == "sphere":
        u = _fibonacci(m)
        q, nq = p.size[0] * u, u
    elif p.kind in ("capsule", "cylinder"):
        r, h = p.size
        side = 4 * np.pi * r * h
        ends = 4 * np.pi * r * r if p.kind == "capsule" else 2 * np.pi * r * r
        ms = max(4, int(round(m * side / (side + ends))))
        rows = max(1, int(round(np.sqrt(ms * 2 * h / (2 * np.pi * r)))))
        cols = max(3, ms // rows)
        t, z = np.meshgrid(2 * np.pi * (np.arange(cols) + 0.5) / cols, h * (2 * (np.arange(rows) + 0.5) / rows - 1))
        t, z = t.ravel(), z.ravel()
        qs = np.c_[r * np.cos(t), r * np.sin(t), z]
        ns = np.c_[np.cos(t), np.sin(t), np.zeros_like(t)]
        me = max(2, m - len(qs))
        if p.kind == "capsule":
            u = _fibonacci(me)
            qe = r * u + np.c_[np.zeros(me), np.zeros(me), np.where(u[:, 2] >= 0, h, -h)]
            ne = u
        else:
            k = max(1, me // 2)
            rr = r * np.sqrt((np.arange(k) + 0.5) / k)
            a = np.arange(k) * np.pi * (3 - np.sqrt(5))
            disk = np.c_[rr * np.cos(a), rr * np.sin(a)]
            qe = np.vstack([np.c_[disk, np.full(k, h)], np.c_[disk, np.full(k, -h)]])
            ne = np.vstack([np.tile([0, 0, 1.0], (k, 1)), np.tile([0, 0, -1.0], (k, 1))])
        q, nq = np.vstack([qs, qe]), np.vstack([ns, ne])
    elif p.kind == "torus":
        R, r = p.size
        n_major = max(8, int(round(np.sqrt(m * R / r))))
        n_tube = max(6, m // n_major)
        t, f = np.meshgrid(2 * np.pi * (np.arange(n_major) + 0.5) / n_major, 2 * np.pi * np.arange(n_tube) / n_tube)
        t, f = t.ravel(), f.ravel()
        nq = np.c_[np.cos(f) * np.cos(t), np.cos(f) * np.sin(t), np.sin(f)]
        q = np.c_[R * np.cos(t), R * np.sin(t), np.zeros_like(t)] + r * nq
    else:
        e = np.asarray(p.size, float)
        qs, ns = [], []
        for ax in range(3):
            b, c = [i for i in range(3) if i != ax]
            mf = max(1, int(round(m * e[b] * e[c] / (2 * (e[0] * e[1] + e[1] * e[2] + e[2] * e[0])) / 2)))
            nb = max(1, int(round(np.sqrt(mf * e[b] / e[c]))))
            nc = max(1, mf // nb)
            gb, gc = np.meshgrid(e[b] * (2 * (np.arange(nb) + 0.5) / nb - 1),
                                 e[c] * (2 * (np.arange(nc) + 0.5) / nc - 1))
            for sgn in (-1.0, 1.0):
                f = np.zeros((gb.size, 3))
                f[:, ax], f[:, b], f[:, c] = sgn * e[ax], gb.ravel(), gc.ravel()
                nf = np.zeros((gb.size, 3))
                nf[:, ax] = sgn
                qs.append(f)
                ns.append(nf)
        q, nq = np.vstack(qs), np.vstack(ns)
    return p.centre + q @ p.rotation.T, nq @ p.rotation.T


def _fibonacci(m: int) -> np.ndarray:
    """(m, 3) near-uniform unit vectors (Fibonacci lattice)."""
    i = np.arange(m) + 0.5
    z = 1 - 2 * i / m
    a = i * np.pi * (3 - np.sqrt(5))
    r = np.sqrt(1 - z * z)
    return np.c_[r * np.cos(a), r * np.sin(a), z]


def build_primitive_field(prims: tuple, dim: int, samples: int = 2000) -> PrimitiveField:
    """The exact signed-distance field of primitive geoms.

    Args:
        prims: the primitives (body frame; for dim 2 already the z = 0 section, :func:`section_primitives`).
        dim: 2 or 3.
        samples: display samples of the surface.

    Returns:
        The :class:`PrimitiveField`.
    """
    v, w = primitive_surface_samples(prims, samples, dim)
    feature = min(p.feature() for p in prims)
    return PrimitiveField(primitives=tuple(prims), dim=dim, vertices=v, normals=w, sigma=0.1 * feature)
