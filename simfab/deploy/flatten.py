"""Boundary First Flattening (Sawhney & Crane 2017) with zero (or prescribed) boundary scale factors.

A disk-topology mesh V (n,3) [m], F (m,3) is flattened to (n,2) [m] with a metric conformal to its
own, g_flat = e^{2u} g, u = 0 on the boundary (the flattening of least area distortion) or the
``u_boundary`` given (the cone metric of a cut mesh, :mod:`simfab.deploy.cuts`). With A the cotan
Laplacian, Omega the interior angle defects and k the boundary geodesic curvatures
(:func:`flatten`, one Cholesky factor of A_II for every solve):

1. A_II u_I = -Omega_I (a flat metric; u <= 0 where the surface is positively curved);
2. k~_B = k_B + A_BI u_I (the target boundary curvature);
3. the boundary curve from the edge lengths e^{(u_i+u_j)/2} l_ij and tangent angles sum k~, closed
   by the least-squares angle correction (``closure_angle_correction`` [rad]);
4. the interior: harmonic extension A_II x_I = -A_IB x_B.

Outputs: u per vertex and the area distortion sigma_f = 1/2 log(area_flat / area_3d) per face.
The discrete quantities in full: docs/methods.md, "simfab.deploy.flatten".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from simfab.errors import ConvergenceError, InputError
from simfab.solve.linear import import_cholmod


@dataclass(frozen=True)
class Flattening:
    """Result of :func:`flatten`.

    Args:
        uv: (n,2) [m] flat positions.
        u: (n,) [-] log scale factor (0 on the boundary, or the prescribed values).
        sigma: (m,) [-] per-face log area-scale factor 1/2 log(A_flat / A_3d).
        boundary: (b,) ordered boundary loop (counter-clockwise in the plane).
        interior: (n-b,) the interior vertices.
        closure_angle_correction: largest tangent-angle change that closed the boundary [rad].
        seconds: wall time per step {assemble, factor, solve, boundary} [s].
    """

    uv: np.ndarray
    u: np.ndarray
    sigma: np.ndarray
    boundary: np.ndarray
    interior: np.ndarray
    closure_angle_correction: float
    seconds: dict


def corner_angles(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Interior angle of each face at each of its corners.

    Args:
        V: (n,3) [m] vertices.
        F: (m,3) faces.

    Returns:
        (m,3) [rad].
    """
    P = V[F]  # (m,3,3)
    out = np.empty(F.shape)
    for k in range(3):
        a = P[:, (k + 1) % 3] - P[:, k]
        b = P[:, (k + 2) % 3] - P[:, k]
        c = np.linalg.norm(np.cross(a, b), axis=1) if V.shape[1] == 3 else np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
        out[:, k] = np.arctan2(c, np.einsum("ij,ij->i", a, b))
    return out


def cotan_laplacian(V: np.ndarray, F: np.ndarray, angles: np.ndarray | None = None) -> sp.csr_matrix:
    """Positive semi-definite cotan Laplacian: ``A_ij = -(cot a_ij + cot b_ij)/2``, ``A_ii = -sum_j A_ij``.

    Args:
        V: (n,3) [m] vertices.
        F: (m,3) faces.
        angles: their :func:`corner_angles` (None: computed).

    Returns:
        A (n,n) [-], CSR.
    """
    n = len(V)
    ang = corner_angles(V, F) if angles is None else angles
    cot = 1.0 / np.tan(ang)
    # the angle at corner k is opposite the edge (k+1, k+2)
    i = np.concatenate([F[:, 1], F[:, 2], F[:, 0]])
    j = np.concatenate([F[:, 2], F[:, 0], F[:, 1]])
    w = 0.5 * np.concatenate([cot[:, 0], cot[:, 1], cot[:, 2]])
    W = sp.coo_matrix((np.concatenate([w, w]), (np.concatenate([i, j]), np.concatenate([j, i]))), shape=(n, n)).tocsr()
    return (sp.diags(np.asarray(W.sum(axis=1)).ravel()) - W).tocsr()


def boundary_loop(F: np.ndarray, n: int) -> np.ndarray:
    """The ordered boundary loop of a disk-topology mesh, following the face winding.

    Args:
        F: (m,3) faces.
        n: the vertex count.

    Returns:
        (b,) vertex ids; InputError unless the boundary is exactly one simple loop.
    """
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    key = np.minimum(e[:, 0], e[:, 1]) * np.int64(n) + np.maximum(e[:, 0], e[:, 1])
    uniq, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
    if np.any(cnt > 2):
        raise InputError(f"mesh is not manifold: {int(np.sum(cnt > 2))} edges are shared by more than two faces")
    be = e[cnt[inv] == 1]
    if len(be) == 0:
        raise InputError("mesh has no boundary (a closed surface cannot be flattened without cuts)")
    nxt = np.full(n, -1, dtype=np.int64)
    if len(np.unique(be[:, 0])) != len(be):
        raise InputError("mesh boundary is not a simple loop (a boundary vertex is visited twice)")
    nxt[be[:, 0]] = be[:, 1]
    loop = [int(be[0, 0])]
    while True:
        v = int(nxt[loop[-1]])
        if v < 0:
            raise InputError("mesh boundary is not closed")
        if v == loop[0]:
            break
        loop.append(v)
        if len(loop) > len(be):
            raise InputError("mesh boundary is not a simple loop")
    if len(loop) != len(be):
        raise InputError(f"mesh has {len(be) - len(loop)} boundary edges outside the first boundary loop "
                         "(more than one boundary loop: not a disk)")
    return np.asarray(loop)


def _close_polygon(lengths: np.ndarray, phi: np.ndarray, *, tol: float = 1e-14, max_iter: int = 20):
    """Minimum-norm tangent-angle correction so that ``sum l_i (cos phi_i, sin phi_i) = 0``."""
    phi = phi.copy()
    total = float(np.sum(lengths))
    for _ in range(max_iter):
        c, s = np.cos(phi), np.sin(phi)
        r = np.array([lengths @ c, lengths @ s])
        if np.linalg.norm(r) <= tol * total:
            return phi
        J = np.stack([-lengths * s, lengths * c])  # (2, b)
        phi -= J.T @ np.linalg.solve(J @ J.T, r)
    raise ConvergenceError("BFF: boundary polygon did not close "
                           f"(residual {np.linalg.norm(r) / total:.2e} of its length)")


def flatten(V, F, *, u_boundary=None) -> Flattening:
    """Boundary First Flattening with u = 0 on the boundary (see the module doc).

    With ``u_boundary`` (BFF's Dirichlet case; :mod:`simfab.deploy.cuts` passes the cone metric's u
    along the cut sides), step 1 solves ``A_II u_I = -Omega_I - A_IB u_B``, step 2 adds ``A_BB u_B``
    to the boundary curvature, and step 3 uses the lengths ``l~ = e^{(u_i+u_j)/2} l``.

    Args:
        V: (n,3) [m] vertices of a disk-topology mesh.
        F: (m,3) faces.
        u_boundary: (n,) [-] prescribed scale factors, read at the boundary vertices (None: 0).

    Returns:
        The :class:`Flattening`.
    """
    import time

    t0 = time.perf_counter()
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    n = len(V)
    loop = boundary_loop(F, n)
    is_b = np.zeros(n, dtype=bool)
    is_b[loop] = True
    interior = np.flatnonzero(~is_b)
    ang = corner_angles(V, F)
    A = cotan_laplacian(V, F, ang)
    angle_sum = np.bincount(F.ravel(), weights=ang.ravel(), minlength=n)
    omega = 2.0 * np.pi - angle_sum[interior]
    kgeo = np.pi - angle_sum[loop]
    A_I = A[interior]  # rows once; A is symmetric, so A_BI = A_IB^T
    A_II = A_I[:, interior]
    A_IB = A_I[:, loop].tocsr()
    t1 = time.perf_counter()
    solver = CholeskyFactor(A_II) if len(interior) else None
    # 1. flat metric, u_B given (0 by default):  A_II u_I = -Omega_I - A_IB u_B
    u = np.zeros(n)
    if u_boundary is not None:
        u[loop] = np.asarray(u_boundary, dtype=np.float64)[loop]
    uB = u[loop]
    if len(interior):
        u[interior] = solver.solve(-omega - A_IB @ uB)
    t2 = time.perf_counter()
    # 2. Dirichlet-to-Neumann: boundary curvature of the flat metric, k~ = k + A_BI u_I + A_BB u_B
    k_new = kgeo + (A_IB.T @ u[interior] if len(interior) else 0.0) + A[loop][:, loop] @ uB
    # 3. boundary polygon with the scaled lengths (u_B = 0: the original ones), closed by the smallest
    # angle change
    Vb = V[loop]
    lengths = np.linalg.norm(np.roll(Vb, -1, axis=0) - Vb, axis=1)  # edge loop[i] -> loop[i+1]
    lengths = lengths * np.exp(0.5 * (uB + np.roll(uB, -1)))
    phi0 = np.cumsum(k_new)  # tangent of edge i turns by k~ at its start vertex
    phi = _close_polygon(lengths, phi0)
    corr = float(np.max(np.abs(phi - phi0)))
    xb = np.concatenate([[0.0], np.cumsum(lengths * np.cos(phi))[:-1]])
    yb = np.concatenate([[0.0], np.cumsum(lengths * np.sin(phi))[:-1]])
    uv = np.zeros((n, 2))
    uv[loop, 0], uv[loop, 1] = xb, yb
    t3 = time.perf_counter()
    # 4. harmonic extension (same factor)
    if len(interior):
        uv[interior] = solver.solve(-(A_IB @ uv[loop]))
    t4 = time.perf_counter()
    uv -= 0.5 * (uv.min(axis=0) + uv.max(axis=0))
    sigma = 0.5 * np.log(_areas(uv, F) / _areas(V, F))
    if not (np.all(np.isfinite(uv)) and np.all(np.isfinite(sigma))):
        raise ConvergenceError("BFF: the flat map is not finite (degenerate input triangles?)")
    return Flattening(uv=uv, u=u, sigma=sigma, boundary=loop, interior=interior, closure_angle_correction=corr,
                      seconds=dict(assemble=t1 - t0, factor_and_solve_u=t2 - t1, boundary=t3 - t2, extend=t4 - t3))


class CholeskyFactor:
    """Sparse Cholesky factor of an SPD matrix (CHOLMOD through cvxopt), computed once and reused for any
    number of right-hand sides (the fill-reducing ordering is CHOLMOD's default).

    Args:
        A: the SPD matrix (n,n).
    """

    def __init__(self, A: sp.spmatrix):

        cholmod = import_cholmod()  # (with the machine's BLAS kernels)
        import cvxopt

        L = sp.tril(A, format="coo")
        self.n = A.shape[0]
        M = cvxopt.spmatrix(cvxopt.matrix(L.data.astype(np.float64)), cvxopt.matrix(L.row.astype(np.int64)),
                            cvxopt.matrix(L.col.astype(np.int64)), (self.n, self.n))
        cholmod.options["supernodal"] = 2
        try:
            self._F = cholmod.symbolic(M)
            cholmod.numeric(M, self._F)
        except ArithmeticError:
            raise ConvergenceError("BFF: the cotan Laplacian is not positive definite "
                                   "(obtuse/degenerate triangles; remesh the target)") from None

    def solve(self, b: np.ndarray) -> np.ndarray:
        """Solve A x = b.

        Args:
            b: (n,) or (n,k).

        Returns:
            x, shaped as b.
        """
        import cvxopt
        import cvxopt.cholmod as cholmod

        b = np.asarray(b, dtype=np.float64)
        x = cvxopt.matrix(np.ascontiguousarray(b.reshape(self.n, -1)))
        cholmod.solve(self._F, x)
        return np.array(x).reshape(b.shape)


def _areas(P, F) -> np.ndarray:
    a = P[F[:, 1]] - P[F[:, 0]]
    b = P[F[:, 2]] - P[F[:, 0]]
    if P.shape[1] == 2:
        return 0.5 * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
    return 0.5 * np.linalg.norm(np.cross(a, b), axis=1)


def face_areas(P, F) -> np.ndarray:
    """Triangle areas.

    Args:
        P: (n,3) or (n,2) [m] vertices.
        F: (m,3) faces.

    Returns:
        (m,) [m^2]; signed (positive counter-clockwise) for 2D points.
    """
    return _areas(np.asarray(P, dtype=np.float64), np.asarray(F))
