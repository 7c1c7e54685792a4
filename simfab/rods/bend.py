"""Bending energy of discrete elastic rods: energy, gradient and Hessian in one Warp kernel.

At a hinge (interior vertex) with incoming edge ``e`` and outgoing edge ``f``:

    kb = 2 e x f / (|e||f| + e.f)                 (discrete curvature binormal, |kb| = 2 tan(phi/2))
    kappa1 =  1/2 kb . (m2_e + m2_f)              (bending towards m1, about m2)
    kappa2 = -1/2 kb . (m1_e + m1_f)              (bending towards m2, about m1)
    E = 1/2 [B1 (kappa1 - kb1)^2 + B2 (kappa2 - kb2)^2] / l                       [J]

with ``(kb1, kb2)`` the natural (rest) material curvatures, ``l = (|e_rest| + |f_rest|) / 2``
the Voronoi length [m] and ``B1, B2`` the bending stiffnesses [N m^2] (rectangle w x t with
m1 along the thickness: ``B1 = E w t^3 / 12``, ``B2 = E t w^3 / 12``).

Derivatives follow Bergou et al. 2008 / 2010 with the material frames moving with the edges
by time-parallel transport; the gradient and Hessian below are exact for that energy
(checked against finite differences in tests/rods). ``theta`` enters through the material
frames: d m1/d theta = m2, d m2/d theta = -m1.
"""

from __future__ import annotations

from simfab._warp import wp
from simfab.rods._stencil import expand_grad, expand_hess, f64, hinge_geometry, mat11d, material, scatter11

# analytic derivatives only: no adjoint code (halves compile time)
wp.set_module_options({"enable_backward": False})


@wp.func
def _outer3(a: wp.vec3d, b: wp.vec3d) -> wp.mat33d:
    return wp.outer(a, b)


@wp.kernel
def _bend(x: wp.array(dtype=wp.vec3d), theta: wp.array(dtype=wp.float64), d1: wp.array(dtype=wp.vec3d),
          nodes: wp.array2d(dtype=wp.int32), edges: wp.array2d(dtype=wp.int32),
          kappa_bar: wp.array2d(dtype=wp.float64), stiff: wp.array2d(dtype=wp.float64),
          vor_len: wp.array(dtype=wp.float64),
          dofs: wp.array2d(dtype=wp.int32), slots: wp.array2d(dtype=wp.int32),
          need_grad: int, need_hess: int,
          energy: wp.array(dtype=wp.float64), grad: wp.array(dtype=wp.float64), hess: wp.array(dtype=wp.float64)):
    s = wp.tid()
    ie = edges[s, 0]
    jf = edges[s, 1]
    ne, nf, te, tf, chi, tt, kb = hinge_geometry(x, nodes, s)
    Me = material(d1[ie], te, theta[ie])
    Mf = material(d1[jf], tf, theta[jf])
    m1e = Me[0]
    m2e = Me[1]
    m1f = Mf[0]
    m2f = Mf[1]
    half = f64(0.5)
    two = f64(2.0)
    d1t = (m1e + m1f) / chi
    d2t = (m2e + m2f) / chi
    k1 = half * wp.dot(kb, m2e + m2f)
    k2 = -half * wp.dot(kb, m1e + m1f)
    w1 = stiff[s, 0] / vor_len[s]
    w2 = stiff[s, 1] / vor_len[s]
    dk1 = k1 - kappa_bar[s, 0]
    dk2 = k2 - kappa_bar[s, 1]
    energy[s] = half * (w1 * dk1 * dk1 + w2 * dk2 * dk2)
    if need_grad == 0 and need_hess == 0:
        return
    # first derivatives of kappa1, kappa2 with respect to (e, f, theta_e, theta_f)
    g1 = expand_grad((-k1 * tt + wp.cross(tf, d2t)) / ne, (-k1 * tt - wp.cross(te, d2t)) / nf,
                     -half * wp.dot(kb, m1e), -half * wp.dot(kb, m1f))
    g2 = expand_grad((-k2 * tt - wp.cross(tf, d1t)) / ne, (-k2 * tt + wp.cross(te, d1t)) / nf,
                     -half * wp.dot(kb, m2e), -half * wp.dot(kb, m2f))
    g = (w1 * dk1) * g1 + (w2 * dk2) * g2
    H = mat11d()
    if need_hess != 0:
        I3 = wp.identity(n=3, dtype=wp.float64)
        quarter = f64(0.25)
        ne2 = ne * ne
        nf2 = nf * nf
        nef = ne * nf
        ttt = _outer3(tt, tt)
        Pe = I3 - _outer3(te, te)
        Pf = I3 - _outer3(tf, tf)
        Q = I3 + _outer3(te, tf)
        # kappa1
        a = wp.cross(tf, d2t)
        b = wp.cross(te, d2t)
        Hee = (two * k1 * ttt - _outer3(a, tt) - _outer3(tt, a)) / ne2 - k1 / (chi * ne2) * Pe \
            + quarter / ne2 * (_outer3(kb, m2e) + _outer3(m2e, kb))
        Hff = (two * k1 * ttt + _outer3(b, tt) + _outer3(tt, b)) / nf2 - k1 / (chi * nf2) * Pf \
            + quarter / nf2 * (_outer3(kb, m2f) + _outer3(m2f, kb))
        Hef = -k1 / (chi * nef) * Q + (two * k1 * ttt - _outer3(a, tt) + _outer3(tt, b) - wp.skew(d2t)) / nef
        H1 = expand_hess(Hee, Hef, Hff,
                         (half * wp.dot(kb, m1e) * tt - wp.cross(tf, m1e) / chi) / ne,
                         (half * wp.dot(kb, m1f) * tt - wp.cross(tf, m1f) / chi) / ne,
                         (half * wp.dot(kb, m1e) * tt + wp.cross(te, m1e) / chi) / nf,
                         (half * wp.dot(kb, m1f) * tt + wp.cross(te, m1f) / chi) / nf,
                         -half * wp.dot(kb, m2e), -half * wp.dot(kb, m2f), f64(0.0))
        # kappa2
        a = wp.cross(tf, d1t)
        b = wp.cross(te, d1t)
        Hee = (two * k2 * ttt + _outer3(a, tt) + _outer3(tt, a)) / ne2 - k2 / (chi * ne2) * Pe \
            - quarter / ne2 * (_outer3(kb, m1e) + _outer3(m1e, kb))
        Hff = (two * k2 * ttt - _outer3(b, tt) - _outer3(tt, b)) / nf2 - k2 / (chi * nf2) * Pf \
            - quarter / nf2 * (_outer3(kb, m1f) + _outer3(m1f, kb))
        Hef = -k2 / (chi * nef) * Q + (two * k2 * ttt + _outer3(a, tt) - _outer3(tt, b) + wp.skew(d1t)) / nef
        H2 = expand_hess(Hee, Hef, Hff,
                         (half * wp.dot(kb, m2e) * tt - wp.cross(tf, m2e) / chi) / ne,
                         (half * wp.dot(kb, m2f) * tt - wp.cross(tf, m2f) / chi) / ne,
                         (half * wp.dot(kb, m2e) * tt + wp.cross(te, m2e) / chi) / nf,
                         (half * wp.dot(kb, m2f) * tt + wp.cross(te, m2f) / chi) / nf,
                         half * wp.dot(kb, m1e), half * wp.dot(kb, m1f), f64(0.0))
        H = w1 * (wp.outer(g1, g1) + dk1 * H1) + w2 * (wp.outer(g2, g2) + dk2 * H2)
    scatter11(s, g, H, need_grad, need_hess, dofs, slots, grad, hess)


def launch_bend(dev, need_grad: bool, need_hess: bool) -> None:
    """Accumulate bending energy per hinge into ``dev.e_bend`` (H,) and its gradient/Hessian
    into ``dev.grad`` (n_dofs,) / ``dev.hess`` (nnz,) for all hinges of all rods in one launch.

    ``dev`` is a :class:`simfab.rods.energy.DeviceBuffers` with the current state uploaded.
    """
    if dev.n_hinges == 0:
        return
    wp.launch(_bend, dim=dev.n_hinges, device=dev.device,
              inputs=[dev.x, dev.theta, dev.d1, dev.hinge_nodes, dev.hinge_edges, dev.kappa_bar, dev.bend_stiff,
                      dev.vor_len, dev.hinge_dofs, dev.hinge_slots, int(need_grad), int(need_hess)],
              outputs=[dev.e_bend, dev.grad, dev.hess])
