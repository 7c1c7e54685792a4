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
_vec6d = wp.types.vector(length=6, dtype=wp.float64)
_vec10d = wp.types.vector(length=10, dtype=wp.float64)
_mat6x2d = wp.types.matrix(shape=(6, 2), dtype=wp.float64)  # a vector per node
_mat10x3d = wp.types.matrix(shape=(10, 3), dtype=wp.float64)

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
def _scratch(g: wp.vec3d):
    """The Hessian kernel's zeroed locals, chosen by the type of g (a shape gradient): two element matrices
    (30 x 30), two tables with a vector per node (10 x 3), and a vector whose length, the node count (10),
    is a compile-time constant in the kernel (10-node tet)."""
    return _mat30d(), _mat30d(), _mat10x3d(), _mat10x3d(), _vec10d()


@wp.func
def _scratch(g: wp.vec2d):  # noqa: F811
    """6-node triangle: 12 x 12, 6 x 2, length 6."""
    return _mat12d(), _mat12d(), _mat6x2d(), _mat6x2d(), _vec6d()


@wp.func
def _det_factor(wdJ: wp.float64, J: wp.float64, g: wp.vec3d):
    """The point's factor t of _det_term from wdJ = w dPsi/dJ (g: a shape gradient, for the overload):
    wdJ / J (10-node tet)."""
    return wdJ / J


@wp.func
def _det_factor(wdJ: wp.float64, J: wp.float64, g: wp.vec2d):  # noqa: F811
    """6-node triangle: wdJ."""
    return wdJ


@wp.func
def _det_term(ga: wp.vec3d, gb: wp.vec3d, ca: wp.vec3d, cb: wp.vec3d, t: wp.float64):
    """w dPsi/dJ F (g_a x g_b), the vector of the block's det term -[.]x (10-node tet), as t (gamma_a x
    gamma_b) with gamma = cof(F) g, t = w dPsi/dJ / J: (A u) x (A v) = cof(A) (u x v) with A = cof F, and
    cof(cof F) = J F (the gammas are already at hand, F (g_a x g_b) would cost a cross and a product)."""
    return t * wp.cross(ca, cb)


@wp.func
def _det_term(ga: wp.vec2d, gb: wp.vec2d, ca: wp.vec2d, cb: wp.vec2d, t: wp.float64):  # noqa: F811
    """2D: w dPsi/dJ (g_a x g_b), t = w dPsi/dJ."""
    return t * (ga[0] * gb[1] - ga[1] * gb[0])


@wp.func
def _block(X: wp.mat33d, m: wp.float64, v: wp.vec3d):
    """w times the exact block (a, b) at a point (10-node tet), mu (g_a . g_b) I + d2Psi/dJ2 gamma_a gamma_b^T
    - dPsi/dJ [F (g_a x g_b)]x (gamma = cof(F) g; d2J/dF_ik dF_jl = eps_ijm eps_klp F_mp contracted with
    g_a, g_b), from its parts X = w d2Psi/dJ2 gamma_a gamma_b^T, m = w mu (g_a . g_b), v = _det_term:
    X + m I - [v]x."""
    return wp.mat33d(X[0, 0] + m, X[0, 1] + v[2], X[0, 2] - v[1],
                     X[1, 0] - v[2], X[1, 1] + m, X[1, 2] + v[0],
                     X[2, 0] + v[1], X[2, 1] - v[0], X[2, 2] + m)


@wp.func
def _block(X: wp.mat22d, m: wp.float64, v: wp.float64):  # noqa: F811
    """6-node triangle: mu (g_a . g_b) I + d2Psi/dJ2 gamma_a gamma_b^T + dPsi/dJ (g_a x g_b) [[0, 1], [-1, 0]]
    (d2J/dF_ik dF_jl = eps_ij eps_kl), times w: X + m I + v [[0, 1], [-1, 0]], v = _det_term."""
    return wp.mat22d(X[0, 0] + m, X[0, 1] + v, X[1, 0] - v, X[1, 1] + m)


@wp.func
def _svd_block(A: Any, ga: Any, gb: Any, w: wp.float64):
    """w G_a^T A G_b for the SVD-rebuilt stress Hessian A (d^2 x d^2), entry (i, j) =
    w sum_{k,l} A[(i,k), (j,l)] g_a[k] g_b[l]: the rare dPsi/dJ > 0 route (every dimension: d = len(g_a))."""
    d = len(ga)
    B = wp.float64(0.0) * wp.outer(ga, gb)  # (a zero d x d matrix of g's type)
    for i in range(d):
        for j in range(d):
            acc = wp.float64(0.0)
            for kk in range(d):
                for l in range(d):
                    acc += A[d * i + kk, d * j + l] * ga[kk] * gb[l]
            B[i, j] = w * acc
    return B


@wp.func
def _twist_terms(F: wp.mat33d, dPsi_dJ: wp.float64, mu: wp.float64, w: wp.float64):
    """(R, Nt, active) of the closed-form projection at one point (10-node tet, dPsi/dJ <= 0): R the polar
    rotation of F, Nt = w/2 R N R^T with N the negative part of the twist block T = mu I + dPsi/dJ S
    (S = sym(R^T F)); active = 0 when nothing is removed.

    The eigenvalues of T are mu + dPsi/dJ sigma_i (sigma_i the singular values of F), so N = 0 and R is
    not needed when mu^2 I - dPsi/dJ^2 F^T F is positive definite (leading minors). Near the rest shape
    T ~ 0 and rounding decides: about half of those points still take the full route, and a point this test
    skips has at most a rounding-sized N."""
    I = wp.identity(n=3, dtype=wp.float64)
    M = (mu * mu) * I - (dPsi_dJ * dPsi_dJ) * (wp.transpose(F) * F)
    if M[0, 0] > wp.float64(0.0) and M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0] > wp.float64(0.0):
        if wp.determinant(M) > wp.float64(0.0):
            return I, wp.mat33d(), 0
    R = polar_rotation3(F)
    S = wp.transpose(R) * F
    S = wp.float64(0.5) * (S + wp.transpose(S))
    N = negative_part_sym3(mu * I + dPsi_dJ * S)
    active = 0
    if wp.ddot(N, N) > wp.float64(0.0):
        active = 1
    return R, wp.float64(0.5) * w * (R * N * wp.transpose(R)), active


@wp.func
def _twist_terms(F: wp.mat22d, dPsi_dJ: wp.float64, mu: wp.float64, w: wp.float64):  # noqa: F811
    """6-node triangle: (RJ, -w t/2, active) with RJ = R [[0, -1], [1, 0]] (R the polar rotation of
    F; the twist mode R [[0, -1], [1, 0]] / sqrt 2) and t = mu + dPsi/dJ its eigenvalue, removed when
    t < 0."""
    t = mu + dPsi_dJ
    RJ = wp.mat22d()
    active = 0
    if t < wp.float64(0.0):
        active = 1
        cr = F[0, 0] + F[1, 1]
        sr = F[1, 0] - F[0, 1]
        RJ = wp.mat22d(-sr, -cr, cr, -sr) / wp.sqrt(cr * cr + sr * sr)
    return RJ, wp.float64(-0.5) * w * t, active


@wp.func
def _twist_node(u: wp.vec3d, Nt: wp.mat33d):
    """Node a's left factor of the removed twist part, u = R g_a: [u]x Nt (10-node tet). The part is
    1/2 P_a N P_b^T (times w) with P_a = R [g_a]x = [R g_a]x R: the twist modes R [e_i]x / sqrt 2 seen at
    node a, as in the linear kernel's direct route."""
    return wp.skew(u) * Nt


@wp.func
def _twist_node(u: wp.vec2d, c: wp.float64):  # noqa: F811
    """2D, u = RJ g_a: -w t/2 u."""
    return c * u


@wp.func
def _twist_block(La: wp.mat33d, u: wp.vec3d):
    """Minus the removed part of block (a, b), u = R g_b: - [R g_a]x Nt [R g_b]x^T = La [u]x
    ([v]x^T = -[v]x), whose row i is La[i] x u."""
    return wp.matrix_from_rows(wp.cross(La[0], u), wp.cross(La[1], u), wp.cross(La[2], u))


@wp.func
def _twist_block(La: wp.vec2d, u: wp.vec2d):  # noqa: F811
    """2D, u = RJ g_b: - w t/2 (RJ g_a)(RJ g_b)^T."""
    return wp.outer(La, u)


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


def _hessian_kernel_of(dim: int):
    """The Hessian kernel of the elements of one dimension (overloaded for it below).

    One kernel per dimension, made by this closure, so that the choice of unrolled loops reads a
    captured constant: a ``wp.static`` that reads the element's types instead cannot be evaluated at
    declaration, and Warp then regenerates the whole module's code in every process before it can look
    up its cached binary (~1.3 s at the first P2 launch, measured).
    """

    @wp.kernel(name=f"_hessian_kernel_{dim}d")
    def _hessian_kernel(first: int, x: wp.array(dtype=Any), elements: wp.array2d(dtype=wp.int32),
                        gN: wp.array3d(dtype=Any), wq: wp.array2d(dtype=wp.float64),
                        mu_e: wp.array(dtype=wp.float64), lam_e: wp.array(dtype=wp.float64), project: int,
                        scatter: int, slots: wp.array3d(dtype=wp.int32), energy: wp.array(dtype=wp.float64),
                        det_F: wp.array(dtype=wp.float64), grad: wp.array(dtype=Any),
                        hess: wp.array3d(dtype=wp.float64), data: wp.array(dtype=wp.float64),
                        data2: wp.array(dtype=wp.float64)):
        """Energy, gradient and Hessian blocks (b >= a) of an element. The exact Hessian is added up in K in
        place, point by point, by one loop over the node pairs for every mode (a helper taking and returning
        the whole matrix would copy it several times per point). Where a point's projection changes its blocks
        (the twist part removed, or the SVD route) that change goes into Kc: the projected Hessian is K + Kc,
        the points' exact blocks plus their changes (the old per-point sum, reassociated)."""
        e = first + wp.tid()  # this launch's part of the elements
        zero = wp.float64(0.0)
        k = elements.shape[1]
        nq = wq.shape[1]
        mu = mu_e[e]
        lam = lam_e[e]
        mode = project
        both = 0
        if mode == HESSIAN_BOTH:
            mode = HESSIAN_PROJECT
            both = 1
        g0 = gN[e, 0, 0]
        d = len(g0)  # a compile-time constant: the loops over range(d) are unrolled
        K, Kc, C, U, nodes = _scratch(g0)
        # k again, as a compile-time constant for the 6-node triangle, whose loops over range(kn) (node pairs)
        # are then unrolled; not for the 10-node tet, whose 55 pairs unrolled run slower (and compile long)
        kn = len(nodes) if wp.static(dim == 2) else k
        E = zero
        g = grad.dtype()
        Jmin = wp.float64(wp.inf)
        for q in range(nq):
            F = _F_at(x, elements, gN, e, q)
            J = wp.determinant(F)
            Jmin = wp.min(Jmin, J)
            if J <= zero:  # the element is voided below
                continue
            w = wq[e, q]
            E += w * psi(F, J, mu, lam, dim_float(F))
            P = pk1(F, J, mu, lam)
            logJ = wp.log(J)
            dPsi_dJ = (lam * logJ - mu) / J
            s = w * (mu + lam * (wp.float64(1.0) - logJ)) / (J * J)  # w d2Psi/dJ2
            wmu = w * mu
            t = _det_factor(w * dPsi_dJ, J, g0)
            cof = J * wp.transpose(wp.inverse(F))
            for a in range(kn):
                ga = gN[e, q, a]
                f = w * (P * ga)
                for i in range(d):
                    g[d * a + i] = g[d * a + i] + f[i]
                C[a] = cof * ga  # gamma_a
            for a in range(kn):
                ga = gN[e, q, a]
                ca = C[a]
                sa = s * ca
                for b in range(a, kn):
                    gb = gN[e, q, b]
                    cb = C[b]
                    B = _block(wp.outer(sa, cb), wmu * wp.dot(ga, gb), _det_term(ga, gb, ca, cb, t))
                    for i in range(d):
                        for j in range(d):
                            K[d * a + i, d * b + j] += B[i, j]
            # projection: the SVD route is rare (dPsi/dJ > 0: strong dilation), so its loops stay rolled
            if mode == HESSIAN_PROJECT_SVD or (mode == HESSIAN_PROJECT and dPsi_dJ > zero):
                A = stress_hessian_svd(F, J, mu, lam)  # its blocks replace the exact ones
                for a in range(k):
                    ga = gN[e, q, a]
                    ca = C[a]
                    for b in range(a, k):
                        gb = gN[e, q, b]
                        cb = C[b]
                        D = _svd_block(A, ga, gb, w) - _block(wp.outer(s * ca, cb), wmu * wp.dot(ga, gb),
                                                              _det_term(ga, gb, ca, cb, t))
                        for i in range(d):
                            for j in range(d):
                                Kc[d * a + i, d * b + j] += D[i, j]
            elif mode == HESSIAN_PROJECT:
                R, Nt, twist = _twist_terms(F, dPsi_dJ, mu, w)
                if twist != 0:  # minus the negative twist part
                    for a in range(kn):
                        U[a] = R * gN[e, q, a]
                    for a in range(kn):
                        La = _twist_node(U[a], Nt)
                        for b in range(a, kn):
                            D = _twist_block(La, U[b])
                            for i in range(d):
                                for j in range(d):
                                    Kc[d * a + i, d * b + j] += D[i, j]
        det_F[e] = Jmin
        if Jmin <= zero:
            void_element(e, scatter, energy, grad, hess)
            return
        energy[e] = E
        grad[e] = g
        kd = len(K)  # unrolled in 2D (12), a loop in 3D (30 > Warp's max_unroll)
        for r in range(kd):
            for c in range(r, kd):
                if both != 0:  # exact into data, projected into data2
                    store_hessian_entry(scatter, slots, hess, data, e, r, c, K[r, c])
                    store_hessian_entry(scatter, slots, hess, data2, e, r, c, K[r, c] + Kc[r, c])
                else:  # Kc is zero unless projected
                    store_hessian_entry(scatter, slots, hess, data, e, r, c, K[r, c] + Kc[r, c])

    return _hessian_kernel


_hessian_kernels = {2: _hessian_kernel_of(2), 3: _hessian_kernel_of(3)}


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
        wp.overload(_hessian_kernels[2 if vec is wp.vec2d else 3], {**types, "grad": wp.array(dtype=gvec)})
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
QUADRATIC = ElementKernels(energy=_energy_kernel, gradient=_gradient_kernel, hessian=_hessian_kernels,
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
