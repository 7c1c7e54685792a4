"""Kolluri's implicit moving least squares (IMLS) surface of a rigid object O.

For a query point x (O's body frame), samples v_i with unit outward normals n_i, sample weights a_i
and Gaussian weights phi_i(x) = a_i exp(-|x - v_i|^2 / sigma^2):

    psi(x) = - sum_i n_i . (x - v_i) phi_i(x) / sum_i phi_i(x)

**psi > 0 inside O**; |psi| approximates the distance to O's surface within a few sigma. The kernel
is truncated at ``radius`` (4 sigma by default) with neighbour lists per cell of a uniform grid; O
moves rigidly, so queries are mapped into the body frame. Sample weights a_i = 1 / (kernel density)
correct unevenly spread samples (:func:`density_weights`). A point with no sample within ``radius``
is "far": ``near = False``, psi = +-``far_distance`` with the side from the generalized winding
number (:meth:`ImlsField.inside`), zero derivatives. 2D objects are curves in the z = 0 plane. The
accuracy notes: docs/methods.md, "simfab.contact.imls".
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import numpy as np

from simfab._parallel import submit
from simfab._warp import RECORD_LOCK, wp
from simfab.errors import InputError
from simfab.rotations import pose_matrix

#: On the CPU, evaluations at this many points or more run as two launches on two threads.
PARALLEL_MIN_POINTS = 1024
#: Default kernel truncation radius in units of sigma (exp(-16) ~ 1.1e-7 at the cut).
DEFAULT_CUTOFF_SIGMAS = 4.0


@wp.kernel
def _imls_eval(
    origin: wp.vec3d,  # body-frame corner of the cell grid [m]
    inv_cell: wp.float64,  # 1 / cell size [1/m]
    cells: wp.vec3i,  # grid size in cells per axis
    cell_start: wp.array(dtype=wp.int32),  # (cells + 1,) CSR offsets into cell_samples
    cell_samples: wp.array(dtype=wp.int32),  # samples within `radius` of each cell (ascending)
    verts: wp.array(dtype=wp.vec3d),  # (n,) body-frame samples [m]
    normals: wp.array(dtype=wp.vec3d),  # (n,) unit outward normals
    weights: wp.array(dtype=wp.float64),  # (n,) sample weights (area per sample, mean 1)
    inv_sigma2: wp.float64,  # 1/sigma^2 [1/m^2]
    radius: wp.float64,  # kernel truncation radius [m]
    far_psi: wp.float64,  # psi reported at far points [m] (negative)
    points: wp.array(dtype=wp.vec3d),  # (capacity,) query points in O's body frame [m]
    n_points: wp.array(dtype=wp.int32),  # (1,) number of points in use (threads beyond it return)
    hess_band: wp.array(dtype=wp.float64),  # (1,) Hessian only where psi > -hess_band [m] (e.g. d_hat)
    psi_out: wp.array(dtype=wp.float64),
    grad_out: wp.array(dtype=wp.vec3d),
    hess_out: wp.array(dtype=wp.mat33d),
    count_out: wp.array(dtype=wp.int32),
):
    tid = wp.tid()
    if tid >= n_points[0]:
        return
    x = points[tid]
    zero = wp.float64(0.0)
    two = wp.float64(2.0)
    D = zero
    N = zero
    gD = wp.vec3d(zero, zero, zero)
    gN = wp.vec3d(zero, zero, zero)
    HD = wp.mat33d()
    HN = wp.mat33d()
    eye = wp.identity(n=3, dtype=wp.float64)
    r2max = radius * radius
    count = int(0)
    # the cell holding x lists every sample within `radius` of any point of the cell; outside the
    # grid (O's sample box grown by `radius`) no sample is that close
    cx = int(wp.floor((x[0] - origin[0]) * inv_cell))
    cy = int(wp.floor((x[1] - origin[1]) * inv_cell))
    cz = int(wp.floor((x[2] - origin[2]) * inv_cell))
    j0 = int(0)
    j1 = int(0)
    if cx >= 0 and cy >= 0 and cz >= 0 and cx < cells[0] and cy < cells[1] and cz < cells[2]:
        cell = (cx * cells[1] + cy) * cells[2] + cz
        j0 = cell_start[cell]
        j1 = cell_start[cell + 1]
    for j in range(j0, j1):
        i = cell_samples[j]
        r = x - verts[i]
        rr = wp.dot(r, r)
        if rr < r2max:
            count += 1
            n = normals[i]
            phi = weights[i] * wp.exp(-rr * inv_sigma2)
            nr = wp.dot(n, r)
            dphi = (-two * inv_sigma2 * phi) * r  # grad phi
            D += phi
            N += nr * phi
            gD += dphi
            gN += phi * n + nr * dphi
    count_out[tid] = count
    if count == 0:
        psi_out[tid] = far_psi
        grad_out[tid] = wp.vec3d(zero, zero, zero)
        hess_out[tid] = wp.mat33d()
        return
    # f = N / D; psi = -f.  grad f = (gN - f gD)/D
    f = N / D
    gf = (gN - f * gD) / D
    psi_out[tid] = -f
    grad_out[tid] = -gf
    if -f <= -hess_band[0]:
        hess_out[tid] = wp.mat33d()
        return
    # second pass for the Hessian, only near O (the barrier needs it where d < d_hat):
    # hess phi = phi (4 r r^T / sigma^4 - 2 I / sigma^2)
    # hess f = (HN - gf gD^T - gD gf^T - f HD)/D   (from N = f D differentiated twice)
    for j in range(j0, j1):
        i = cell_samples[j]
        r = x - verts[i]
        rr = wp.dot(r, r)
        if rr < r2max:
            n = normals[i]
            phi = weights[i] * wp.exp(-rr * inv_sigma2)
            nr = wp.dot(n, r)
            dphi = (-two * inv_sigma2 * phi) * r
            hphi = phi * (two * two * inv_sigma2 * inv_sigma2 * wp.outer(r, r) - two * inv_sigma2 * eye)
            HD += hphi
            HN += wp.outer(n, dphi) + wp.outer(dphi, n) + nr * hphi
    Hf = (HN - wp.outer(gf, gD) - wp.outer(gD, gf) - f * HD) / D
    hess_out[tid] = -Hf


@dataclass(frozen=True, kw_only=True)
class ImlsEval:
    """IMLS evaluated at k query points (world frame).

    psi  : (k,) [m], > 0 inside O

    Args:
        grad: (k, dim) d psi / d x [-]
        hess: (k, dim, dim) d2 psi / d x2 [1/m] (zeros when not requested)
        near: (k,) bool, False where no sample lies within the kernel radius (field undefined there)
    """

    psi: np.ndarray
    grad: np.ndarray
    hess: np.ndarray
    near: np.ndarray


@dataclass(kw_only=True, eq=False)
class ImlsField:
    """IMLS field of a rigid object in its body frame (immutable model data + a cell grid of
    neighbour lists).

    Args:
        vertices: (n, dim) body-frame surface samples [m]
    normals  : (n, dim) unit outward normals
    sigma    : Gaussian width [m]
    radius   : kernel truncation radius [m]
    far_distance : distance reported at far points [m] (conservative lower bound of the true distance)
    dim      : 2 or 3
    """

    vertices: np.ndarray
    normals: np.ndarray
    sigma: float
    radius: float
    far_distance: float
    dim: int
    device: str = "cpu"
    _cells: object = field(default=None, repr=False)  # _CellLists on the device
    _wverts: object = field(default=None, repr=False)
    _wnormals: object = field(default=None, repr=False)
    _wweights: object = field(default=None, repr=False)
    weights: np.ndarray | None = None  # (n,) sample weights a_i (mean 1)
    area: float | None = None  # O's surface area [m^2] (3D) or perimeter [m] (2D), for the winding number
    _buffers: dict = field(default_factory=dict, repr=False)

    def inside(self, points, pose=None) -> np.ndarray:
        """(k,) bool: world points (k, dim) inside O by the generalized winding number of its
        oriented samples (> 1/2 inside). 3D: libigl's fast winding number with the samples' areas
        a_i * area / n; 2D: the winding number of the closed polygon through the samples (in
        their order, CCW)."""
        b = body_frame(points, pose)
        if len(b) == 0:
            return np.zeros(0, dtype=bool)
        if self.dim == 3:
            import igl

            tree = self._buffers.get("winding")
            if tree is None:  # octree and its expansion, once (rebuilding them per call cost 16x the query)
                P, N = np.ascontiguousarray(self.vertices), np.ascontiguousarray(self.normals)
                A = self.weights * (self.area / len(self.vertices))
                cells, children = igl.octree(P)[:2]
                tree = self._buffers["winding"] = (P, N, A, cells, children,
                                                   *igl.fast_winding_number_precompute(P, N, A, cells, children, 2))
            return np.asarray(igl.fast_winding_number(*tree, np.ascontiguousarray(b), 2.0)) > 0.5
        P = self.vertices
        a = P[None, :, :] - b[:, None, :2]  # (k, n, 2)
        c = np.roll(a, -1, axis=1)
        ang = np.arctan2(a[..., 0] * c[..., 1] - a[..., 1] * c[..., 0], np.einsum("knd,knd->kn", a, c))
        return np.abs(ang.sum(axis=1)) > np.pi

    def evaluate(self, points, pose=None, *, hessian: bool = True, hessian_band: float | None = None) -> ImlsEval:
        """Evaluate psi, its gradient and Hessian at world points (k, dim); see :func:`evaluate_imls`."""
        return evaluate_imls(self, points, pose, hessian=hessian, hessian_band=hessian_band)

    def far_lower_bound(self, points, pose=None) -> np.ndarray:
        """(k,) lower bound of the distance [m] from world points (k, dim) that are *far* (no sample
        within ``radius``; ``near`` False in :func:`evaluate_imls`) to O's surface, sharper than
        ``far_distance`` for points well beyond the radius: the distance to the nearest sample
        minus the same 2 sigma surface-to-sample allowance ``far_distance`` is built on, and never
        below ``far_distance``. Meaningless for near points (use psi there)."""
        return self.far_bound(self.nearest_sample(points, pose))

    def far_bound(self, nearest: np.ndarray) -> np.ndarray:
        """:meth:`far_lower_bound` of far points from their :meth:`nearest_sample` distances (k,) [m]."""
        return np.maximum(self.far_distance, nearest - 2.0 * self.sigma)

    def nearest_sample(self, points, pose=None) -> np.ndarray:
        """(k,) distance [m] from world points (k, dim) to their nearest sample of O; a point is far
        (``near`` False in :func:`evaluate_imls`) when it is at least ``radius``."""
        from scipy.spatial import cKDTree

        tree = self._buffers.get("kdtree")
        if tree is None:
            tree = self._buffers["kdtree"] = cKDTree(_pad3(self.vertices))
        return tree.query(body_frame(points, pose), k=1)[0]


def mean_edge_length(vertices: np.ndarray, edges: np.ndarray) -> float:
    """Mean length of ``edges`` (e, 2) over ``vertices`` (n, d) [m]."""
    v = np.asarray(vertices, float)
    e = np.asarray(edges, int)
    return float(np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1).mean())


def build_imls(
    vertices,
    normals,
    *,
    sigma: float | None = None,
    spacing: float | None = None,
    cutoff_sigmas: float = DEFAULT_CUTOFF_SIGMAS,
    device: str = "cpu",
    weights=None,
    area: float | None = None,
) -> ImlsField:
    """Build the IMLS field of O from body-frame samples.

    Args:
        vertices: (n, dim) samples [m].
        normals: (n, dim) outward normals (normalized here).
        sigma: kernel width [m]; default ``spacing`` (O's mean edge length), or when that is None
            :func:`default_sigma` of the samples.
        spacing: the samples' spacing [m] (see ``sigma``).
        cutoff_sigmas: truncation radius in sigmas.
        device: Warp device.
        weights: (n,) sample weights (areas); default :func:`density_weights`.
        area: O's surface area [m^2] (3D), for the sign of points beyond the kernel radius
            (:meth:`ImlsField.inside`); 2D: the sample polygon's perimeter by default. Without it (3D)
            far points are reported outside.

    Returns:
        The :class:`ImlsField`.
    """
    v = np.asarray(vertices, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] not in (2, 3) or v.shape != n.shape or len(v) < 3:
        raise InputError(f"object samples must be (n, 2|3) with matching normals, got {v.shape} and {n.shape}")
    if not (np.isfinite(v).all() and np.isfinite(n).all()):
        raise InputError("object samples or normals contain non-finite values")
    nn = np.linalg.norm(n, axis=1)
    if (nn < 1e-12).any():
        raise InputError("object has zero-length vertex normals")
    n = n / nn[:, None]
    dim = v.shape[1]
    if sigma is None:
        sigma = float(spacing) if spacing is not None else default_sigma(v)
    if not (sigma > 0 and np.isfinite(sigma)):
        raise InputError(f"IMLS sigma must be positive, got {sigma}")
    radius = cutoff_sigmas * sigma
    v3 = _pad3(v)
    n3 = _pad3(n)
    wverts = wp.array(v3, dtype=wp.vec3d, device=device)
    cells = _cell_lists(v3, radius, sigma, dim, device)
    a = density_weights(v, sigma, radius) if weights is None else np.asarray(weights, float) / np.mean(weights)
    if area is None and dim == 2:  # the closed polygon through the samples
        area = float(np.linalg.norm(np.diff(np.vstack([v, v[:1]]), axis=0), axis=1).sum())
    # Far points: no sample within `radius`; O's surface lies within about half the largest sample
    # spacing of some sample, so the distance to it is at least radius - spacing (kept >= radius/2).
    far = max(0.5 * radius, radius - 2.0 * sigma)
    return ImlsField(
        vertices=v, normals=n, sigma=float(sigma), radius=float(radius), far_distance=float(far), dim=dim,
        device=device, _cells=cells, _wverts=wverts, _wnormals=wp.array(n3, dtype=wp.vec3d, device=device),
        _wweights=wp.array(a, dtype=wp.float64, device=device), weights=a, area=area,
    )


#: Samples count as uneven when their distances to the 6th nearest neighbour vary by more than
#: this coefficient of variation (random samples: 0.2, a UV sphere's vertices: 0.29; trimesh's
#: sample_surface_even: 0.12, an icosphere's vertices: 0.03).
UNEVEN_CV = 0.15
#: Kernel width of uneven samples in units of their mean spacing sqrt(area per sample): with it
#: the error stays within the sigma^2 / R bound of even samples (random samples of a sphere:
#: 0.87 of it; at 1x the spacing 2.1x, at the mean nearest-neighbour distance 5.9x).
UNEVEN_SIGMA_SPACINGS = 2.0


def default_sigma(v: np.ndarray) -> float:
    """Default kernel width [m] of samples v (n, dim): their mean nearest-neighbour distance when
    they are evenly spread, UNEVEN_SIGMA_SPACINGS mean spacings (sqrt of the area per sample,
    pi r_6^2 / 6 from the 6th neighbour distance r_6; 2D: r_2 / 2) when they are not (UNEVEN_CV)."""
    from scipy.spatial import cKDTree

    k = 7 if v.shape[1] == 3 else 3
    d, _ = cKDTree(v).query(v, k=min(k, len(v)))
    far = d[:, -1]
    if far.std() <= UNEVEN_CV * far.mean():
        return float(d[:, 1].mean())
    spacing = np.sqrt(np.pi * np.mean(far**2) / 6) if v.shape[1] == 3 else float(np.mean(far)) / 2
    return float(UNEVEN_SIGMA_SPACINGS * spacing)


def density_weights(v: np.ndarray, sigma: float, radius: float) -> np.ndarray:
    """(n,) sample weights a_i = 1 / sum_j exp(-|v_i - v_j|^2 / sigma^2) (j within ``radius``),
    normalized to mean 1: the share of the surface each sample stands for (module docstring)."""
    from scipy.spatial import cKDTree

    tree = cKDTree(_pad3(v))
    pairs = tree.query_pairs(radius, output_type="ndarray")
    rho = np.ones(len(v))
    if len(pairs):
        d2 = np.sum((v[pairs[:, 0]] - v[pairs[:, 1]]) ** 2, axis=1)
        k = np.exp(-d2 / sigma**2)
        rho += (np.bincount(pairs[:, 0], weights=k, minlength=len(v))
                + np.bincount(pairs[:, 1], weights=k, minlength=len(v)))
    a = 1.0 / rho
    return a / a.mean()


#: Cell grid of the neighbour lists: cell size in sigmas, and the largest number of cells (the
#: cell size grows beyond CELL_SIGMAS * sigma for an object that would need more).
CELL_SIGMAS = 1.0
MAX_CELLS = 1 << 24


@dataclass(frozen=True)
class _CellLists:
    """Neighbour lists on a uniform grid over O's sample box grown by the kernel radius: cell c
    lists (ascending) every sample within ``radius`` of some point of c, so a query point needs only
    its own cell's list (a few more than the samples within ``radius``, where a hash-grid query walks
    the 27 cells of size ``radius`` around the point; the figure: docs/decisions.md, "IMLS neighbour
    lists"). Built once per
    object; O moves rigidly."""

    origin: np.ndarray  # (3,) body-frame corner [m]
    size: float  # cell edge [m]
    shape: tuple  # cells per axis (3,)
    start: object  # wp.array (cells + 1,) int32 CSR offsets
    samples: object  # wp.array (pairs,) int32 sample indices

    def launch_args(self) -> list:
        return [wp.vec3d(*self.origin), 1.0 / self.size, wp.vec3i(*self.shape), self.start, self.samples]


def _cell_lists(v3: np.ndarray, radius: float, sigma: float, dim: int, device: str) -> _CellLists:
    """Build the :class:`_CellLists` of body-frame samples (n, 3) (2D objects: z = 0, one cell layer)."""
    lo, hi = v3.min(0) - radius, v3.max(0) + radius
    h = CELL_SIGMAS * sigma
    span = hi - lo
    if dim == 2:  # one layer of cells centred on z = 0
        span[2] = 0.0
    h = max(h, float(np.prod(np.maximum(span, 1e-300)[: dim]) / MAX_CELLS) ** (1.0 / dim))
    shape = np.maximum(1, np.ceil(span / h).astype(np.int64))
    origin = lo.copy()
    if dim == 2:
        shape[2], origin[2] = 1, -0.5 * h
    # every (sample, cell) pair among the cells around the sample's own cell whose box lies within
    # `radius` of the sample: the squared distance to a box is a sum of per-axis terms, so it is
    # built from (sample, axis, offset) gaps by broadcasting, in chunks of samples to bound memory
    m = int(np.ceil(radius / h)) + 1
    offs = [np.arange(-m, m + 1)] * 2 + [np.arange(-m, m + 1) if dim == 3 else np.zeros(1, np.int64)]
    own = np.floor((v3 - origin) / h).astype(np.int64)
    r2 = radius * radius
    cell_ids, sample_ids = [], []
    n_offs = int(np.prod([len(o) for o in offs]))
    chunk = max(1, 4_000_000 // n_offs)
    for a in range(0, len(v3), chunk):
        v = v3[a:a + chunk]
        cax, g2 = [], []
        for k in range(3):
            c = own[a:a + chunk, k, None] + offs[k]  # (s, R_k) cell index along axis k
            lo_k = origin[k] + c * h
            gap = np.maximum(0.0, np.maximum(lo_k - v[:, k, None], v[:, k, None] - (lo_k + h)))
            cax.append(c)
            g2.append(np.where((c >= 0) & (c < shape[k]), gap * gap, np.inf))
        d2 = g2[0][:, :, None, None] + g2[1][:, None, :, None] + g2[2][:, None, None, :]
        si, ix, iy, iz = np.nonzero(d2 < r2)
        cell_ids.append((cax[0][si, ix] * shape[1] + cax[1][si, iy]) * shape[2] + cax[2][si, iz])
        sample_ids.append(si + a)
    cell_ids = np.concatenate(cell_ids)
    sample_ids = np.concatenate(sample_ids)
    order = np.argsort(cell_ids, kind="stable")  # pairs come by ascending sample: lists stay ascending
    start = np.zeros(int(np.prod(shape)) + 1, dtype=np.int64)
    np.cumsum(np.bincount(cell_ids, minlength=int(np.prod(shape))), out=start[1:])
    return _CellLists(origin=origin, size=float(h), shape=tuple(int(k) for k in shape),
                      start=wp.array(start.astype(np.int32), dtype=wp.int32, device=device),
                      samples=wp.array(sample_ids[order].astype(np.int32), dtype=wp.int32, device=device))


_EYE3_BYTES = np.eye(3).tobytes()


def unrotated(R: np.ndarray) -> bool:
    """Whether the (3, 3) float64 rotation R is exactly the identity (a byte comparison: this runs
    on every field evaluation, where np.array_equal costs several microseconds)."""
    return R.tobytes() == _EYE3_BYTES


def body_frame(points, pose=None) -> np.ndarray:
    """World points (..., dim) in O's body frame (..., 3): R^T (x - p) for O's ``pose`` (as in
    :func:`simfab.rotations.pose_matrix`); 2D points get z = 0."""
    R, p = pose_matrix(pose)
    pts = np.asarray(points, dtype=np.float64)
    body = _pad3(pts.reshape(-1, pts.shape[-1])) - p
    if not unrotated(R):  # (an unrotated O: nothing to rotate)
        body = body @ R
    return body.reshape(pts.shape[:-1] + (3,))


def evaluate_imls(fld: ImlsField, points, pose=None, *, hessian: bool = True,
                  hessian_band: float | None = None) -> ImlsEval:
    """Evaluate the IMLS field at world points in one Warp launch.

    Args:
        points: (k, dim) world positions [m]
    pose   : O's pose, world x = R x_body + p: None, (R (3,3), p (3,)) or (pos (3,), quat_wxyz (4,))
    hessian : compute Hessians; ``hessian_band`` [m] limits them to points with psi > -hessian_band
        (others get zeros), which is all a barrier with activation distance d_hat needs.
    Returns :class:`ImlsEval` with world-frame gradient and Hessian.
    """
    q = _prepare(fld, points, pose, hessian, hessian_band)
    m = len(q.body)
    if m == 0:
        return _finish(q, (np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0, np.int32)))
    if m >= PARALLEL_MIN_POINTS and wp.get_device(fld.device).is_cpu:
        # two single-threaded launches on two threads, each with its own buffers
        half = m // 2
        second = submit(_launch, fld, q.body[half:], q.band)
        parts = [_launch(fld, q.body[:half], q.band), second.result()]
        out = _finish(q, tuple(np.concatenate(a) for a in zip(*parts)))
    else:
        out = _finish(q, _launch(fld, q.body, q.band))
    far = ~out.near
    if far.any() and fld.area is not None:  # beyond the kernel: the side from the winding number
        inside = fld.inside(q.body[far][:, : fld.dim])
        out.psi[np.flatnonzero(far)[inside]] = fld.far_distance
    return out


@dataclass(frozen=True)
class _Query:
    """An evaluation prepared for launch: ``body`` (k, 3) body-frame query points, ``R`` O's
    rotation (None: identity, nothing to rotate back), ``band`` the Hessian band (-inf: no Hessian)."""

    dim: int
    R: np.ndarray | None
    body: np.ndarray
    band: float

    @property
    def hessian(self) -> bool:
        return self.band > -np.inf


def _prepare(fld: ImlsField, points, pose, hessian: bool, hessian_band: float | None) -> _Query:
    """The :class:`_Query` of world points (k, dim). Points far from O need no culling here: outside
    the cell grid the kernel finds no neighbour at once."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, fld.dim)
    R, p = pose_matrix(pose)
    body = body_frame(pts, (R, p))
    R = None if unrotated(R) else R
    band = -np.inf if not hessian else (np.inf if hessian_band is None else float(hessian_band))
    return _Query(dim=fld.dim, R=R, body=body, band=band)


def _finish(q: _Query, launched) -> ImlsEval:
    """World-frame :class:`ImlsEval` from the launch's body-frame results (copies, see _launch)."""
    v_psi, v_grad, v_hess, v_count = launched
    dim = q.dim
    Rd = None if q.R is None else q.R[:dim, :dim]
    grad = v_grad[:, :dim] if Rd is None else v_grad[:, :dim] @ Rd.T
    if q.hessian:
        hess = v_hess[:, :dim, :dim] if Rd is None else Rd @ v_hess[:, :dim, :dim] @ Rd.T
        hess = np.ascontiguousarray(hess)
    else:
        hess = np.zeros((len(v_psi), dim, dim))
    return ImlsEval(psi=v_psi, grad=np.ascontiguousarray(grad), hess=hess, near=v_count > 0)


def _launch(fld: ImlsField, body: np.ndarray, band: float):
    """One launch at body-frame points (m, 3) with the calling thread's buffers; returns
    (psi (m,), grad (m, 3), hess (m, 3, 3), count (m,)) as copies.

    Buffer sets come in power-of-two capacities, each with its launch recorded once over its whole
    capacity; the point count and the Hessian band are written into one-element arrays the kernel
    reads, so a launch re-binds nothing (setting the launch size and a parameter cost ~60 us in
    Python, more than the launch itself at a few hundred points)."""
    m = len(body)
    buf = _buffers(fld, m)
    views = buf["views"]  # zero-copy NumPy views of the (CPU) Warp buffers
    if views is not None:
        views["points"][:m] = body
        views["n_points"][0] = m
        views["hess_band"][0] = band
    else:
        buf["points"].assign(np.ascontiguousarray(np.pad(body, ((0, buf["capacity"] - m), (0, 0)))))
        buf["n_points"].assign(np.array([m], dtype=np.int32))
        buf["hess_band"].assign(np.array([band]))
    cmd = buf.get("cmd")
    if cmd is None:  # recorded once per buffer set and replayed (a plain launch re-packs every argument)
        with RECORD_LOCK:
            cmd = buf["cmd"] = wp.launch(
                _imls_eval, dim=buf["capacity"], device=fld.device,
                inputs=[*fld._cells.launch_args(), fld._wverts, fld._wnormals, fld._wweights, 1.0 / fld.sigma**2,
                        fld.radius,
                        -fld.far_distance, buf["points"], buf["n_points"], buf["hess_band"]],
                outputs=[buf["psi"], buf["grad"], buf["hess"], buf["count"]],
                record_cmd=True,
            )
    cmd.launch()
    v = views if views is not None else {k: buf[k].numpy() for k in ("psi", "grad", "hess", "count")}
    hess = v["hess"][:m].copy() if band > -np.inf else v["hess"][:m]  # unread without Hessians
    return v["psi"][:m].copy(), v["grad"][:m].copy(), hess, v["count"][:m].copy()


def _buffers(fld: ImlsField, k: int) -> dict:
    """Reusable Warp work arrays of the calling thread for k query points: one set per power-of-two
    capacity (at least 64) and thread, since evaluations may run concurrently. On the CPU, NumPy
    views of them are kept so that filling and reading cost no copy (results are copied out before
    the next launch of the same thread)."""
    cap = max(64, 1 << (k - 1).bit_length())
    key = ("work", threading.get_ident(), cap)
    b = fld._buffers.get(key)
    if b is None:
        dev = fld.device
        b = {
            "capacity": cap,
            "points": wp.zeros(cap, dtype=wp.vec3d, device=dev),
            "n_points": wp.zeros(1, dtype=wp.int32, device=dev),
            "hess_band": wp.zeros(1, dtype=wp.float64, device=dev),
            "psi": wp.zeros(cap, dtype=wp.float64, device=dev),
            "grad": wp.zeros(cap, dtype=wp.vec3d, device=dev),
            "hess": wp.zeros(cap, dtype=wp.mat33d, device=dev),
            "count": wp.zeros(cap, dtype=wp.int32, device=dev),
        }
        is_cpu = wp.get_device(dev).is_cpu
        names = ("points", "n_points", "hess_band", "psi", "grad", "hess", "count")
        b["views"] = {k2: b[k2].numpy() for k2 in names} if is_cpu else None
        fld._buffers[key] = b
    return b


def _pad3(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.shape[1] == 3:
        return np.ascontiguousarray(a)
    out = np.zeros((len(a), 3))
    out[:, : a.shape[1]] = a
    return out


def imls_reference(points, vertices, normals, sigma: float, radius: float | None = None, weights=None):
    """Brute-force NumPy IMLS value and gradient (for tests): psi (k,), grad (k, dim).

    Same formula as the Warp kernel; no neighbour lists; ``radius`` truncates the kernel when given;
    ``weights`` (n,) the sample weights (default 1).
    """
    x = np.asarray(points, float)[:, None, :]
    v = np.asarray(vertices, float)[None]
    n = np.asarray(normals, float)
    n = (n / np.linalg.norm(n, axis=1, keepdims=True))[None]
    r = x - v
    rr = (r**2).sum(-1)
    phi = np.exp(-rr / sigma**2) * (1.0 if weights is None else np.asarray(weights, float)[None])
    if radius is not None:
        phi = np.where(rr < radius**2, phi, 0.0)
    nr = (n * r).sum(-1)
    D = phi.sum(1)
    N = (nr * phi).sum(1)
    dphi = -2.0 / sigma**2 * phi[..., None] * r
    gD = dphi.sum(1)
    gN = (phi[..., None] * n + nr[..., None] * dphi).sum(1)
    with np.errstate(invalid="ignore", divide="ignore"):  # D = 0 only for truncated far points
        f = N / D
        gf = (gN - f[:, None] * gD) / D[:, None]
    return -f, -gf


def curve_normals(points: np.ndarray, closed: bool = True) -> np.ndarray:
    """Unit outward vertex normals of a 2D polyline ordered counter-clockwise (n, 2).

    For a CCW closed curve the outward normal of edge (a, b) is (t_y, -t_x); vertex normals average
    the two adjacent edge normals.
    """
    p = np.asarray(points, float)
    nxt = np.roll(p, -1, axis=0)
    t = nxt - p
    en = np.stack([t[:, 1], -t[:, 0]], axis=1)
    en /= np.linalg.norm(en, axis=1, keepdims=True)
    if not closed:
        en[-1] = en[-2]
    vn = en + np.roll(en, 1, axis=0)
    if not closed:
        vn[0] = en[0]
    return vn / np.linalg.norm(vn, axis=1, keepdims=True)
