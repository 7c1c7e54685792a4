"""Compressible Neo-Hookean elasticity on linear simplices: energy, gradient, Hessian side by side.

Per element (volume V, Lame parameters mu, lam, dimension d):

    Psi(F) = mu/2 (||F||_F^2 - d) - mu log J + lam/2 (log J)^2,      E_e = V Psi(F),  J = det F
    F = Ds Dm^-1,  Ds = [x1 - x0, x2 - x0(, x3 - x0)]

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
det F, whose eigenvalues on those modes are +-s_k.) The element Hessian is
V sum_modes max(eig, 0) b b^T with b = dF/dx^T : mode, i.e. the projection to PSD is done exactly
in the d^2-dimensional stress space, which makes the 12x12 (6x6) element block PSD without a
numerical eigensolver. With ``project_psd=False`` the eigenvalues are used unclamped, giving the
exact Hessian (validated against finite differences in the tests).

All kernels run in float64, one launch per call for all elements (energy, gradient and Hessian
blocks in the same kernel when the Hessian is wanted).

An element with det F <= 0 makes the energy +inf (the log barrier of Neo-Hookean); such an
element contributes nothing to the gradient and Hessian, which are then not meaningful.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from simfab._warp import wp
from simfab.fem.model import FemModel

wp.set_module_options({"enable_backward": False})  # hand-written derivatives; halves compile time

_vec6d = wp.types.vector(length=6, dtype=wp.float64)
_vec12d = wp.types.vector(length=12, dtype=wp.float64)
_vec4d = wp.types.vector(length=4, dtype=wp.float64)
_vec9d = wp.types.vector(length=9, dtype=wp.float64)
_mat4x6d = wp.types.matrix(shape=(4, 6), dtype=wp.float64)
_mat9x12d = wp.types.matrix(shape=(9, 12), dtype=wp.float64)

_HALF_SQRT2 = 0.7071067811865476  # 1/sqrt(2): unit Frobenius norm of the twist/flip modes


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


# ----------------------------------------------------------------------------------------------
# 3D
# ----------------------------------------------------------------------------------------------
@wp.func
def _F3(x: wp.array(dtype=wp.vec3d), elements: wp.array2d(dtype=wp.int32), Dm_inv: wp.array(dtype=wp.mat33d), e: int):
    x0 = x[elements[e, 0]]
    Ds = wp.matrix_from_cols(x[elements[e, 1]] - x0, x[elements[e, 2]] - x0, x[elements[e, 3]] - x0)
    return Ds * Dm_inv[e]


@wp.func
def _nodal3(M: wp.mat33d, Dmi: wp.mat33d):
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
def _mode3(U: wp.mat33d, M: wp.mat33d, V: wp.mat33d, Dmi: wp.mat33d):
    return _nodal3(U * M * wp.transpose(V), Dmi)


@wp.func
def _cholesky3(A: wp.mat33d):
    """Lower-triangular L with L L^T = A for a symmetric positive definite 3x3 A."""
    l00 = wp.sqrt(A[0, 0])
    l10 = A[1, 0] / l00
    l20 = A[2, 0] / l00
    l11 = wp.sqrt(A[1, 1] - l10 * l10)
    l21 = (A[2, 1] - l20 * l10) / l11
    l22 = wp.sqrt(A[2, 2] - l20 * l20 - l21 * l21)
    z = wp.float64(0.0)
    return wp.mat33d(l00, z, z, l10, l11, z, l20, l21, l22)


@wp.kernel
def _energy3(x: wp.array(dtype=wp.vec3d), elements: wp.array2d(dtype=wp.int32), Dm_inv: wp.array(dtype=wp.mat33d),
             volume: wp.array(dtype=wp.float64), mu: wp.array(dtype=wp.float64), lam: wp.array(dtype=wp.float64),
             energy: wp.array(dtype=wp.float64), det_F: wp.array(dtype=wp.float64)):
    e = wp.tid()
    F = _F3(x, elements, Dm_inv, e)
    J = wp.determinant(F)
    det_F[e] = J
    energy[e] = wp.float64(0.0)
    if J > wp.float64(0.0):
        energy[e] = volume[e] * _psi(F, J, mu[e], lam[e], wp.float64(3.0))


@wp.kernel
def _gradient3(x: wp.array(dtype=wp.vec3d), elements: wp.array2d(dtype=wp.int32), Dm_inv: wp.array(dtype=wp.mat33d),
               volume: wp.array(dtype=wp.float64), mu: wp.array(dtype=wp.float64), lam: wp.array(dtype=wp.float64),
               energy: wp.array(dtype=wp.float64), det_F: wp.array(dtype=wp.float64), grad: wp.array(dtype=_vec12d)):
    e = wp.tid()
    F = _F3(x, elements, Dm_inv, e)
    J = wp.determinant(F)
    det_F[e] = J
    energy[e] = wp.float64(0.0)
    grad[e] = _vec12d()
    if J > wp.float64(0.0):
        energy[e] = volume[e] * _psi(F, J, mu[e], lam[e], wp.float64(3.0))
        grad[e] = volume[e] * _nodal3(_pk1(F, J, mu[e], lam[e]), Dm_inv[e])


@wp.kernel
def _hessian3(x: wp.array(dtype=wp.vec3d), elements: wp.array2d(dtype=wp.int32), Dm_inv: wp.array(dtype=wp.mat33d),
              volume: wp.array(dtype=wp.float64), mu_e: wp.array(dtype=wp.float64), lam_e: wp.array(dtype=wp.float64),
              project: int, scatter: int, slots: wp.array3d(dtype=wp.int32),
              energy: wp.array(dtype=wp.float64), det_F: wp.array(dtype=wp.float64), grad: wp.array(dtype=_vec12d),
              hess: wp.array3d(dtype=wp.float64), data: wp.array(dtype=wp.float64)):
    e = wp.tid()
    F = _F3(x, elements, Dm_inv, e)
    J = wp.determinant(F)
    det_F[e] = J
    zero = wp.float64(0.0)
    energy[e] = zero
    grad[e] = _vec12d()
    if J <= zero:
        if scatter == 0:
            for r in range(12):
                for c in range(12):
                    hess[e, r, c] = zero
        return
    V = volume[e]
    mu = mu_e[e]
    lam = lam_e[e]
    Dmi = Dm_inv[e]
    energy[e] = V * _psi(F, J, mu, lam, wp.float64(3.0))
    grad[e] = V * _nodal3(_pk1(F, J, mu, lam), Dmi)

    U = wp.mat33d()
    s = wp.vec3d()
    Vs = wp.mat33d()
    wp.svd3(F, U, s, Vs)
    logJ = wp.log(J)
    dPsi_dJ = (lam * logJ - mu) / J
    h = wp.float64(_HALF_SQRT2)
    B = _mat9x12d()  # rows: nodal vectors of the 9 eigenmodes of d2Psi/dF2
    w = _vec9d()  # their (clamped) eigenvalues
    # twist (skew) and flip (symmetric) modes in the (1,2), (0,2), (0,1) planes
    B[0] = _mode3(U, wp.mat33d(zero, zero, zero, zero, zero, -h, zero, h, zero), Vs, Dmi)
    w[0] = _clamp(mu + dPsi_dJ * s[0], project)
    B[1] = _mode3(U, wp.mat33d(zero, zero, zero, zero, zero, h, zero, h, zero), Vs, Dmi)
    w[1] = _clamp(mu - dPsi_dJ * s[0], project)
    B[2] = _mode3(U, wp.mat33d(zero, zero, h, zero, zero, zero, -h, zero, zero), Vs, Dmi)
    w[2] = _clamp(mu + dPsi_dJ * s[1], project)
    B[3] = _mode3(U, wp.mat33d(zero, zero, h, zero, zero, zero, h, zero, zero), Vs, Dmi)
    w[3] = _clamp(mu - dPsi_dJ * s[1], project)
    B[4] = _mode3(U, wp.mat33d(zero, -h, zero, h, zero, zero, zero, zero, zero), Vs, Dmi)
    w[4] = _clamp(mu + dPsi_dJ * s[2], project)
    B[5] = _mode3(U, wp.mat33d(zero, h, zero, h, zero, zero, zero, zero, zero), Vs, Dmi)
    w[5] = _clamp(mu - dPsi_dJ * s[2], project)
    # scaling modes: the Hessian of Psi in the singular values,
    #   A = mu I + (mu - lam log J) diag(1/s^2) + lam t t^T,  t = 1/s,
    # acting on the modes U diag(e_i) V^T. When dPsi/dJ <= 0 (i.e. lam log J <= mu: everything
    # but strong volumetric expansion) every term is PSD and mu I > 0, so A is positive definite
    # and is used as is through its Cholesky factor (cheaper than an eigensolve); otherwise A is
    # diagonalized and its eigenvalues clamped.
    cs = mu + lam * (wp.float64(1.0) - logJ)
    A = wp.mat33d(
        mu + cs / (s[0] * s[0]), lam / (s[0] * s[1]), lam / (s[0] * s[2]),
        lam / (s[0] * s[1]), mu + cs / (s[1] * s[1]), lam / (s[1] * s[2]),
        lam / (s[0] * s[2]), lam / (s[1] * s[2]), mu + cs / (s[2] * s[2]),
    )
    if dPsi_dJ <= zero:
        b0 = _mode3(U, wp.diag(wp.vec3d(wp.float64(1.0), zero, zero)), Vs, Dmi)
        b1 = _mode3(U, wp.diag(wp.vec3d(zero, wp.float64(1.0), zero)), Vs, Dmi)
        b2 = _mode3(U, wp.diag(wp.vec3d(zero, zero, wp.float64(1.0))), Vs, Dmi)
        L = _cholesky3(A)  # sum_ij A_ij b_i b_j^T = sum_k c_k c_k^T, c_k = sum_i L_ik b_i
        B[6] = L[0, 0] * b0 + L[1, 0] * b1 + L[2, 0] * b2
        B[7] = L[1, 1] * b1 + L[2, 1] * b2
        B[8] = L[2, 2] * b2
        w[6] = wp.float64(1.0)
        w[7] = wp.float64(1.0)
        w[8] = wp.float64(1.0)
    else:
        Q = wp.mat33d()
        d = wp.vec3d()
        wp.eig3(A, Q, d)
        for k in range(3):
            B[6 + k] = _mode3(U, wp.diag(wp.vec3d(Q[0, k], Q[1, k], Q[2, k])), Vs, Dmi)
            w[6 + k] = _clamp(d[k], project)
    # H_e = V sum_k w_k b_k b_k^T  (symmetric: compute the upper triangle, mirror)
    for r in range(12):
        for c in range(r, 12):
            acc = zero
            for k in range(9):
                acc += w[k] * B[k, r] * B[k, c]
            _store(scatter, slots, hess, data, e, r, c, V * acc)


# ----------------------------------------------------------------------------------------------
# 2D (plane strain)
# ----------------------------------------------------------------------------------------------
@wp.func
def _F2(x: wp.array(dtype=wp.vec2d), elements: wp.array2d(dtype=wp.int32), Dm_inv: wp.array(dtype=wp.mat22d), e: int):
    x0 = x[elements[e, 0]]
    Ds = wp.matrix_from_cols(x[elements[e, 1]] - x0, x[elements[e, 2]] - x0)
    return Ds * Dm_inv[e]


@wp.func
def _nodal2(M: wp.mat22d, Dmi: wp.mat22d):
    W = M * wp.transpose(Dmi)
    b = _vec6d()
    for a in range(2):
        b[2 + a] = W[a, 0]
        b[4 + a] = W[a, 1]
        b[a] = -(W[a, 0] + W[a, 1])
    return b


@wp.func
def _mode2(U: wp.mat22d, M: wp.mat22d, V: wp.mat22d, Dmi: wp.mat22d):
    return _nodal2(U * M * wp.transpose(V), Dmi)


@wp.kernel
def _energy2(x: wp.array(dtype=wp.vec2d), elements: wp.array2d(dtype=wp.int32), Dm_inv: wp.array(dtype=wp.mat22d),
             volume: wp.array(dtype=wp.float64), mu: wp.array(dtype=wp.float64), lam: wp.array(dtype=wp.float64),
             energy: wp.array(dtype=wp.float64), det_F: wp.array(dtype=wp.float64)):
    e = wp.tid()
    F = _F2(x, elements, Dm_inv, e)
    J = wp.determinant(F)
    det_F[e] = J
    energy[e] = wp.float64(0.0)
    if J > wp.float64(0.0):
        energy[e] = volume[e] * _psi(F, J, mu[e], lam[e], wp.float64(2.0))


@wp.kernel
def _gradient2(x: wp.array(dtype=wp.vec2d), elements: wp.array2d(dtype=wp.int32), Dm_inv: wp.array(dtype=wp.mat22d),
               volume: wp.array(dtype=wp.float64), mu: wp.array(dtype=wp.float64), lam: wp.array(dtype=wp.float64),
               energy: wp.array(dtype=wp.float64), det_F: wp.array(dtype=wp.float64), grad: wp.array(dtype=_vec6d)):
    e = wp.tid()
    F = _F2(x, elements, Dm_inv, e)
    J = wp.determinant(F)
    det_F[e] = J
    energy[e] = wp.float64(0.0)
    grad[e] = _vec6d()
    if J > wp.float64(0.0):
        energy[e] = volume[e] * _psi(F, J, mu[e], lam[e], wp.float64(2.0))
        grad[e] = volume[e] * _nodal2(_pk1(F, J, mu[e], lam[e]), Dm_inv[e])


@wp.kernel
def _hessian2(x: wp.array(dtype=wp.vec2d), elements: wp.array2d(dtype=wp.int32), Dm_inv: wp.array(dtype=wp.mat22d),
              volume: wp.array(dtype=wp.float64), mu_e: wp.array(dtype=wp.float64), lam_e: wp.array(dtype=wp.float64),
              project: int, scatter: int, slots: wp.array3d(dtype=wp.int32),
              energy: wp.array(dtype=wp.float64), det_F: wp.array(dtype=wp.float64), grad: wp.array(dtype=_vec6d),
              hess: wp.array3d(dtype=wp.float64), data: wp.array(dtype=wp.float64)):
    e = wp.tid()
    F = _F2(x, elements, Dm_inv, e)
    J = wp.determinant(F)
    det_F[e] = J
    zero = wp.float64(0.0)
    energy[e] = zero
    grad[e] = _vec6d()
    if J <= zero:
        if scatter == 0:
            for r in range(6):
                for c in range(6):
                    hess[e, r, c] = zero
        return
    V = volume[e]
    mu = mu_e[e]
    lam = lam_e[e]
    Dmi = Dm_inv[e]
    energy[e] = V * _psi(F, J, mu, lam, wp.float64(2.0))
    grad[e] = V * _nodal2(_pk1(F, J, mu, lam), Dmi)

    U = wp.mat22d()
    s = wp.vec2d()
    Vs = wp.mat22d()
    wp.svd2(F, U, s, Vs)
    logJ = wp.log(J)
    dPsi_dJ = (lam * logJ - mu) / J
    h = wp.float64(_HALF_SQRT2)
    B = _mat4x6d()
    w = _vec4d()
    B[0] = _mode2(U, wp.mat22d(zero, -h, h, zero), Vs, Dmi)  # twist
    w[0] = _clamp(mu + dPsi_dJ, project)
    B[1] = _mode2(U, wp.mat22d(zero, h, h, zero), Vs, Dmi)  # flip
    w[1] = _clamp(mu - dPsi_dJ, project)
    # scaling modes: closed-form eigensystem of the symmetric 2x2 [[a, o], [o, c2]]
    cs = mu + lam * (wp.float64(1.0) - logJ)
    a = mu + cs / (s[0] * s[0])
    c2 = mu + cs / (s[1] * s[1])
    o = lam / (s[0] * s[1])
    theta = wp.float64(0.5) * wp.atan2(wp.float64(2.0) * o, a - c2)
    ct = wp.cos(theta)
    st = wp.sin(theta)
    B[2] = _mode2(U, wp.mat22d(ct, zero, zero, st), Vs, Dmi)
    w[2] = _clamp(a * ct * ct + wp.float64(2.0) * o * st * ct + c2 * st * st, project)
    B[3] = _mode2(U, wp.mat22d(-st, zero, zero, ct), Vs, Dmi)
    w[3] = _clamp(a * st * st - wp.float64(2.0) * o * st * ct + c2 * ct * ct, project)
    for r in range(6):
        for c in range(r, 6):
            acc = zero
            for k in range(4):
                acc += w[k] * B[k, r] * B[k, c]
            _store(scatter, slots, hess, data, e, r, c, V * acc)


# ----------------------------------------------------------------------------------------------
# host side
# ----------------------------------------------------------------------------------------------
_ENERGY, _GRADIENT, _HESSIAN, _BLOCKS = 0, 1, 2, 3  # what a launch computes
_KERNELS = {2: (_energy2, _gradient2, _hessian2), 3: (_energy3, _gradient3, _hessian3)}


class _Workspace:
    """Device copies of the model arrays and reusable output buffers (per model)."""

    def __init__(self, model: FemModel):
        d, m, k = model.dim, model.n_elements, model.dim + 1
        dev = model.device
        self.vec = wp.vec3d if d == 3 else wp.vec2d
        mat = wp.mat33d if d == 3 else wp.mat22d
        self.kernels = _KERNELS[d]
        self.elements = wp.array(model.elements, dtype=wp.int32, device=dev)
        self.Dm_inv = wp.array(model.Dm_inv, dtype=mat, device=dev)
        self.volume = wp.array(model.volume, dtype=wp.float64, device=dev)
        self.mu = wp.array(model.mu, dtype=wp.float64, device=dev)
        self.lam = wp.array(model.lam, dtype=wp.float64, device=dev)
        self.energy = wp.zeros(m, dtype=wp.float64, device=dev)
        self.det_F = wp.zeros(m, dtype=wp.float64, device=dev)
        self.grad = wp.zeros(m, dtype=_vec12d if d == 3 else _vec6d, device=dev)
        self.hess = None  # element blocks (m, k*d, k*d) float64, allocated on first element_hessians()
        self.slots = None  # model.pattern.element_slots as int32, on first Hessian request
        self.dummy3 = wp.zeros((1, 1, 1), dtype=wp.float64, device=dev)
        self.dummy_slots = wp.zeros((1, 1, 1), dtype=wp.int32, device=dev)
        # gradient scatter: (n*d, m*k*d) sparse sum over the element copies of each dof
        dofs = (model.elements.astype(np.int64)[:, :, None] * d + np.arange(d)).ravel()
        self.scatter = sp.csr_matrix((np.ones(dofs.size), (dofs, np.arange(dofs.size))),
                                     shape=(model.n_dofs, dofs.size))


def _workspace(model: FemModel) -> _Workspace:
    ws = model._cache.get("neohookean")
    if ws is None:
        ws = model._cache["neohookean"] = _Workspace(model)
    return ws


def _launch(model: FemModel, x, want: int, project: bool = True) -> _Workspace:
    """One kernel launch over all elements computing what ``want`` asks for."""
    x = model.check_positions(x)
    ws = _workspace(model)
    dev = model.device
    common = [wp.array(x, dtype=ws.vec, device=dev), ws.elements, ws.Dm_inv, ws.volume, ws.mu, ws.lam]
    if want == _ENERGY:
        wp.launch(ws.kernels[0], dim=model.n_elements, inputs=common, outputs=[ws.energy, ws.det_F], device=dev)
    elif want == _GRADIENT:
        wp.launch(ws.kernels[1], dim=model.n_elements, inputs=common, outputs=[ws.energy, ws.det_F, ws.grad],
                  device=dev)
    else:
        # _HESSIAN: scatter straight into CSR values; _BLOCKS: keep the per-element blocks
        scatter = want == _HESSIAN
        if scatter and ws.slots is None:
            if model.pattern.nnz >= 2**31:
                raise ValueError("Hessian too large for int32 slots")
            ws.slots = wp.array(model.pattern.element_slots.astype(np.int32), dtype=wp.int32, device=dev)
        if not scatter and ws.hess is None:
            k = (model.dim + 1) * model.dim
            ws.hess = wp.zeros((model.n_elements, k, k), dtype=wp.float64, device=dev)
        # a fresh values array per call (callers keep and modify returned matrices); on the CPU
        # numpy owns it and the kernel writes through an alias, so no copy is made
        data_np = np.zeros(model.pattern.nnz if scatter else 1)
        data = wp.array(data_np, dtype=wp.float64, device=dev, copy=False) if wp.get_device(dev).is_cpu \
            else wp.array(data_np, dtype=wp.float64, device=dev)
        wp.launch(ws.kernels[2], dim=model.n_elements,
                  inputs=common + [int(bool(project)), int(scatter), ws.slots if scatter else ws.dummy_slots],
                  outputs=[ws.energy, ws.det_F, ws.grad, ws.dummy3 if scatter else ws.hess, data], device=dev)
        ws.data = data
        ws.data_np = data_np
    return ws


def _total(ws: _Workspace) -> float:
    if np.any(ws.det_F.numpy() <= 0.0):
        return float("inf")
    return float(np.sum(ws.energy.numpy()))


def _gradient(model: FemModel, ws: _Workspace) -> np.ndarray:
    return (ws.scatter @ ws.grad.numpy().reshape(-1)).reshape(model.n_vertices, model.dim)


def energy(model: FemModel, x) -> float:
    """Elastic energy [J] at positions x (n, dim) [m]; +inf if any element has det F <= 0."""
    return _total(_launch(model, x, _ENERGY, False))


def energy_gradient(model: FemModel, x) -> tuple[float, np.ndarray]:
    """(energy [J], gradient dE/dx (n, dim) [N]). The elastic nodal force is ``-gradient``."""
    ws = _launch(model, x, _GRADIENT, False)
    return _total(ws), _gradient(model, ws)


def element_hessians(model: FemModel, x, *, project_psd: bool = True) -> np.ndarray:
    """Per-element Hessian blocks (m, (dim+1)*dim, (dim+1)*dim) [N/m], dofs ordered (vertex, axis)."""
    ws = _launch(model, x, _BLOCKS, project_psd)
    return ws.hess.numpy().copy()


def energy_gradient_hessian(model: FemModel, x, *, project_psd: bool = True) -> tuple[float, np.ndarray, sp.csr_matrix]:
    """(energy [J], gradient (n, dim) [N], Hessian (n*dim, n*dim) CSR [N/m]).

    With ``project_psd`` (default) every element block is projected to positive semi-definite
    (clamped eigenvalues of d2Psi/dF2), so the assembled Hessian is PSD; otherwise it is the
    exact Hessian. The CSR has the model's fixed pattern (``model.pattern``); its ``data`` is a
    fresh array the caller may modify (e.g. add contact blocks via ``pattern.block_slots``).
    """
    ws = _launch(model, x, _HESSIAN, project_psd)
    data = ws.data_np if wp.get_device(model.device).is_cpu else ws.data.numpy()
    H = model.pattern.matrix(data)
    return _total(ws), _gradient(model, ws), H


def det_F(model: FemModel, x) -> np.ndarray:
    """det F per element (m,) at positions x (n, dim); <= 0 means inverted or degenerate."""
    return _launch(model, x, _ENERGY, False).det_F.numpy().copy()
