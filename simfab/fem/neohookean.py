"""Compressible Neo-Hookean elasticity on linear simplices: energy, gradient, Hessian side by side.

Per element (volume V, Lame parameters mu, lam, dimension d):

    Psi(F) = mu/2 (||F||_F^2 - d) - mu log J + lam/2 (log J)^2,      E_e = V Psi(F),  J = det F
    F = Ds Dm^-1,  Ds = [x1 - x0, x2 - x0(, x3 - x0)]

2D is plane strain: the body is extruded by ``model.thickness`` with F_zz = 1, for which the 3D
energy density equals the d = 2 formula above (||F||^2 - 3 = ||F_2D||^2 - 2, det F = det F_2D);
V = area * thickness.

First Piola-Kirchhoff stress (dPsi/dF):

    P = mu (F - F^-T) + lam log J F^-T

Nodal gradient: dE/dx_i = V P Dm^-T e_i (i = 1..d), dE/dx_0 = -sum_i dE/dx_i. Sign: the gradient
is the internal force with the sign of the energy increase; the elastic force on the nodes is
``-gradient``.

Hessian d2Psi/dF2 via its analytic eigensystem (Smith, De Goes, Kim 2019, "Analytic eigensystems
for isotropic distortion energies"). With the SVD F = U diag(s) V^T (J > 0, so det U det V = 1) and
dPsi/dJ = (lam log J - mu) / J:

    twist modes  U T_k V^T:  eigenvalue mu + dPsi/dJ * s_k      (3D; 2D: mu + dPsi/dJ)
    flip modes   U L_k V^T:  eigenvalue mu - dPsi/dJ * s_k      (3D; 2D: mu - dPsi/dJ)
    scaling modes U diag(q) V^T: q, eigenvalue of the d x d matrix
        A_ii = mu + (mu + lam (1 - log J)) / s_i^2,   A_ij = lam / (s_i s_j)

(T_k skew and L_k symmetric unit off-diagonal pairs in the plane orthogonal to axis k; the
twist/flip values come from the mu ||F||^2 term (2 * mu/2 * I) plus dPsi/dJ times the Hessian of
det F, whose eigenvalues on those modes are +-s_k.) The PSD projection clamps negative
eigenvalues to zero in this d^2-dimensional stress space, which makes the element block PSD.

3D evaluation (measured ~2x faster than the SVD route, no eigensolver in the common case): when
dPsi/dJ <= 0 (lam log J <= mu - all but strong volumetric expansion) the flip and scaling
eigenvalues are provably positive, so only the 3-dimensional twist block can be indefinite. That
block is T = mu I + dPsi/dJ S in the basis R [e_i]x / sqrt 2, with F = R S the polar decomposition
(cheap Newton iteration instead of an SVD). The kernel assembles the exact Hessian directly
(mu I + d2Psi/dJ2 g g^T + dPsi/dJ d2J/dF2, g = cof F) and subtracts the negative part of T, whose
spectral projectors come from closed-form eigenvalues (accurate also for clustered eigenvalues).
With dPsi/dJ > 0 the full SVD eigensystem is used. 2D works the same way with its single twist
mode (polar rotation in closed form).
With ``project_psd=False`` the exact Hessian is returned (validated against finite differences;
the two projected routes agree to round-off, also checked against numpy ``eigh`` in the tests).
Batched numpy ``eigh`` of the 12x12 element blocks instead was ~10x slower than the whole kernel
(``python -m simfab.fem.benchmark``).

All kernels run in float64, one launch per call for all elements (energy, gradient and Hessian
blocks in the same kernel when the Hessian is wanted); the Hessian kernel adds its values straight
into the CSR ``data`` of the model's fixed pattern through precomputed slots. Warp CPU kernels
run single-threaded, so results are bit-reproducible there; on CUDA the additions are atomic and
their order (hence the last bits) can vary between runs.

An element with det F <= 0 makes the energy +inf (the log barrier of Neo-Hookean); such an
element contributes nothing to the gradient and Hessian, which are then not meaningful.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from simfab._warp import RECORD_LOCK, wp
from simfab.fem import tolerances
from simfab.fem.model import FemModel

wp.set_module_options({"enable_backward": False})  # hand-written derivatives; halves compile time

_vec6d = wp.types.vector(length=6, dtype=wp.float64)
_vec12d = wp.types.vector(length=12, dtype=wp.float64)
_vec4d = wp.types.vector(length=4, dtype=wp.float64)
_vec9d = wp.types.vector(length=9, dtype=wp.float64)
_mat4x6d = wp.types.matrix(shape=(4, 6), dtype=wp.float64)
_mat9x12d = wp.types.matrix(shape=(9, 12), dtype=wp.float64)

_HALF_SQRT2 = 0.7071067811865476  # 1/sqrt(2): unit Frobenius norm of the twist/flip modes
# Hessian kernel modes: exact; PSD-projected (direct route where valid, else SVD); PSD-projected
# always through the SVD eigensystem (reference route for tests and the benchmark)
_EXACT = wp.constant(0)
_PROJECT = wp.constant(1)
_PROJECT_SVD = wp.constant(2)
_BOTH = wp.constant(3)  # exact into ``data`` and PSD-projected (default route) into ``data2``
_POLAR_STEP_SQ_TOL = wp.constant(wp.float64(tolerances.POLAR_STEP_SQ_TOL))
_POLAR_MAX_ITER = wp.constant(tolerances.POLAR_MAX_ITER)


@wp.func
def _clamp(lam: wp.float64, project: int):
    if project != 0 and lam < wp.float64(0.0):
        return wp.float64(0.0)
    return lam


@wp.func
def _store(scatter: int, slots: wp.array3d(dtype=wp.int32), hess: wp.array3d(dtype=wp.float64),
           data: wp.array(dtype=wp.float64), e: int, r: int, c: int, val: wp.float64):
    """Symmetric entry (r, c) and (c, r) of element e's Hessian block: added straight into the CSR
    values through the precomputed slots (scatter != 0), or stored in the (m, k, k) block array."""
    if scatter != 0:
        wp.atomic_add(data, slots[e, r, c], val)
        if c != r:
            wp.atomic_add(data, slots[e, c, r], val)
    else:
        hess[e, r, c] = val
        hess[e, c, r] = val


@wp.func
def _psi(F: Any, J: wp.float64, mu: wp.float64, lam: wp.float64, d: wp.float64):
    """Neo-Hookean energy density [Pa] (J > 0)."""
    logJ = wp.log(J)
    return wp.float64(0.5) * mu * (wp.ddot(F, F) - d) - mu * logJ + wp.float64(0.5) * lam * logJ * logJ


@wp.func
def _pk1(F: Any, J: wp.float64, mu: wp.float64, lam: wp.float64):
    """First Piola-Kirchhoff stress P = mu (F - F^-T) + lam log J F^-T [Pa]."""
    FinvT = wp.transpose(wp.inverse(F))
    return mu * (F - FinvT) + lam * wp.log(J) * FinvT


@wp.func
def _mode(U: Any, M: Any, V: Any, Dmi: Any):
    """Nodal vector of the stress-space mode U M V^T (2D or 3D through the ``_nodal`` overloads)."""
    return _nodal(U * M * wp.transpose(V), Dmi)


# ----------------------------------------------------------------------------------------------
# 3D
# ----------------------------------------------------------------------------------------------
@wp.func
def _F(x: wp.array(dtype=wp.vec3d), elements: wp.array2d(dtype=wp.int32), Dm_inv: wp.array(dtype=wp.mat33d), e: int):
    x0 = x[elements[e, 0]]
    Ds = wp.matrix_from_cols(x[elements[e, 1]] - x0, x[elements[e, 2]] - x0, x[elements[e, 3]] - x0)
    return Ds * Dm_inv[e]


@wp.func
def _nodal(M: wp.mat33d, Dmi: wp.mat33d):
    """b = (dF/dx)^T : M as a 12-vector ordered (vertex, axis): columns of M Dm^-T, vertex 0 = -sum."""
    W = M * wp.transpose(Dmi)
    b = _vec12d()
    for a in range(3):
        b[3 + a] = W[a, 0]
        b[6 + a] = W[a, 1]
        b[9 + a] = W[a, 2]
        b[a] = -(W[a, 0] + W[a, 1] + W[a, 2])
    return b


@wp.func
def _store_block3(scatter: int, slots: wp.array3d(dtype=wp.int32), hess: wp.array3d(dtype=wp.float64),
                  data: wp.array(dtype=wp.float64), e: int, l: int, lp: int, K: wp.mat33d):
    """Block (l, lp) of element e's 12x12 Hessian (and its transpose at (lp, l) when l != lp)."""
    for a in range(3):
        for b in range(3):
            if l != lp or b >= a:
                _store(scatter, slots, hess, data, e, 3 * l + a, 3 * lp + b, K[a, b])


@wp.func
def _store_all3(scatter: int, slots: wp.array3d(dtype=wp.int32), hess: wp.array3d(dtype=wp.float64),
                data: wp.array(dtype=wp.float64), e: int, K11: wp.mat33d, K22: wp.mat33d, K33: wp.mat33d,
                K12: wp.mat33d, K23: wp.mat33d, K13: wp.mat33d):
    """Store a 12x12 element Hessian given its vertex 1..3 blocks (vertex 0 = minus their sums)."""
    K21 = wp.transpose(K12)
    K32 = wp.transpose(K23)
    K31 = wp.transpose(K13)
    K01 = -(K11 + K21 + K31)
    K02 = -(K12 + K22 + K32)
    K03 = -(K13 + K23 + K33)
    K00 = -(K01 + K02 + K03)
    _store_block3(scatter, slots, hess, data, e, 0, 0, K00)
    _store_block3(scatter, slots, hess, data, e, 0, 1, K01)
    _store_block3(scatter, slots, hess, data, e, 0, 2, K02)
    _store_block3(scatter, slots, hess, data, e, 0, 3, K03)
    _store_block3(scatter, slots, hess, data, e, 1, 1, K11)
    _store_block3(scatter, slots, hess, data, e, 1, 2, K12)
    _store_block3(scatter, slots, hess, data, e, 1, 3, K13)
    _store_block3(scatter, slots, hess, data, e, 2, 2, K22)
    _store_block3(scatter, slots, hess, data, e, 2, 3, K23)
    _store_block3(scatter, slots, hess, data, e, 3, 3, K33)


@wp.func
def _negative_part_sym3(T: wp.mat33d):
    """Negative part sum_{t_k < 0} t_k v_k v_k^T of a symmetric 3x3 matrix, from its eigenvalues only.

    Eigenvalues in closed form (trigonometric Cardano). The spectral projector of the isolated sign
    group comes from the Lagrange/Sylvester formula, e.g. v v^T = (T - t2 I)(T - t3 I) / ((t1 - t2)
    (t1 - t3)). The eigenvalue factor in front is never larger than the smallest denominator gap
    across the sign change, so the absolute error stays O(eps ||T||) even for clustered eigenvalues
    (where eigenvector-based formulas break down).
    """
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    I = wp.identity(n=3, dtype=wp.float64)
    m = wp.trace(T) / wp.float64(3.0)
    K = T - m * I
    p = wp.ddot(K, K) / wp.float64(6.0)
    t_max = m
    t_min = m
    t_mid = m
    if p > zero:
        sp_ = wp.sqrt(p)
        r = wp.determinant(K / sp_) * wp.float64(0.5)
        r = wp.clamp(r, -one, one)
        phi = wp.acos(r) / wp.float64(3.0)
        t_max = m + wp.float64(2.0) * sp_ * wp.cos(phi)
        t_min = m + wp.float64(2.0) * sp_ * wp.cos(phi + wp.float64(2.0943951023931957))  # + 2 pi / 3
        t_mid = wp.float64(3.0) * m - t_max - t_min
    N = wp.mat33d()
    if t_min >= zero:
        return N
    if t_max < zero:
        return T
    if t_mid < zero:  # two negative: T minus the positive part t_max P_max
        return T - t_max * (T - t_min * I) * (T - t_mid * I) / ((t_max - t_min) * (t_max - t_mid))
    return t_min * (T - t_mid * I) * (T - t_max * I) / ((t_min - t_mid) * (t_min - t_max))


@wp.func
def _polar_rotation3(F: wp.mat33d):
    """Rotation R of the polar decomposition F = R S (det F > 0), by scaled Newton iteration
    X <- (g X + X^-T / g) / 2 (Higham), quadratically convergent."""
    X = F
    for it in range(_POLAR_MAX_ITER):
        Xi = wp.inverse(X)
        g = wp.sqrt(wp.sqrt(wp.ddot(Xi, Xi) / wp.ddot(X, X)))
        Xn = wp.float64(0.5) * (g * X + wp.transpose(Xi) / g)
        dX = Xn - X
        X = Xn
        if wp.ddot(dX, dX) <= _POLAR_STEP_SQ_TOL:
            break
    return X


@wp.func
def _hessian_direct(x: wp.array(dtype=wp.vec3d), elements: wp.array2d(dtype=wp.int32), e: int, F: wp.mat33d,
                    J: wp.float64, Dmi: wp.mat33d, V: wp.float64, mu: wp.float64, lam: wp.float64,
                    dPsi_dJ: wp.float64, project: int, both: int, scatter: int, slots: wp.array3d(dtype=wp.int32),
                    hess: wp.array3d(dtype=wp.float64), data: wp.array(dtype=wp.float64),
                    data2: wp.array(dtype=wp.float64)):
    """Element Hessian without an SVD, exact, plus the PSD projection of its twist block.

    d2Psi/dF2 = mu I + d2Psi/dJ2 g g^T + dPsi/dJ d2J/dF2 with g = dJ/dF = cof F. Mapped to the
    vertices (blocks for vertices 1..3, vertex 0 = minus the sum):
      mu term: mu (Dm^-1 Dm^-T)[l, l'] I;  g term: gamma_l gamma_l'^T, gamma_l = g Dm^-T e_l;
      det term: J = det(Ds) det(Dm^-1) with det(Ds) = e1 . (e2 x e3) trilinear in the deformed
      edges, so d2 det(Ds)/de_i de_j = -[e_k]x for (i, j, k) cyclic (transpose for anticyclic).
    Projection (only when dPsi/dJ <= 0, the caller's condition): the flip and scaling eigenvalues
    are then positive (see the module docstring), and only the twist block can be indefinite. In
    the orthonormal twist basis R [e_i]x / sqrt 2 (R the polar rotation of F) that block is
    T = mu I + dPsi/dJ S with S = R^T F, so the projected Hessian is the exact one minus
    Q N Q^T, N = negative part of T; mapped to vertex l: (R [e_i]x / sqrt2) d_l = -R [d_l]x e_i / sqrt 2.
    """
    zero = wp.float64(0.0)
    I = wp.identity(n=3, dtype=wp.float64)
    logJ = wp.log(J)
    d2Psi_dJ2 = (mu + lam * (wp.float64(1.0) - logJ)) / (J * J)
    cof = J * wp.transpose(wp.inverse(F))
    G = cof * wp.transpose(Dmi)  # columns gamma_1..3
    DDt = Dmi * wp.transpose(Dmi)
    x0 = x[elements[e, 0]]
    e1 = x[elements[e, 1]] - x0
    e2 = x[elements[e, 2]] - x0
    e3 = x[elements[e, 3]] - x0
    cJ = V * dPsi_dJ * wp.determinant(Dmi)
    g1 = wp.vec3d(G[0, 0], G[1, 0], G[2, 0])
    g2 = wp.vec3d(G[0, 1], G[1, 1], G[2, 1])
    g3 = wp.vec3d(G[0, 2], G[1, 2], G[2, 2])
    c2 = V * d2Psi_dJ2
    K11 = V * mu * DDt[0, 0] * I + c2 * wp.outer(g1, g1)
    K22 = V * mu * DDt[1, 1] * I + c2 * wp.outer(g2, g2)
    K33 = V * mu * DDt[2, 2] * I + c2 * wp.outer(g3, g3)
    K12 = V * mu * DDt[0, 1] * I + c2 * wp.outer(g1, g2) - cJ * wp.skew(e3)
    K23 = V * mu * DDt[1, 2] * I + c2 * wp.outer(g2, g3) - cJ * wp.skew(e1)
    K13 = V * mu * DDt[0, 2] * I + c2 * wp.outer(g1, g3) + cJ * wp.skew(e2)
    if both != 0:  # exact Hessian into data, projected into data2
        _store_all3(scatter, slots, hess, data, e, K11, K22, K33, K12, K23, K13)
    if project != 0:
        R = _polar_rotation3(F)
        S = wp.transpose(R) * F
        S = wp.float64(0.5) * (S + wp.transpose(S))
        N = _negative_part_sym3(mu * I + dPsi_dJ * S)
        if wp.ddot(N, N) > zero:
            # P_l = -R [d_l]x / sqrt 2 (columns: twist modes seen at vertex l); block -= V P_l N P_l'^T
            P1 = R * wp.skew(wp.vec3d(Dmi[0, 0], Dmi[0, 1], Dmi[0, 2]))
            P2 = R * wp.skew(wp.vec3d(Dmi[1, 0], Dmi[1, 1], Dmi[1, 2]))
            P3 = R * wp.skew(wp.vec3d(Dmi[2, 0], Dmi[2, 1], Dmi[2, 2]))
            hV = wp.float64(0.5) * V
            K11 = K11 - hV * P1 * N * wp.transpose(P1)
            K22 = K22 - hV * P2 * N * wp.transpose(P2)
            K33 = K33 - hV * P3 * N * wp.transpose(P3)
            K12 = K12 - hV * P1 * N * wp.transpose(P2)
            K23 = K23 - hV * P2 * N * wp.transpose(P3)
            K13 = K13 - hV * P1 * N * wp.transpose(P3)
    if both != 0:
        _store_all3(scatter, slots, hess, data2, e, K11, K22, K33, K12, K23, K13)
    else:
        _store_all3(scatter, slots, hess, data, e, K11, K22, K33, K12, K23, K13)


@wp.func
def _hessian_svd(F: wp.mat33d, J: wp.float64, Dmi: wp.mat33d, V: wp.float64, mu: wp.float64, lam: wp.float64,
                 dPsi_dJ: wp.float64, scatter: int, slots: wp.array3d(dtype=wp.int32),
                 hess: wp.array3d(dtype=wp.float64), data: wp.array(dtype=wp.float64), e: int):
    """PSD-projected element Hessian from the full analytic eigensystem (SVD of F). Used when
    dPsi/dJ > 0 (strong volumetric expansion), where flip and scaling eigenvalues can be negative."""
    zero = wp.float64(0.0)
    project = 1
    U = wp.mat33d()
    s = wp.vec3d()
    Vs = wp.mat33d()
    wp.svd3(F, U, s, Vs)
    logJ = wp.log(J)
    h = wp.float64(_HALF_SQRT2)
    B = _mat9x12d()  # rows: nodal vectors of the 9 eigenmodes of d2Psi/dF2
    w = _vec9d()  # their clamped eigenvalues
    # twist (skew) and flip (symmetric) modes in the (1,2), (0,2), (0,1) planes
    B[0] = _mode(U, wp.mat33d(zero, zero, zero, zero, zero, -h, zero, h, zero), Vs, Dmi)
    w[0] = _clamp(mu + dPsi_dJ * s[0], project)
    B[1] = _mode(U, wp.mat33d(zero, zero, zero, zero, zero, h, zero, h, zero), Vs, Dmi)
    w[1] = _clamp(mu - dPsi_dJ * s[0], project)
    B[2] = _mode(U, wp.mat33d(zero, zero, h, zero, zero, zero, -h, zero, zero), Vs, Dmi)
    w[2] = _clamp(mu + dPsi_dJ * s[1], project)
    B[3] = _mode(U, wp.mat33d(zero, zero, h, zero, zero, zero, h, zero, zero), Vs, Dmi)
    w[3] = _clamp(mu - dPsi_dJ * s[1], project)
    B[4] = _mode(U, wp.mat33d(zero, -h, zero, h, zero, zero, zero, zero, zero), Vs, Dmi)
    w[4] = _clamp(mu + dPsi_dJ * s[2], project)
    B[5] = _mode(U, wp.mat33d(zero, h, zero, h, zero, zero, zero, zero, zero), Vs, Dmi)
    w[5] = _clamp(mu - dPsi_dJ * s[2], project)
    # scaling modes U diag(q) V^T: q eigenvectors of the Hessian of Psi in the singular values
    cs = mu + lam * (wp.float64(1.0) - logJ)
    A = wp.mat33d(
        mu + cs / (s[0] * s[0]), lam / (s[0] * s[1]), lam / (s[0] * s[2]),
        lam / (s[0] * s[1]), mu + cs / (s[1] * s[1]), lam / (s[1] * s[2]),
        lam / (s[0] * s[2]), lam / (s[1] * s[2]), mu + cs / (s[2] * s[2]),
    )
    Q = wp.mat33d()
    d = wp.vec3d()
    wp.eig3(A, Q, d)
    for k in range(3):
        B[6 + k] = _mode(U, wp.diag(wp.vec3d(Q[0, k], Q[1, k], Q[2, k])), Vs, Dmi)
        w[6 + k] = _clamp(d[k], project)
    # H_e = V sum_k w_k b_k b_k^T  (symmetric: compute the upper triangle, mirror)
    for r in range(12):
        for c in range(r, 12):
            acc = zero
            for k in range(9):
                acc += w[k] * B[k, r] * B[k, c]
            _store(scatter, slots, hess, data, e, r, c, V * acc)


# ----------------------------------------------------------------------------------------------
# 2D (plane strain): Warp overloads of the 3D functions of the same name (noqa F811)
# ----------------------------------------------------------------------------------------------
@wp.func
def _F(x: wp.array(dtype=wp.vec2d), elements: wp.array2d(dtype=wp.int32),  # noqa: F811
       Dm_inv: wp.array(dtype=wp.mat22d), e: int):
    x0 = x[elements[e, 0]]
    Ds = wp.matrix_from_cols(x[elements[e, 1]] - x0, x[elements[e, 2]] - x0)
    return Ds * Dm_inv[e]


@wp.func
def _nodal(M: wp.mat22d, Dmi: wp.mat22d):  # noqa: F811
    W = M * wp.transpose(Dmi)
    b = _vec6d()
    for a in range(2):
        b[2 + a] = W[a, 0]
        b[4 + a] = W[a, 1]
        b[a] = -(W[a, 0] + W[a, 1])
    return b


@wp.func
def _store_block2(scatter: int, slots: wp.array3d(dtype=wp.int32), hess: wp.array3d(dtype=wp.float64),
                  data: wp.array(dtype=wp.float64), e: int, l: int, lp: int, K: wp.mat22d):
    """Block (l, lp) of element e's 6x6 Hessian (and its transpose at (lp, l) when l != lp)."""
    for a in range(2):
        for b in range(2):
            if l != lp or b >= a:
                _store(scatter, slots, hess, data, e, 2 * l + a, 2 * lp + b, K[a, b])


@wp.func
def _store_all2(scatter: int, slots: wp.array3d(dtype=wp.int32), hess: wp.array3d(dtype=wp.float64),
                data: wp.array(dtype=wp.float64), e: int, K11: wp.mat22d, K22: wp.mat22d, K12: wp.mat22d):
    """Store a 6x6 element Hessian given its vertex 1..2 blocks (vertex 0 = minus their sums)."""
    K21 = wp.transpose(K12)
    K01 = -(K11 + K21)
    K02 = -(K12 + K22)
    K00 = -(K01 + K02)
    _store_block2(scatter, slots, hess, data, e, 0, 0, K00)
    _store_block2(scatter, slots, hess, data, e, 0, 1, K01)
    _store_block2(scatter, slots, hess, data, e, 0, 2, K02)
    _store_block2(scatter, slots, hess, data, e, 1, 1, K11)
    _store_block2(scatter, slots, hess, data, e, 1, 2, K12)
    _store_block2(scatter, slots, hess, data, e, 2, 2, K22)


@wp.func
def _hessian_direct(x: wp.array(dtype=wp.vec2d), elements: wp.array2d(dtype=wp.int32),  # noqa: F811
                    e: int, F: wp.mat22d, J: wp.float64, Dmi: wp.mat22d, V: wp.float64, mu: wp.float64, lam: wp.float64,
                    dPsi_dJ: wp.float64, project: int, both: int, scatter: int, slots: wp.array3d(dtype=wp.int32),
                    hess: wp.array3d(dtype=wp.float64), data: wp.array(dtype=wp.float64),
                    data2: wp.array(dtype=wp.float64)):
    """2D overload of :func:`_hessian_direct`: exact Hessian (det(Ds) = e1 x e2 is bilinear, so
    d2/de1 de2 = [[0, 1], [-1, 0]]), and with dPsi/dJ <= 0 only the single twist mode
    R [[0, -1], [1, 0]] / sqrt 2 (R the polar rotation, closed form in 2D) can have a negative
    eigenvalue, t = mu + dPsi/dJ, which projection removes: K -= V min(t, 0) b b^T."""
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    I = wp.identity(n=2, dtype=wp.float64)
    logJ = wp.log(J)
    c2 = V * (mu + lam * (one - logJ)) / (J * J)
    cof = J * wp.transpose(wp.inverse(F))
    G = cof * wp.transpose(Dmi)  # columns gamma_1, gamma_2
    g1 = wp.vec2d(G[0, 0], G[1, 0])
    g2 = wp.vec2d(G[0, 1], G[1, 1])
    DDt = Dmi * wp.transpose(Dmi)
    cJ = V * dPsi_dJ * wp.determinant(Dmi)
    K11 = V * mu * DDt[0, 0] * I + c2 * wp.outer(g1, g1)
    K22 = V * mu * DDt[1, 1] * I + c2 * wp.outer(g2, g2)
    K12 = V * mu * DDt[0, 1] * I + c2 * wp.outer(g1, g2) + cJ * wp.mat22d(zero, one, -one, zero)
    if both != 0:  # exact Hessian into data, projected into data2
        _store_all2(scatter, slots, hess, data, e, K11, K22, K12)
    t = mu + dPsi_dJ
    if project != 0 and t < zero:
        cr = F[0, 0] + F[1, 1]
        sr = F[1, 0] - F[0, 1]
        nr = wp.sqrt(cr * cr + sr * sr)
        RJ = wp.mat22d(-sr, -cr, cr, -sr) / nr  # R [[0, -1], [1, 0]], R = [[c, -s], [s, c]]
        b1 = RJ * wp.vec2d(Dmi[0, 0], Dmi[0, 1])
        b2 = RJ * wp.vec2d(Dmi[1, 0], Dmi[1, 1])
        ht = wp.float64(0.5) * V * t
        K11 = K11 - ht * wp.outer(b1, b1)
        K22 = K22 - ht * wp.outer(b2, b2)
        K12 = K12 - ht * wp.outer(b1, b2)
    if both != 0:
        _store_all2(scatter, slots, hess, data2, e, K11, K22, K12)
    else:
        _store_all2(scatter, slots, hess, data, e, K11, K22, K12)


@wp.func
def _hessian_svd(F: wp.mat22d, J: wp.float64, Dmi: wp.mat22d,  # noqa: F811
                 V: wp.float64, mu: wp.float64, lam: wp.float64,
                 dPsi_dJ: wp.float64, scatter: int, slots: wp.array3d(dtype=wp.int32),
                 hess: wp.array3d(dtype=wp.float64), data: wp.array(dtype=wp.float64), e: int):
    """PSD-projected element Hessian from the full eigensystem (SVD of F), for dPsi/dJ > 0."""
    zero = wp.float64(0.0)
    project = 1
    U = wp.mat22d()
    s = wp.vec2d()
    Vs = wp.mat22d()
    wp.svd2(F, U, s, Vs)
    logJ = wp.log(J)
    h = wp.float64(_HALF_SQRT2)
    B = _mat4x6d()
    w = _vec4d()
    B[0] = _mode(U, wp.mat22d(zero, -h, h, zero), Vs, Dmi)  # twist
    w[0] = _clamp(mu + dPsi_dJ, project)
    B[1] = _mode(U, wp.mat22d(zero, h, h, zero), Vs, Dmi)  # flip
    w[1] = _clamp(mu - dPsi_dJ, project)
    # scaling modes: closed-form eigensystem of the symmetric 2x2 [[a, o], [o, c2]]
    cs = mu + lam * (wp.float64(1.0) - logJ)
    a = mu + cs / (s[0] * s[0])
    c2 = mu + cs / (s[1] * s[1])
    o = lam / (s[0] * s[1])
    theta = wp.float64(0.5) * wp.atan2(wp.float64(2.0) * o, a - c2)
    ct = wp.cos(theta)
    st = wp.sin(theta)
    B[2] = _mode(U, wp.mat22d(ct, zero, zero, st), Vs, Dmi)
    w[2] = _clamp(a * ct * ct + wp.float64(2.0) * o * st * ct + c2 * st * st, project)
    B[3] = _mode(U, wp.mat22d(-st, zero, zero, ct), Vs, Dmi)
    w[3] = _clamp(a * st * st - wp.float64(2.0) * o * st * ct + c2 * ct * ct, project)
    for r in range(6):
        for c in range(r, 6):
            acc = zero
            for k in range(4):
                acc += w[k] * B[k, r] * B[k, c]
            _store(scatter, slots, hess, data, e, r, c, V * acc)


# ----------------------------------------------------------------------------------------------
# kernels: generic over the dimension (element functions above are overloaded for 2D and 3D;
# explicit overloads below, so the module is built once for both)
# ----------------------------------------------------------------------------------------------
@wp.func
def _dim(F: wp.mat33d):
    return wp.float64(3.0)


@wp.func
def _dim(F: wp.mat22d):  # noqa: F811
    return wp.float64(2.0)


@wp.kernel
def _energy_kernel(x: wp.array(dtype=Any), elements: wp.array2d(dtype=wp.int32), Dm_inv: wp.array(dtype=Any),
                   volume: wp.array(dtype=wp.float64), mu: wp.array(dtype=wp.float64), lam: wp.array(dtype=wp.float64),
                   energy: wp.array(dtype=wp.float64), det_F: wp.array(dtype=wp.float64)):
    e = wp.tid()
    F = _F(x, elements, Dm_inv, e)
    J = wp.determinant(F)
    det_F[e] = J
    energy[e] = wp.float64(0.0)
    if J > wp.float64(0.0):
        energy[e] = volume[e] * _psi(F, J, mu[e], lam[e], _dim(F))


@wp.kernel
def _gradient_kernel(x: wp.array(dtype=Any), elements: wp.array2d(dtype=wp.int32), Dm_inv: wp.array(dtype=Any),
                     volume: wp.array(dtype=wp.float64), mu: wp.array(dtype=wp.float64),
                     lam: wp.array(dtype=wp.float64), energy: wp.array(dtype=wp.float64),
                     det_F: wp.array(dtype=wp.float64), grad: wp.array(dtype=Any)):
    e = wp.tid()
    F = _F(x, elements, Dm_inv, e)
    J = wp.determinant(F)
    det_F[e] = J
    energy[e] = wp.float64(0.0)
    grad[e] = grad.dtype()
    if J > wp.float64(0.0):
        energy[e] = volume[e] * _psi(F, J, mu[e], lam[e], _dim(F))
        grad[e] = volume[e] * _nodal(_pk1(F, J, mu[e], lam[e]), Dm_inv[e])


@wp.kernel
def _hessian_kernel(x: wp.array(dtype=Any), elements: wp.array2d(dtype=wp.int32), Dm_inv: wp.array(dtype=Any),
                    volume: wp.array(dtype=wp.float64), mu_e: wp.array(dtype=wp.float64),
                    lam_e: wp.array(dtype=wp.float64), project: int, scatter: int, slots: wp.array3d(dtype=wp.int32),
                    energy: wp.array(dtype=wp.float64), det_F: wp.array(dtype=wp.float64), grad: wp.array(dtype=Any),
                    hess: wp.array3d(dtype=wp.float64), data: wp.array(dtype=wp.float64),
                    data2: wp.array(dtype=wp.float64)):
    e = wp.tid()
    F = _F(x, elements, Dm_inv, e)
    J = wp.determinant(F)
    det_F[e] = J
    zero = wp.float64(0.0)
    energy[e] = zero
    grad[e] = grad.dtype()
    if J <= zero:
        if scatter == 0:
            for r in range(hess.shape[1]):
                for c in range(hess.shape[2]):
                    hess[e, r, c] = zero
        return
    V = volume[e]
    mu = mu_e[e]
    lam = lam_e[e]
    Dmi = Dm_inv[e]
    energy[e] = V * _psi(F, J, mu, lam, _dim(F))
    grad[e] = V * _nodal(_pk1(F, J, mu, lam), Dmi)

    logJ = wp.log(J)
    dPsi_dJ = (lam * logJ - mu) / J
    mode = project
    both = 0
    if mode == _BOTH:  # exact Hessian into data, projected into data2
        mode = _PROJECT
        both = 1
    if mode == _EXACT or (mode == _PROJECT and dPsi_dJ <= zero):
        _hessian_direct(x, elements, e, F, J, Dmi, V, mu, lam, dPsi_dJ, mode, both, scatter, slots, hess, data, data2)
    elif both != 0:
        _hessian_direct(x, elements, e, F, J, Dmi, V, mu, lam, dPsi_dJ, _EXACT, 0, scatter, slots, hess, data, data)
        _hessian_svd(F, J, Dmi, V, mu, lam, dPsi_dJ, scatter, slots, hess, data2, e)
    else:
        _hessian_svd(F, J, Dmi, V, mu, lam, dPsi_dJ, scatter, slots, hess, data, e)


@wp.func
def _minus_eye(B: wp.mat33d):
    return B - wp.identity(n=3, dtype=wp.float64)


@wp.func
def _minus_eye(B: wp.mat22d):  # noqa: F811
    return B - wp.identity(n=2, dtype=wp.float64)


@wp.kernel
def _stress_kernel(x: wp.array(dtype=Any), elements: wp.array2d(dtype=wp.int32), Dm_inv: wp.array(dtype=Any),
                   mu_e: wp.array(dtype=wp.float64), det_F: wp.array(dtype=wp.float64),
                   von_mises: wp.array(dtype=wp.float64)):
    """det F and the von Mises stress sqrt(3/2) mu |dev(F F^T - I)| / J per element (see
    simfab.fem.stress.det_and_von_mises); +inf where det F <= 0 (stress undefined)."""
    e = wp.tid()
    F = _F(x, elements, Dm_inv, e)
    J = wp.determinant(F)
    det_F[e] = J
    if J <= wp.float64(0.0):
        von_mises[e] = wp.float64(wp.inf)
        return
    C = _minus_eye(F * wp.transpose(F))
    tr = wp.trace(C)
    dev2 = wp.max(wp.ddot(C, C) - tr * tr / wp.float64(3.0), wp.float64(0.0))
    von_mises[e] = wp.sqrt(wp.float64(1.5) * dev2) * mu_e[e] / J


def _declare_overloads():
    """2D and 3D instances of the kernels: positions, Dm^-1 and per-element gradient types."""
    for vec, mat, nodal_vec in ((wp.vec2d, wp.mat22d, _vec6d), (wp.vec3d, wp.mat33d, _vec12d)):
        types = {"x": wp.array(dtype=vec), "Dm_inv": wp.array(dtype=mat)}
        wp.overload(_stress_kernel, types)
        wp.overload(_energy_kernel, types)
        wp.overload(_gradient_kernel, {**types, "grad": wp.array(dtype=nodal_vec)})
        wp.overload(_hessian_kernel, {**types, "grad": wp.array(dtype=nodal_vec)})


_declare_overloads()

# ----------------------------------------------------------------------------------------------
# host side
# ----------------------------------------------------------------------------------------------
_ENERGY, _GRADIENT, _HESSIAN, _BLOCKS, _STRESS = 0, 1, 2, 3, 4  # what a launch computes
_KERNELS = (_energy_kernel, _gradient_kernel, _hessian_kernel, _hessian_kernel, _stress_kernel)  # by ``want``


class _Workspace:
    """Device copies of the model arrays, reusable buffers and pre-recorded launches (per model).

    Small meshes are dominated by per-call overhead, so the position buffer is persistent (on the
    CPU a numpy array the kernels read through an alias) and the launches are recorded once
    (``record_cmd``) and replayed with only the changing parameters updated.
    """

    def __init__(self, model: FemModel):
        d, m = model.dim, model.n_elements
        dev = model.device
        self.cpu = wp.get_device(dev).is_cpu
        self.vec = wp.vec3d if d == 3 else wp.vec2d
        mat = wp.mat33d if d == 3 else wp.mat22d
        self.x_np = np.zeros((model.n_vertices, d))
        self.x = self._wrap(self.x_np, self.vec, dev)
        self.elements = wp.array(model.elements, dtype=wp.int32, device=dev)
        self.Dm_inv = wp.array(model.Dm_inv, dtype=mat, device=dev)
        self.volume = wp.array(model.volume, dtype=wp.float64, device=dev)
        self.mu = wp.array(model.mu, dtype=wp.float64, device=dev)
        self.lam = wp.array(model.lam, dtype=wp.float64, device=dev)
        self.energy = wp.zeros(m, dtype=wp.float64, device=dev)
        self.det_F = wp.zeros(m, dtype=wp.float64, device=dev)
        self.grad = wp.zeros(m, dtype=_vec12d if d == 3 else _vec6d, device=dev)
        self.von_mises = wp.zeros(m, dtype=wp.float64, device=dev)
        self.hess = None  # element blocks (m, k*d, k*d) float64, allocated on first element_hessians()
        self.slots = None  # model.pattern.element_slots as int32, on first Hessian request
        self.dummy3 = wp.zeros((1, 1, 1), dtype=wp.float64, device=dev)
        self.dummy_slots = wp.zeros((1, 1, 1), dtype=wp.int32, device=dev)
        self.dummy_data = wp.zeros(1, dtype=wp.float64, device=dev)
        # host views of the per-element outputs on the CPU (the Warp arrays' own memory: no copy)
        self.energy_np, self.det_F_np, self.grad_np = (
            (self.energy.numpy(), self.det_F.numpy(), self.grad.numpy()) if self.cpu else (None, None, None))
        # CSR values written by the Hessian kernel: persistent buffers (``data``, and ``data2`` for the
        # projected Hessian with _BOTH), zeroed before and copied out after each launch, so the
        # recorded launch keeps its arguments (re-binding fresh arrays per call costs more than the copy)
        self.data_np = self.data = None
        self.data2_np = self.data2 = None
        self.bound = {}  # (launch, parameter name) -> value currently bound in a recorded launch
        self.commands: dict = {}
        # gradient scatter: (n*d, m*k*d) sparse sum over the element copies of each dof
        dofs = (model.elements.astype(np.int64)[:, :, None] * d + np.arange(d)).ravel()
        self.scatter = sp.csr_matrix((np.ones(dofs.size), (dofs, np.arange(dofs.size))),
                                     shape=(model.n_dofs, dofs.size))

    def _wrap(self, arr: np.ndarray, dtype, dev):
        """Warp view of a numpy array (alias on the CPU, a device copy elsewhere)."""
        return wp.array(arr, dtype=dtype, device=dev, copy=False) if self.cpu else wp.array(arr, dtype=dtype, device=dev)

    def hessian_values(self, second: bool = False) -> np.ndarray:
        """A fresh copy (nnz,) of the CSR values filled by the last Hessian launch: ``data``, or
        ``data2`` with ``second`` (callers keep and modify the matrices built on it)."""
        if self.cpu:
            return (self.data2_np if second else self.data_np).copy()
        return (self.data2 if second else self.data).numpy()

    def outputs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(energy (m,), det F (m,), nodal gradient blocks) of the last launch, as host arrays."""
        if self.cpu:
            return self.energy_np, self.det_F_np, self.grad_np
        return self.energy.numpy(), self.det_F.numpy(), self.grad.numpy()

    def bind(self, cmd, name: str, value) -> None:
        """Set a parameter of a recorded launch only when it changes (setting costs ~20 us): ints
        by value, arrays by identity."""
        key = (id(cmd), name)
        prev = self.bound.get(key)
        if (prev == value) if isinstance(value, int) else (prev is value):
            return
        cmd.set_param_by_name(name, value)
        self.bound[key] = value

    def set_positions(self, x: np.ndarray) -> None:
        self.x_np[...] = x
        if not self.cpu:
            self.x.assign(self.x_np)

    def command(self, model: FemModel, want: int):
        """The recorded launch for ``want`` (created on first use)."""
        cmd = self.commands.get(want)
        if cmd is not None:
            return cmd
        common = [self.x, self.elements, self.Dm_inv, self.volume, self.mu, self.lam]
        dev = model.device
        if want == _STRESS:
            args = dict(inputs=[self.x, self.elements, self.Dm_inv, self.mu], outputs=[self.det_F, self.von_mises])
        elif want == _ENERGY:
            args = dict(inputs=common, outputs=[self.energy, self.det_F])
        elif want == _GRADIENT:
            args = dict(inputs=common, outputs=[self.energy, self.det_F, self.grad])
        elif want == _HESSIAN:  # scatter straight into CSR values
            if model.pattern.nnz >= 2**31:
                raise ValueError("Hessian too large for int32 slots")
            self.slots = wp.array(model.pattern.element_slots.astype(np.int32), dtype=wp.int32, device=dev)
            self.data_np = np.zeros(model.pattern.nnz)
            self.data = self._wrap(self.data_np, wp.float64, dev)
            args = dict(inputs=common + [1, 1, self.slots],
                        outputs=[self.energy, self.det_F, self.grad, self.dummy3, self.data, self.dummy_data])
        else:  # _BLOCKS: keep the per-element blocks
            kk = (model.dim + 1) * model.dim
            self.hess = wp.zeros((model.n_elements, kk, kk), dtype=wp.float64, device=dev)
            args = dict(inputs=common + [1, 0, self.dummy_slots],
                        outputs=[self.energy, self.det_F, self.grad, self.hess, self.dummy_data, self.dummy_data])
        kernel = _KERNELS[want]
        with RECORD_LOCK:  # the first launch loads the module: one thread at a time
            cmd = wp.launch(kernel, dim=model.n_elements, device=dev, record_cmd=True, **args)
        self.commands[want] = cmd
        return cmd


def _workspace(model: FemModel) -> _Workspace:
    ws = model._cache.get("neohookean")
    if ws is None:
        ws = model._cache["neohookean"] = _Workspace(model)
    return ws


def _launch(model: FemModel, x, want: int, project: int = 1) -> _Workspace:
    """One kernel launch over all elements computing what ``want`` asks for."""
    x = model.check_positions(x)
    ws = _workspace(model)
    ws.set_positions(x)
    cmd = ws.command(model, want)
    if want in (_HESSIAN, _BLOCKS):
        ws.bind(cmd, "project", int(project))
    if want == _HESSIAN:
        _zero(ws, "data")
        if project == _BOTH:
            if ws.data2 is None:
                ws.data2_np = np.zeros(model.pattern.nnz)
                ws.data2 = ws._wrap(ws.data2_np, wp.float64, model.device)
            _zero(ws, "data2")
            ws.bind(cmd, "data2", ws.data2)
        else:
            ws.bind(cmd, "data2", ws.dummy_data)
    cmd.launch()
    return ws


def _zero(ws: _Workspace, name: str) -> None:
    """Zero the persistent CSR values buffer ``name`` ("data" or "data2") before a launch adds into it."""
    if ws.cpu:
        getattr(ws, name + "_np").fill(0.0)
    else:
        getattr(ws, name).zero_()


def _total(ws: _Workspace) -> float:
    energy, det, _ = ws.outputs()
    if det.min() <= 0.0:
        return float("inf")
    return float(energy.sum())


def _gradient(model: FemModel, ws: _Workspace) -> np.ndarray:
    return (ws.scatter @ ws.outputs()[2].reshape(-1)).reshape(model.n_vertices, model.dim)


def energy(model: FemModel, x) -> float:
    """Elastic energy [J] at positions x (n, dim) [m]; +inf if any element has det F <= 0."""
    return _total(_launch(model, x, _ENERGY, False))


def energy_gradient(model: FemModel, x) -> tuple[float, np.ndarray]:
    """(energy [J], gradient dE/dx (n, dim) [N]). The elastic nodal force is ``-gradient``."""
    ws = _launch(model, x, _GRADIENT, False)
    return _total(ws), _gradient(model, ws)


def element_hessians(model: FemModel, x, *, project_psd: bool = True) -> np.ndarray:
    """Per-element Hessian blocks (m, (dim+1)*dim, (dim+1)*dim) [N/m], dofs ordered (vertex, axis)."""
    ws = _launch(model, x, _BLOCKS, _PROJECT if project_psd else _EXACT)
    return ws.hess.numpy().copy()


def energy_gradient_hessian(model: FemModel, x, *, project_psd: bool = True) -> tuple[float, np.ndarray, sp.csr_matrix]:
    """(energy [J], gradient (n, dim) [N], Hessian (n*dim, n*dim) CSR [N/m]).

    With ``project_psd`` (default) every element block is projected to positive semi-definite
    (clamped eigenvalues of d2Psi/dF2), so the assembled Hessian is PSD; otherwise it is the
    exact Hessian. The CSR has the model's fixed pattern (``model.pattern``); its ``data`` is a
    fresh array the caller may modify (e.g. add contact blocks via ``pattern.block_slots``).
    """
    ws = _launch(model, x, _HESSIAN, _PROJECT if project_psd else _EXACT)
    H = model.pattern.matrix(ws.hessian_values())
    return _total(ws), _gradient(model, ws), H


def energy_gradient_hessians(model: FemModel, x) -> tuple[float, np.ndarray, sp.csr_matrix, sp.csr_matrix]:
    """(energy [J], gradient (n, dim) [N], exact Hessian, PSD-projected Hessian), both CSR
    (n*dim, n*dim) [N/m] with the model's pattern, from a single kernel launch.

    For :func:`simfab.solve.newton.minimize` return ``(H_exact, H_psd)`` as the Hessian: it takes
    exact Newton steps whenever the exact Hessian is positive definite (quadratic convergence near
    stable equilibria with large rotations, where per-element projection converges only linearly)
    and falls back to the projected one otherwise.
    """
    ws = _launch(model, x, _HESSIAN, _BOTH)
    H_exact = model.pattern.matrix(ws.hessian_values())
    H_psd = model.pattern.matrix(ws.hessian_values(second=True))
    return _total(ws), _gradient(model, ws), H_exact, H_psd


def _energy_gradient_hessian_svd(model: FemModel, x) -> tuple[float, np.ndarray, sp.csr_matrix]:
    """Like :func:`energy_gradient_hessian` (projected) but always through the SVD eigensystem:
    the reference route the faster direct route is checked and benchmarked against."""
    ws = _launch(model, x, _HESSIAN, _PROJECT_SVD)
    H = model.pattern.matrix(ws.hessian_values())
    return _total(ws), _gradient(model, ws), H


def det_and_von_mises(model: FemModel, x) -> tuple[np.ndarray, np.ndarray]:
    """(det F (m,) [-], von Mises stress (m,) [Pa]) per element in one launch; see
    :func:`simfab.fem.stress.det_and_von_mises` (the public entry point) for the formula."""
    ws = _launch(model, x, _STRESS)
    return ws.det_F.numpy().copy(), ws.von_mises.numpy().copy()


def det_F(model: FemModel, x) -> np.ndarray:
    """det F per element (m,) at positions x (n, dim); <= 0 means inverted or degenerate."""
    return _launch(model, x, _ENERGY, False).outputs()[1].copy()
