"""Compressible Neo-Hookean elasticity on linear simplices: the Warp kernels (energy, gradient,
Hessian side by side) and their :data:`LINEAR` record. The public functions that launch them, for
every element order, are in :mod:`simfab.fem.elastic`.

Per element (volume V, Lame parameters mu, lam, dimension d; 2D is plane strain, V = area * thickness):

    Psi(F) = mu/2 (||F||_F^2 - d) - mu log J + lam/2 (log J)^2,      E_e = V Psi(F),  J = det F
    F = Ds Dm^-1,  Ds = [x1 - x0, x2 - x0(, x3 - x0)],    P = dPsi/dF = mu (F - F^-T) + lam log J F^-T

Nodal gradient: dE/dx_i = V P Dm^-T e_i (i = 1..d), dE/dx_0 = -sum_i dE/dx_i (the elastic force is
``-gradient``). Hessian d2Psi/dF2 through its analytic eigensystem (Smith, De Goes, Kim 2019); the
PSD projection clamps negative eigenvalues in the d^2-dimensional stress space. In the common case
dPsi/dJ <= 0 only the twist block can be indefinite, and its negative part is removed in closed form
from the polar decomposition (no SVD); otherwise the full SVD eigensystem is used. Hessian modes:
EXACT (validated against finite differences), PROJECT and PROJECT_SVD (agree to round-off), BOTH.
The helpers the P2 kernels share (:mod:`simfab.fem.neohookean_p2`) are public: ``psi``, ``pk1``,
``negative_part_sym3``, ``polar_rotation3``, ``stress_hessian_svd``, ``store_hessian_entry``,
``void_element``, ``dim_float``, ``dim_int``, ``mat44d``, ``mat99d`` and the ``HESSIAN_*`` constants.

All kernels run in float64 with one thread per element (:mod:`simfab.fem.workspace`). The
eigensystem's derivation: docs/methods.md, "simfab.fem.neohookean".
"""

from __future__ import annotations

from typing import Any

from simfab._warp import wp
from simfab.fem import tolerances
from simfab.fem.workspace import ElementKernels, Hessian

wp.set_module_options({"enable_backward": False})  # hand-written derivatives; halves compile time

_vec6d = wp.types.vector(length=6, dtype=wp.float64)
_vec12d = wp.types.vector(length=12, dtype=wp.float64)
_vec4d = wp.types.vector(length=4, dtype=wp.float64)
_vec9d = wp.types.vector(length=9, dtype=wp.float64)
_mat4x6d = wp.types.matrix(shape=(4, 6), dtype=wp.float64)
_mat9x12d = wp.types.matrix(shape=(9, 12), dtype=wp.float64)
mat44d = wp.types.matrix(shape=(4, 4), dtype=wp.float64)
mat99d = wp.types.matrix(shape=(9, 9), dtype=wp.float64)

_HALF_SQRT2 = 0.7071067811865476  # 1/sqrt(2): unit Frobenius norm of the twist/flip modes
# Hessian kernel modes (simfab.fem.workspace.Hessian)
HESSIAN_EXACT = wp.constant(int(Hessian.EXACT))
HESSIAN_PROJECT = wp.constant(int(Hessian.PROJECT))
HESSIAN_PROJECT_SVD = wp.constant(int(Hessian.PROJECT_SVD))
HESSIAN_BOTH = wp.constant(int(Hessian.BOTH))
_POLAR_STEP_SQ_TOL = wp.constant(wp.float64(tolerances.POLAR_STEP_SQ_TOL))
_POLAR_MAX_ITER = wp.constant(tolerances.POLAR_MAX_ITER)


@wp.func
def _clamp(lam: wp.float64, project: int):
    if project != 0 and lam < wp.float64(0.0):
        return wp.float64(0.0)
    return lam


@wp.func
def store_hessian_entry(scatter: int, slots: wp.array3d(dtype=wp.int32), hess: wp.array3d(dtype=wp.float64),
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
def void_element(e: int, scatter: int, energy: wp.array(dtype=wp.float64), grad: wp.array(dtype=Any),
          hess: wp.array3d(dtype=wp.float64)):
    """Zero element e's energy, gradient and (with block storage, scatter == 0) Hessian block: an
    inverted element contributes nothing."""
    energy[e] = wp.float64(0.0)
    grad[e] = grad.dtype()
    if scatter == 0:
        for r in range(hess.shape[1]):
            for c in range(hess.shape[2]):
                hess[e, r, c] = wp.float64(0.0)


@wp.func
def psi(F: Any, J: wp.float64, mu: wp.float64, lam: wp.float64, d: wp.float64):
    """Neo-Hookean energy density [Pa] (J > 0)."""
    logJ = wp.log(J)
    return wp.float64(0.5) * mu * (wp.ddot(F, F) - d) - mu * logJ + wp.float64(0.5) * lam * logJ * logJ


@wp.func
def pk1(F: Any, J: wp.float64, mu: wp.float64, lam: wp.float64):
    """First Piola-Kirchhoff stress P = mu (F - F^-T) + lam log J F^-T [Pa]."""
    FinvT = wp.transpose(wp.inverse(F))
    return mu * (F - FinvT) + lam * wp.log(J) * FinvT


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
                store_hessian_entry(scatter, slots, hess, data, e, 3 * l + a, 3 * lp + b, K[a, b])


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
def negative_part_sym3(T: wp.mat33d):
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
def polar_rotation3(F: wp.mat33d):
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
        R = polar_rotation3(F)
        S = wp.transpose(R) * F
        S = wp.float64(0.5) * (S + wp.transpose(S))
        N = negative_part_sym3(mu * I + dPsi_dJ * S)
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
def _eigensystem(F: wp.mat33d, J: wp.float64, mu: wp.float64, lam: wp.float64):
    """The 9 eigenmodes of d2Psi/dF2 from the SVD F = U diag(s) V^T, as rows vec(U M_k V^T)
    (row-major) of a 9x9 matrix, and their eigenvalues clamped at 0 (module docstring): twist
    (skew) and flip (symmetric) modes in the (1,2), (0,2), (0,1) planes, then the scaling modes
    U diag(q) V^T, q the eigenvectors of the Hessian of Psi in the singular values."""
    zero = wp.float64(0.0)
    U = wp.mat33d()
    s = wp.vec3d()
    Vs = wp.mat33d()
    wp.svd3(F, U, s, Vs)
    logJ = wp.log(J)
    dPsi_dJ = (lam * logJ - mu) / J
    h = wp.float64(_HALF_SQRT2)
    Vt = wp.transpose(Vs)
    modes = mat99d()
    w = _vec9d()
    modes[0] = _vec(U * wp.mat33d(zero, zero, zero, zero, zero, -h, zero, h, zero) * Vt)
    w[0] = _clamp(mu + dPsi_dJ * s[0], 1)
    modes[1] = _vec(U * wp.mat33d(zero, zero, zero, zero, zero, h, zero, h, zero) * Vt)
    w[1] = _clamp(mu - dPsi_dJ * s[0], 1)
    modes[2] = _vec(U * wp.mat33d(zero, zero, h, zero, zero, zero, -h, zero, zero) * Vt)
    w[2] = _clamp(mu + dPsi_dJ * s[1], 1)
    modes[3] = _vec(U * wp.mat33d(zero, zero, h, zero, zero, zero, h, zero, zero) * Vt)
    w[3] = _clamp(mu - dPsi_dJ * s[1], 1)
    modes[4] = _vec(U * wp.mat33d(zero, -h, zero, h, zero, zero, zero, zero, zero) * Vt)
    w[4] = _clamp(mu + dPsi_dJ * s[2], 1)
    modes[5] = _vec(U * wp.mat33d(zero, h, zero, h, zero, zero, zero, zero, zero) * Vt)
    w[5] = _clamp(mu - dPsi_dJ * s[2], 1)
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
        modes[6 + k] = _vec(U * wp.diag(wp.vec3d(Q[0, k], Q[1, k], Q[2, k])) * Vt)
        w[6 + k] = _clamp(d[k], 1)
    return modes, w


@wp.func
def _vec(M: wp.mat33d):
    """vec(M), row-major."""
    return _vec9d(M[0, 0], M[0, 1], M[0, 2], M[1, 0], M[1, 1], M[1, 2], M[2, 0], M[2, 1], M[2, 2])


@wp.func
def _unvec(v: _vec9d):
    return wp.mat33d(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8])


@wp.func
def _hessian_svd(F: wp.mat33d, J: wp.float64, Dmi: wp.mat33d, V: wp.float64, mu: wp.float64, lam: wp.float64,
                 scatter: int, slots: wp.array3d(dtype=wp.int32), hess: wp.array3d(dtype=wp.float64),
                 data: wp.array(dtype=wp.float64), e: int):
    """PSD-projected element Hessian V sum_k w_k b_k b_k^T from the clamped eigensystem (b_k: the
    nodal vector of mode k). Used when dPsi/dJ > 0 (strong volumetric expansion), where flip and
    scaling eigenvalues can be negative."""
    zero = wp.float64(0.0)
    modes, w = _eigensystem(F, J, mu, lam)
    B = _mat9x12d()  # rows: nodal vectors of the 9 eigenmodes
    for k in range(9):
        B[k] = _nodal(_unvec(modes[k]), Dmi)
    for r in range(12):  # symmetric: the upper triangle, mirrored by store_hessian_entry
        for c in range(r, 12):
            acc = zero
            for k in range(9):
                acc += w[k] * B[k, r] * B[k, c]
            store_hessian_entry(scatter, slots, hess, data, e, r, c, V * acc)


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
                store_hessian_entry(scatter, slots, hess, data, e, 2 * l + a, 2 * lp + b, K[a, b])


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
def _eigensystem(F: wp.mat22d, J: wp.float64, mu: wp.float64, lam: wp.float64):  # noqa: F811
    """2D: twist, flip and the two scaling modes (closed-form eigensystem of the symmetric 2x2
    [[a, o], [o, c2]]) as rows vec(U M_k V^T) of a 4x4 matrix, eigenvalues clamped at 0."""
    zero = wp.float64(0.0)
    U = wp.mat22d()
    s = wp.vec2d()
    Vs = wp.mat22d()
    wp.svd2(F, U, s, Vs)
    logJ = wp.log(J)
    dPsi_dJ = (lam * logJ - mu) / J
    h = wp.float64(_HALF_SQRT2)
    Vt = wp.transpose(Vs)
    modes = mat44d()
    w = _vec4d()
    modes[0] = _vec(U * wp.mat22d(zero, -h, h, zero) * Vt)  # twist
    w[0] = _clamp(mu + dPsi_dJ, 1)
    modes[1] = _vec(U * wp.mat22d(zero, h, h, zero) * Vt)  # flip
    w[1] = _clamp(mu - dPsi_dJ, 1)
    cs = mu + lam * (wp.float64(1.0) - logJ)
    a = mu + cs / (s[0] * s[0])
    c2 = mu + cs / (s[1] * s[1])
    o = lam / (s[0] * s[1])
    theta = wp.float64(0.5) * wp.atan2(wp.float64(2.0) * o, a - c2)
    ct = wp.cos(theta)
    st = wp.sin(theta)
    modes[2] = _vec(U * wp.mat22d(ct, zero, zero, st) * Vt)
    w[2] = _clamp(a * ct * ct + wp.float64(2.0) * o * st * ct + c2 * st * st, 1)
    modes[3] = _vec(U * wp.mat22d(-st, zero, zero, ct) * Vt)
    w[3] = _clamp(a * st * st - wp.float64(2.0) * o * st * ct + c2 * ct * ct, 1)
    return modes, w


@wp.func
def _vec(M: wp.mat22d):  # noqa: F811
    return _vec4d(M[0, 0], M[0, 1], M[1, 0], M[1, 1])


@wp.func
def _unvec(v: _vec4d):  # noqa: F811
    return wp.mat22d(v[0], v[1], v[2], v[3])


@wp.func
def _hessian_svd(F: wp.mat22d, J: wp.float64, Dmi: wp.mat22d, V: wp.float64, mu: wp.float64,  # noqa: F811
                 lam: wp.float64, scatter: int, slots: wp.array3d(dtype=wp.int32),
                 hess: wp.array3d(dtype=wp.float64), data: wp.array(dtype=wp.float64), e: int):
    zero = wp.float64(0.0)
    modes, w = _eigensystem(F, J, mu, lam)
    B = _mat4x6d()
    for k in range(4):
        B[k] = _nodal(_unvec(modes[k]), Dmi)
    for r in range(6):
        for c in range(r, 6):
            acc = zero
            for k in range(4):
                acc += w[k] * B[k, r] * B[k, c]
            store_hessian_entry(scatter, slots, hess, data, e, r, c, V * acc)


# ----------------------------------------------------------------------------------------------
# the clamped stress Hessian d2Psi/dF2 from the analytic eigensystem, for the P2 kernels' SVD route
# (built mode by mode rather than from ``_eigensystem``: see docs/decisions.md)
# ----------------------------------------------------------------------------------------------
@wp.func
def dim_int(M: wp.mat33d):
    return 3


@wp.func
def dim_int(M: wp.mat22d):  # noqa: F811
    return 2


@wp.func
def _outer_vec(A: Any, M: Any, c: wp.float64):
    """A + c vec(M) vec(M)^T (vec row-major, M d x d)."""
    d = dim_int(M)
    B = A
    for i in range(d):
        for k in range(d):
            for j in range(d):
                for l in range(d):
                    B[d * i + k, d * j + l] = B[d * i + k, d * j + l] + c * M[i, k] * M[j, l]
    return B


@wp.func
def _svd_mode(A: Any, U: Any, M: Any, Vs: Any, lam_k: wp.float64):
    """A + lam_k vec(U M V^T) vec(U M V^T)^T."""
    return _outer_vec(A, U * M * wp.transpose(Vs), lam_k)


@wp.func
def stress_hessian_svd(F: wp.mat33d, J: wp.float64, mu: wp.float64, lam: wp.float64):
    """d2Psi/dF2 rebuilt from its analytic eigensystem with clamped eigenvalues (PSD)."""
    zero = wp.float64(0.0)
    U = wp.mat33d()
    s = wp.vec3d()
    Vs = wp.mat33d()
    wp.svd3(F, U, s, Vs)
    logJ = wp.log(J)
    dPsi_dJ = (lam * logJ - mu) / J
    h = wp.float64(_HALF_SQRT2)
    A = mat99d()
    A = _svd_mode(A, U, wp.mat33d(zero, zero, zero, zero, zero, -h, zero, h, zero), Vs, _clamp(mu + dPsi_dJ * s[0], 1))
    A = _svd_mode(A, U, wp.mat33d(zero, zero, zero, zero, zero, h, zero, h, zero), Vs, _clamp(mu - dPsi_dJ * s[0], 1))
    A = _svd_mode(A, U, wp.mat33d(zero, zero, h, zero, zero, zero, -h, zero, zero), Vs, _clamp(mu + dPsi_dJ * s[1], 1))
    A = _svd_mode(A, U, wp.mat33d(zero, zero, h, zero, zero, zero, h, zero, zero), Vs, _clamp(mu - dPsi_dJ * s[1], 1))
    A = _svd_mode(A, U, wp.mat33d(zero, -h, zero, h, zero, zero, zero, zero, zero), Vs, _clamp(mu + dPsi_dJ * s[2], 1))
    A = _svd_mode(A, U, wp.mat33d(zero, h, zero, h, zero, zero, zero, zero, zero), Vs, _clamp(mu - dPsi_dJ * s[2], 1))
    cs = mu + lam * (wp.float64(1.0) - logJ)
    S = wp.mat33d(
        mu + cs / (s[0] * s[0]), lam / (s[0] * s[1]), lam / (s[0] * s[2]),
        lam / (s[0] * s[1]), mu + cs / (s[1] * s[1]), lam / (s[1] * s[2]),
        lam / (s[0] * s[2]), lam / (s[1] * s[2]), mu + cs / (s[2] * s[2]),
    )
    Q = wp.mat33d()
    d = wp.vec3d()
    wp.eig3(S, Q, d)
    for k in range(3):
        A = _svd_mode(A, U, wp.diag(wp.vec3d(Q[0, k], Q[1, k], Q[2, k])), Vs, _clamp(d[k], 1))
    return A


@wp.func
def stress_hessian_svd(F: wp.mat22d, J: wp.float64, mu: wp.float64, lam: wp.float64):  # noqa: F811
    zero = wp.float64(0.0)
    U = wp.mat22d()
    s = wp.vec2d()
    Vs = wp.mat22d()
    wp.svd2(F, U, s, Vs)
    logJ = wp.log(J)
    dPsi_dJ = (lam * logJ - mu) / J
    h = wp.float64(_HALF_SQRT2)
    A = mat44d()
    A = _svd_mode(A, U, wp.mat22d(zero, -h, h, zero), Vs, _clamp(mu + dPsi_dJ, 1))  # twist
    A = _svd_mode(A, U, wp.mat22d(zero, h, h, zero), Vs, _clamp(mu - dPsi_dJ, 1))  # flip
    cs = mu + lam * (wp.float64(1.0) - logJ)
    a = mu + cs / (s[0] * s[0])
    c2 = mu + cs / (s[1] * s[1])
    o = lam / (s[0] * s[1])
    theta = wp.float64(0.5) * wp.atan2(wp.float64(2.0) * o, a - c2)
    ct = wp.cos(theta)
    st = wp.sin(theta)
    A = _svd_mode(A, U, wp.mat22d(ct, zero, zero, st), Vs,
                  _clamp(a * ct * ct + wp.float64(2.0) * o * st * ct + c2 * st * st, 1))
    A = _svd_mode(A, U, wp.mat22d(-st, zero, zero, ct), Vs,
                  _clamp(a * st * st - wp.float64(2.0) * o * st * ct + c2 * ct * ct, 1))
    return A


# ----------------------------------------------------------------------------------------------
# kernels: generic over the dimension (element functions above are overloaded for 2D and 3D;
# explicit overloads below, so the module is built once for both)
# ----------------------------------------------------------------------------------------------
@wp.func
def dim_float(F: wp.mat33d):
    return wp.float64(3.0)


@wp.func
def dim_float(F: wp.mat22d):  # noqa: F811
    return wp.float64(2.0)


@wp.kernel
def _energy_kernel(first: int, x: wp.array(dtype=Any), elements: wp.array2d(dtype=wp.int32),
                   Dm_inv: wp.array(dtype=Any), volume: wp.array(dtype=wp.float64), mu: wp.array(dtype=wp.float64),
                   lam: wp.array(dtype=wp.float64), energy: wp.array(dtype=wp.float64),
                   det_F: wp.array(dtype=wp.float64)):
    e = first + wp.tid()
    F = _F(x, elements, Dm_inv, e)
    J = wp.determinant(F)
    det_F[e] = J
    energy[e] = wp.float64(0.0)
    if J > wp.float64(0.0):
        energy[e] = volume[e] * psi(F, J, mu[e], lam[e], dim_float(F))


@wp.kernel
def _gradient_kernel(first: int, x: wp.array(dtype=Any), elements: wp.array2d(dtype=wp.int32),
                     Dm_inv: wp.array(dtype=Any), volume: wp.array(dtype=wp.float64), mu: wp.array(dtype=wp.float64),
                     lam: wp.array(dtype=wp.float64), energy: wp.array(dtype=wp.float64),
                     det_F: wp.array(dtype=wp.float64), grad: wp.array(dtype=Any)):
    e = first + wp.tid()
    F = _F(x, elements, Dm_inv, e)
    J = wp.determinant(F)
    det_F[e] = J
    energy[e] = wp.float64(0.0)
    grad[e] = grad.dtype()
    if J > wp.float64(0.0):
        energy[e] = volume[e] * psi(F, J, mu[e], lam[e], dim_float(F))
        grad[e] = volume[e] * _nodal(pk1(F, J, mu[e], lam[e]), Dm_inv[e])


@wp.kernel
def _hessian_kernel(first: int, x: wp.array(dtype=Any), elements: wp.array2d(dtype=wp.int32),
                    Dm_inv: wp.array(dtype=Any), volume: wp.array(dtype=wp.float64), mu_e: wp.array(dtype=wp.float64),
                    lam_e: wp.array(dtype=wp.float64), project: int, scatter: int, slots: wp.array3d(dtype=wp.int32),
                    energy: wp.array(dtype=wp.float64), det_F: wp.array(dtype=wp.float64), grad: wp.array(dtype=Any),
                    hess: wp.array3d(dtype=wp.float64), data: wp.array(dtype=wp.float64),
                    data2: wp.array(dtype=wp.float64)):
    e = first + wp.tid()
    F = _F(x, elements, Dm_inv, e)
    J = wp.determinant(F)
    det_F[e] = J
    zero = wp.float64(0.0)
    if J <= zero:
        void_element(e, scatter, energy, grad, hess)
        return
    V = volume[e]
    mu = mu_e[e]
    lam = lam_e[e]
    Dmi = Dm_inv[e]
    energy[e] = V * psi(F, J, mu, lam, dim_float(F))
    grad[e] = V * _nodal(pk1(F, J, mu, lam), Dmi)

    logJ = wp.log(J)
    dPsi_dJ = (lam * logJ - mu) / J
    mode = project
    both = 0
    if mode == HESSIAN_BOTH:  # exact Hessian into data, projected into data2
        mode = HESSIAN_PROJECT
        both = 1
    if mode == HESSIAN_EXACT or (mode == HESSIAN_PROJECT and dPsi_dJ <= zero):
        _hessian_direct(x, elements, e, F, J, Dmi, V, mu, lam, dPsi_dJ, mode, both, scatter, slots, hess, data, data2)
    elif both != 0:
        _hessian_direct(x, elements, e, F, J, Dmi, V, mu, lam, dPsi_dJ, HESSIAN_EXACT, 0, scatter, slots, hess, data,
                        data)
        _hessian_svd(F, J, Dmi, V, mu, lam, scatter, slots, hess, data2, e)
    else:
        _hessian_svd(F, J, Dmi, V, mu, lam, scatter, slots, hess, data, e)


@wp.func
def _minus_eye(B: wp.mat33d):
    return B - wp.identity(n=3, dtype=wp.float64)


@wp.func
def _minus_eye(B: wp.mat22d):  # noqa: F811
    return B - wp.identity(n=2, dtype=wp.float64)


@wp.kernel
def _stress_kernel(first: int, x: wp.array(dtype=Any), elements: wp.array2d(dtype=wp.int32),
                   Dm_inv: wp.array(dtype=Any), volume: wp.array(dtype=wp.float64), mu_e: wp.array(dtype=wp.float64),
                   lam_e: wp.array(dtype=wp.float64), det_F: wp.array(dtype=wp.float64),
                   von_mises: wp.array(dtype=wp.float64)):
    """det F and the von Mises stress sqrt(3/2) mu |dev(F F^T - I)| / J per element (see
    simfab.fem.elastic.det_and_von_mises); +inf where det F <= 0 (stress undefined)."""
    e = first + wp.tid()
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
# the element order's record for simfab.fem.workspace
# ----------------------------------------------------------------------------------------------
#: Linear simplices: F = Ds Dm^-1 is constant over the element (the one-quadrature-point case:
#: ``model.element_geometry()`` is (Dm^-1 (m, d, d), volume (m,))). One launch at every size: two
#: halves on two threads gained nothing on the insertion models (see docs/decisions.md).
LINEAR = ElementKernels(energy=_energy_kernel, gradient=_gradient_kernel,
                        hessian={2: _hessian_kernel, 3: _hessian_kernel}, stress=_stress_kernel,
                        grad_dtype={2: _vec6d, 3: _vec12d}, geometry_dtype={2: wp.mat22d, 3: wp.mat33d})
