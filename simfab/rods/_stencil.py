"""Warp helpers shared by the hinge energies (bending, twisting).

A *hinge* stencil is an interior vertex with its incoming edge ``e = x1 - x0`` and outgoing
edge ``f = x2 - x1``. Its 11 local degrees of freedom are ordered

    [x0 (0:3), theta_e (3), x1 (4:7), theta_f (7), x2 (8:11)].

Energies compute derivatives with respect to ``(e, f, theta_e, theta_f)`` and expand them
to the 11 DOFs with ``d/dx0 = -d/de``, ``d/dx1 = d/de - d/df``, ``d/dx2 = d/df``.
Local results are scattered into the global gradient with ``dofs`` (stencil -> global DOF,
-1 for none) and into the CSR data of the global Hessian with ``slots`` (precomputed
position of each local entry in the CSR pattern).
"""

from __future__ import annotations

from simfab._warp import wp

f64 = wp.float64
vec11d = wp.types.vector(length=11, dtype=wp.float64)
mat11d = wp.types.matrix(shape=(11, 11), dtype=wp.float64)

# analytic derivatives only: no adjoint code (halves compile time)
wp.set_module_options({"enable_backward": False})


@wp.func
def material(d1: wp.vec3d, t: wp.vec3d, theta: wp.float64) -> wp.mat33d:
    """Rows (m1, m2, 0) of the material frame: reference director d1 rotated by theta about t."""
    d2 = wp.cross(t, d1)
    c = wp.cos(theta)
    s = wp.sin(theta)
    m1 = c * d1 + s * d2
    m2 = -s * d1 + c * d2
    z = f64(0.0)
    return wp.mat33d(m1[0], m1[1], m1[2], m2[0], m2[1], m2[2], z, z, z)


@wp.func
def hinge_geometry(x: wp.array(dtype=wp.vec3d), nodes: wp.array2d(dtype=wp.int32), s: int):
    """Of hinge ``s``: edge lengths ``|e|``, ``|f|`` [m], unit tangents ``te``, ``tf``,
    ``chi = 1 + te.tf``, ``tt = (te + tf) / chi`` and the curvature binormal ``kb = 2 te x tf / chi``."""
    e = x[nodes[s, 1]] - x[nodes[s, 0]]
    f = x[nodes[s, 2]] - x[nodes[s, 1]]
    ne = wp.length(e)
    nf = wp.length(f)
    te = e / ne
    tf = f / nf
    chi = f64(1.0) + wp.dot(te, tf)
    tt = (te + tf) / chi
    kb = f64(2.0) * wp.cross(te, tf) / chi
    return ne, nf, te, tf, chi, tt, kb


@wp.func
def expand_grad(De: wp.vec3d, Df: wp.vec3d, dth_e: wp.float64, dth_f: wp.float64) -> vec11d:
    g = vec11d()
    for k in range(3):
        g[k] = -De[k]
        g[4 + k] = De[k] - Df[k]
        g[8 + k] = Df[k]
    g[3] = dth_e
    g[7] = dth_f
    return g


@wp.func
def expand_hess(Hee: wp.mat33d, Hef: wp.mat33d, Hff: wp.mat33d,
                He_te: wp.vec3d, He_tf: wp.vec3d, Hf_te: wp.vec3d, Hf_tf: wp.vec3d,
                H_tete: wp.float64, H_tftf: wp.float64, H_tetf: wp.float64) -> mat11d:
    """11x11 Hessian from second derivatives in (e, f, theta_e, theta_f)."""
    Hfe = wp.transpose(Hef)
    A00 = Hee
    A01 = Hef - Hee
    A02 = -Hef
    A11 = Hee - Hef - Hfe + Hff
    A12 = Hef - Hff
    A22 = Hff
    H = mat11d()
    for i in range(3):
        for j in range(3):
            H[i, j] = A00[i, j]
            H[i, 4 + j] = A01[i, j]
            H[4 + j, i] = A01[i, j]
            H[i, 8 + j] = A02[i, j]
            H[8 + j, i] = A02[i, j]
            H[4 + i, 4 + j] = A11[i, j]
            H[4 + i, 8 + j] = A12[i, j]
            H[8 + j, 4 + i] = A12[i, j]
            H[8 + i, 8 + j] = A22[i, j]
        a = -He_te[i]
        b = He_te[i] - Hf_te[i]
        c = Hf_te[i]
        H[i, 3] = a
        H[3, i] = a
        H[4 + i, 3] = b
        H[3, 4 + i] = b
        H[8 + i, 3] = c
        H[3, 8 + i] = c
        a = -He_tf[i]
        b = He_tf[i] - Hf_tf[i]
        c = Hf_tf[i]
        H[i, 7] = a
        H[7, i] = a
        H[4 + i, 7] = b
        H[7, 4 + i] = b
        H[8 + i, 7] = c
        H[7, 8 + i] = c
    H[3, 3] = H_tete
    H[7, 7] = H_tftf
    H[3, 7] = H_tetf
    H[7, 3] = H_tetf
    return H


@wp.func
def scatter11(s: int, g: vec11d, H: mat11d, need_grad: int, need_hess: int,
              dofs: wp.array2d(dtype=wp.int32), slots: wp.array2d(dtype=wp.int32),
              grad: wp.array(dtype=wp.float64), hess: wp.array(dtype=wp.float64)):
    if need_grad != 0:
        for a in range(11):
            d = dofs[s, a]
            if d >= 0:
                wp.atomic_add(grad, d, g[a])
    if need_hess != 0:
        for a in range(11):
            for b in range(11):
                k = slots[s, a * 11 + b]
                if k >= 0:
                    wp.atomic_add(hess, k, H[a, b])
