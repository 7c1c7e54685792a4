"""Compressible Neo-Hookean elasticity on quadratic (P2) simplices: the Warp kernels (energy,
gradient, Hessian side by side) and their :data:`QUADRATIC` record; the public functions that
launch them, for every element order, are in :mod:`simfab.fem.elastic`.

Same energy density as :mod:`simfab.fem.neohookean`, but F varies linearly over a P2 element, so
the element energy is a quadrature sum over the points q of the model's rule
(:data:`simfab.fem.p2.RULES`, weights w_q = volume * rule weight):

    E_e = sum_q w_q Psi(F_q),    F_q = sum_a x_a (x) g_qa,    g_qa = grad N_a(X_q)
    dE/dx_a = sum_q w_q P(F_q) g_qa
    K_ab[i, j] = sum_q w_q sum_{k,l} A_q[(i,k), (j,l)] g_qa[k] g_qb[l],   A = d2Psi/dF2

PSD projection clamps the negative eigenvalues of each A_q (positive weights keep the sum PSD),
with the analytic eigensystem of :mod:`simfab.fem.neohookean`. The energy is +inf when J <= 0 at
any quadrature point (:func:`simfab.fem.p2.det_F_lower_bound` bounds det F over whole elements).
Kernels run in float64 with one thread per element and the quadrature loop inside; on the CPU a
mesh of :data:`SPLIT_ELEMENTS` or more runs its Hessian as two launches on two threads. The
closed forms of each block: docs/methods.md, "simfab.fem.neohookean_p2".
"""

from __future__ import annotations

from typing import Any

import numpy as np

from simfab._warp import wp
from simfab.fem.neohookean import (
    HESSIAN_BOTH,
    HESSIAN_EXACT,
    HESSIAN_PROJECT,
    HESSIAN_PROJECT_SVD,
    dim_float,
    dim_int,
    mat44d,
    mat99d,
    negative_part_sym3,
    pk1,
    polar_rotation3,
    psi,
    store_hessian_entry,
    stress_hessian_svd,
    void_element,
)
from simfab.fem.workspace import ElementKernels

wp.set_module_options({"enable_backward": False})

_vec12d = wp.types.vector(length=12, dtype=wp.float64)
_vec30d = wp.types.vector(length=30, dtype=wp.float64)
_mat12d = wp.types.matrix(shape=(12, 12), dtype=wp.float64)
_mat30d = wp.types.matrix(shape=(30, 30), dtype=wp.float64)


# ----------------------------------------------------------------------------------------------
# per-dimension helpers (Warp overloads on the matrix type)
# ----------------------------------------------------------------------------------------------
@wp.func
def _F_at(x: wp.array(dtype=wp.vec3d), elements: wp.array2d(dtype=wp.int32), gN: wp.array3d(dtype=wp.vec3d),
          e: int, q: int):
    """F at quadrature point q of element e: sum_a x_a (x) g_qa."""
    F = wp.mat33d()
    for a in range(elements.shape[1]):
        F += wp.outer(x[elements[e, a]], gN[e, q, a])
    return F


@wp.func
def _F_at(x: wp.array(dtype=wp.vec2d), elements: wp.array2d(dtype=wp.int32),  # noqa: F811
          gN: wp.array3d(dtype=wp.vec2d), e: int, q: int):
    F = wp.mat22d()
    for a in range(elements.shape[1]):
        F += wp.outer(x[elements[e, a]], gN[e, q, a])
    return F


@wp.func
def _zero_hess(F: wp.mat33d):
    return _mat30d()


@wp.func
def _zero_hess(F: wp.mat22d):  # noqa: F811
    return _mat12d()


@wp.func
def _add_svd_route(K: Any, A: Any, gN: wp.array3d(dtype=Any), e: int, q: int, d: int, w: wp.float64):
    """K + w G_q^T A G_q for a full stress Hessian A (d^2 x d^2): the rare dPsi/dJ > 0 route."""
    Kn = K
    k = gN.shape[2]
    for a in range(k):
        ga = gN[e, q, a]
        for b in range(a, k):
            gb = gN[e, q, b]
            for i in range(d):
                for j in range(d):
                    acc = wp.float64(0.0)
                    for kk in range(d):
                        for l in range(d):
                            acc += A[d * i + kk, d * j + l] * ga[kk] * gb[l]
                    Kn[d * a + i, d * b + j] = Kn[d * a + i, d * b + j] + w * acc
    return Kn


@wp.func
def _add_qp_hessian(K: _mat30d, F: wp.mat33d, J: wp.float64, mu: wp.float64, lam: wp.float64, w: wp.float64,
                    mode: int, gN: wp.array3d(dtype=wp.vec3d), e: int, q: int):
    """K + w * (quadrature point q's Hessian) in the blocks b >= a (10-node tet, 3D).

    Exact block (a, b): mu (g_a . g_b) I + d2Psi/dJ2 gamma_a gamma_b^T - dPsi/dJ [F (g_a x g_b)]x,
    gamma_a = cof(F) g_a (from d2J/dF_ik dF_jl = eps_ijm eps_klp F_mp contracted with g_a, g_b).
    Projection with dPsi/dJ <= 0: minus 1/2 P_a N P_b^T, P_a = R [g_a]x = [R g_a]x R (the twist
    modes R [e_i]x / sqrt 2 seen at node a; N the negative part of T = mu I + dPsi/dJ S), as
    in the linear kernel's direct route. With dPsi/dJ > 0 (or HESSIAN_PROJECT_SVD): the SVD eigensystem.
    """
    logJ = wp.log(J)
    dPsi_dJ = (lam * logJ - mu) / J
    if mode == HESSIAN_PROJECT_SVD or (mode == HESSIAN_PROJECT and dPsi_dJ > wp.float64(0.0)):
        return _add_svd_route(K, stress_hessian_svd(F, J, mu, lam), gN, e, q, 3, w)
    d2 = (mu + lam * (wp.float64(1.0) - logJ)) / (J * J)
    I = wp.identity(n=3, dtype=wp.float64)
    cof = J * wp.transpose(wp.inverse(F))
    project = 0
    R = I
    Nt = wp.mat33d()
    if mode == HESSIAN_PROJECT:
        R = polar_rotation3(F)
        S = wp.transpose(R) * F
        S = wp.float64(0.5) * (S + wp.transpose(S))
        N = negative_part_sym3(mu * I + dPsi_dJ * S)
        if wp.ddot(N, N) > wp.float64(0.0):
            project = 1
            Nt = wp.float64(0.5) * w * (R * N * wp.transpose(R))
    Kn = K
    k = gN.shape[2]
    wmu = w * mu
    wdJ = w * dPsi_dJ
    for a in range(k):
        ga = gN[e, q, a]
        ca = (w * d2) * (cof * ga)
        RaN = wp.skew(R * ga) * Nt
        for b in range(a, k):
            gb = gN[e, q, b]
            B = (wmu * wp.dot(ga, gb)) * I + wp.outer(ca, cof * gb) - wdJ * wp.skew(F * wp.cross(ga, gb))
            if project != 0:
                B = B + RaN * wp.skew(R * gb)  # - [R g_a]x Nt [R g_b]x^T, [v]x^T = -[v]x
            for i in range(3):
                for j in range(3):
                    Kn[3 * a + i, 3 * b + j] = Kn[3 * a + i, 3 * b + j] + B[i, j]
    return Kn


@wp.func
def _add_qp_hessian(K: _mat12d, F: wp.mat22d, J: wp.float64, mu: wp.float64, lam: wp.float64,  # noqa: F811
                    w: wp.float64, mode: int, gN: wp.array3d(dtype=wp.vec2d), e: int, q: int):
    """2D (6-node triangle): exact block mu (g_a . g_b) I + d2Psi/dJ2 gamma_a gamma_b^T +
    dPsi/dJ (g_a x g_b) [[0, 1], [-1, 0]] (d2J/dF_ik dF_jl = eps_ij eps_kl); projection with
    dPsi/dJ <= 0 removes the twist mode R [[0, -1], [1, 0]] / sqrt 2 when t = mu + dPsi/dJ < 0:
    minus t/2 (RJ g_a)(RJ g_b)^T."""
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    logJ = wp.log(J)
    dPsi_dJ = (lam * logJ - mu) / J
    if mode == HESSIAN_PROJECT_SVD or (mode == HESSIAN_PROJECT and dPsi_dJ > zero):
        return _add_svd_route(K, stress_hessian_svd(F, J, mu, lam), gN, e, q, 2, w)
    d2 = (mu + lam * (one - logJ)) / (J * J)
    I = wp.identity(n=2, dtype=wp.float64)
    E2 = wp.mat22d(zero, one, -one, zero)
    cof = J * wp.transpose(wp.inverse(F))
    t = mu + dPsi_dJ
    project = 0
    RJ = wp.mat22d()
    if mode == HESSIAN_PROJECT and t < zero:
        project = 1
        cr = F[0, 0] + F[1, 1]
        sr = F[1, 0] - F[0, 1]
        RJ = wp.mat22d(-sr, -cr, cr, -sr) / wp.sqrt(cr * cr + sr * sr)
    Kn = K
    k = gN.shape[2]
    for a in range(k):
        ga = gN[e, q, a]
        ca = w * (cof * ga)
        ra = RJ * ga
        for b in range(a, k):
            gb = gN[e, q, b]
            B = (w * mu * wp.dot(ga, gb)) * I + d2 * wp.outer(ca, cof * gb) + (
                w * dPsi_dJ * (ga[0] * gb[1] - ga[1] * gb[0])) * E2
            if project != 0:
                B = B - (wp.float64(0.5) * w * t) * wp.outer(ra, RJ * gb)
            for i in range(2):
                for j in range(2):
                    Kn[2 * a + i, 2 * b + j] = Kn[2 * a + i, 2 * b + j] + B[i, j]
    return Kn


# ----------------------------------------------------------------------------------------------
# kernels (generic over the dimension; explicit overloads below)
# ----------------------------------------------------------------------------------------------
@wp.kernel
def _energy_kernel(first: int, x: wp.array(dtype=Any), elements: wp.array2d(dtype=wp.int32), gN: wp.array3d(dtype=Any),
                   wq: wp.array2d(dtype=wp.float64), mu: wp.array(dtype=wp.float64), lam: wp.array(dtype=wp.float64),
                   energy: wp.array(dtype=wp.float64), det_F: wp.array(dtype=wp.float64)):
    e = first + wp.tid()  # this launch's part of the elements
    E = wp.float64(0.0)
    Jmin = wp.float64(wp.inf)
    for q in range(wq.shape[1]):
        F = _F_at(x, elements, gN, e, q)
        J = wp.determinant(F)
        Jmin = wp.min(Jmin, J)
        if J > wp.float64(0.0):
            E += wq[e, q] * psi(F, J, mu[e], lam[e], dim_float(F))
    det_F[e] = Jmin
    energy[e] = wp.where(Jmin > wp.float64(0.0), E, wp.float64(0.0))


@wp.kernel
def _gradient_kernel(first: int, x: wp.array(dtype=Any), elements: wp.array2d(dtype=wp.int32),
                     gN: wp.array3d(dtype=Any), wq: wp.array2d(dtype=wp.float64), mu: wp.array(dtype=wp.float64),
                     lam: wp.array(dtype=wp.float64), energy: wp.array(dtype=wp.float64),
                     det_F: wp.array(dtype=wp.float64), grad: wp.array(dtype=Any)):
    e = first + wp.tid()  # this launch's part of the elements
    E = wp.float64(0.0)
    Jmin = wp.float64(wp.inf)
    g = grad.dtype()
    k = elements.shape[1]
    for q in range(wq.shape[1]):
        F = _F_at(x, elements, gN, e, q)
        J = wp.determinant(F)
        Jmin = wp.min(Jmin, J)
        if J > wp.float64(0.0):
            w = wq[e, q]
            E += w * psi(F, J, mu[e], lam[e], dim_float(F))
            P = pk1(F, J, mu[e], lam[e])
            d = dim_int(F)
            for a in range(k):
                f = w * (P * gN[e, q, a])
                for i in range(d):
                    g[d * a + i] = g[d * a + i] + f[i]
    det_F[e] = Jmin
    energy[e] = wp.float64(0.0)
    grad[e] = grad.dtype()
    if Jmin > wp.float64(0.0):
        energy[e] = E
        grad[e] = g


@wp.kernel
def _hessian_kernel(first: int, x: wp.array(dtype=Any), elements: wp.array2d(dtype=wp.int32), gN: wp.array3d(dtype=Any),
                    wq: wp.array2d(dtype=wp.float64), mu_e: wp.array(dtype=wp.float64),
                    lam_e: wp.array(dtype=wp.float64), project: int, scatter: int, slots: wp.array3d(dtype=wp.int32),
                    energy: wp.array(dtype=wp.float64), det_F: wp.array(dtype=wp.float64), grad: wp.array(dtype=Any),
                    hess: wp.array3d(dtype=wp.float64), data: wp.array(dtype=wp.float64),
                    data2: wp.array(dtype=wp.float64)):
    e = first + wp.tid()  # this launch's part of the elements
    zero = wp.float64(0.0)
    k = elements.shape[1]
    nq = wq.shape[1]
    mu = mu_e[e]
    lam = lam_e[e]
    # first pass: det F at every quadrature point (an inverted point voids the whole element)
    Jmin = wp.float64(wp.inf)
    for q in range(nq):
        Jmin = wp.min(Jmin, wp.determinant(_F_at(x, elements, gN, e, q)))
    det_F[e] = Jmin
    if Jmin <= zero:
        void_element(e, scatter, energy, grad, hess)
        return
    mode = project
    both = 0
    if mode == HESSIAN_BOTH:
        mode = HESSIAN_PROJECT
        both = 1
    E = zero
    g = grad.dtype()
    F0 = _F_at(x, elements, gN, e, 0)
    K = _zero_hess(F0)
    K2 = _zero_hess(F0)
    for q in range(nq):
        F = _F_at(x, elements, gN, e, q)
        J = wp.determinant(F)
        w = wq[e, q]
        E += w * psi(F, J, mu, lam, dim_float(F))
        P = pk1(F, J, mu, lam)
        d = dim_int(F)
        for a in range(k):
            f = w * (P * gN[e, q, a])
            for i in range(d):
                g[d * a + i] = g[d * a + i] + f[i]
        if both != 0:  # exact Hessian into K2
            K2 = _add_qp_hessian(K2, F, J, mu, lam, w, HESSIAN_EXACT, gN, e, q)
        K = _add_qp_hessian(K, F, J, mu, lam, w, mode, gN, e, q)
    energy[e] = E
    grad[e] = g
    kd = k * dim_int(F0)
    for r in range(kd):
        for c in range(r, kd):
            if both != 0:  # exact into data, projected into data2
                store_hessian_entry(scatter, slots, hess, data, e, r, c, K2[r, c])
                store_hessian_entry(scatter, slots, hess, data2, e, r, c, K[r, c])
            else:
                store_hessian_entry(scatter, slots, hess, data, e, r, c, K[r, c])


@wp.kernel
def _stress_kernel(first: int, x: wp.array(dtype=Any), elements: wp.array2d(dtype=wp.int32),
                   gN: wp.array3d(dtype=Any), wq: wp.array2d(dtype=wp.float64), mu_e: wp.array(dtype=wp.float64),
                   lam_e: wp.array(dtype=wp.float64), det_F: wp.array(dtype=wp.float64),
                   von_mises: wp.array(dtype=wp.float64)):
    """min det F and max von Mises sqrt(3/2) mu |dev(F F^T - I)| / J over the quadrature points
    (see simfab.fem.elastic.det_and_von_mises); +inf stress where any det F <= 0."""
    e = first + wp.tid()  # this launch's part of the elements
    Jmin = wp.float64(wp.inf)
    vm = wp.float64(0.0)
    for q in range(wq.shape[1]):
        F = _F_at(x, elements, gN, e, q)
        J = wp.determinant(F)
        Jmin = wp.min(Jmin, J)
        if J > wp.float64(0.0):
            C = F * wp.transpose(F)
            for i in range(dim_int(F)):
                C[i, i] = C[i, i] - wp.float64(1.0)
            tr = wp.trace(C)
            dev2 = wp.max(wp.ddot(C, C) - tr * tr / wp.float64(3.0), wp.float64(0.0))
            vm = wp.max(vm, wp.sqrt(wp.float64(1.5) * dev2) * mu_e[e] / J)
    det_F[e] = Jmin
    von_mises[e] = wp.where(Jmin > wp.float64(0.0), vm, wp.float64(wp.inf))


@wp.kernel
def _stress_hessian_kernel(F: wp.array(dtype=Any), J: wp.array(dtype=wp.float64), mu: wp.float64, lam: wp.float64,
                           out: wp.array(dtype=Any)):
    """PSD-projected d2Psi/dF2 from the SVD eigensystem, for a batch of F (tests)."""
    t = wp.tid()
    out[t] = stress_hessian_svd(F[t], J[t], mu, lam)


def _declare_overloads():
    for vec, mat, gvec, amat in ((wp.vec2d, wp.mat22d, _vec12d, mat44d), (wp.vec3d, wp.mat33d, _vec30d, mat99d)):
        types = {"x": wp.array(dtype=vec), "gN": wp.array3d(dtype=vec)}
        wp.overload(_energy_kernel, types)
        wp.overload(_stress_kernel, types)
        wp.overload(_gradient_kernel, {**types, "grad": wp.array(dtype=gvec)})
        wp.overload(_hessian_kernel, {**types, "grad": wp.array(dtype=gvec)})
        wp.overload(_stress_hessian_kernel, {"F": wp.array(dtype=mat), "out": wp.array(dtype=amat)})


_declare_overloads()

# ----------------------------------------------------------------------------------------------
# the element order's record for simfab.fem.workspace, and the batched stress Hessian
# ----------------------------------------------------------------------------------------------
#: Meshes with at least this many elements (by dimension) launch their Hessians in two halves on two
#: threads on the CPU: handing a launch to the second thread costs about as much as a few 10-node tet
#: Hessians, so smaller meshes stay one launch. A 6-node triangle's Hessian is 12 x 12 against a
#: tet's 30 x 30 (~1/6 of the work): a 455-triangle mesh runs each launch faster on one thread.
SPLIT_ELEMENTS = {2: 2048, 3: 256}

#: Quadratic simplices: ``model.element_geometry()`` is (grad_N (m, nq, k, d), qp_weight (m, nq)).
QUADRATIC = ElementKernels(energy=_energy_kernel, gradient=_gradient_kernel, hessian=_hessian_kernel,
                           stress=_stress_kernel, grad_dtype={2: _vec12d, 3: _vec30d},
                           geometry_dtype={2: wp.vec2d, 3: wp.vec3d}, split_elements=SPLIT_ELEMENTS)


def projected_stress_hessian(F, mu: float, lam: float) -> np.ndarray:
    """d2Psi/dF2 with clamped eigenvalues (b, d^2, d^2) [Pa] for a batch of deformation gradients
    F (b, d, d) with det F > 0 (vec(F) row-major), from the analytic eigensystem the kernels use
    on their SVD route (one launch, CPU)."""
    F = np.ascontiguousarray(F, dtype=np.float64)
    d = F.shape[-1]
    mat, amat = (wp.mat33d, mat99d) if d == 3 else (wp.mat22d, mat44d)
    out = wp.zeros(F.shape[0], dtype=amat, device="cpu")
    wp.launch(_stress_hessian_kernel, dim=F.shape[0], device="cpu",
              inputs=[wp.array(F, dtype=mat, device="cpu"), wp.array(np.linalg.det(F), dtype=wp.float64, device="cpu"),
                      wp.float64(mu), wp.float64(lam)], outputs=[out])
    return out.numpy()
