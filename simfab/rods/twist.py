"""Twisting energy of discrete elastic rods: energy, gradient and Hessian in one Warp kernel.

At a hinge with incoming edge ``e`` and outgoing edge ``f`` the integrated twist is

    m = theta_f - theta_e + r          (r: reference twist of the hinge, see frames.py)
    E = 1/2 GJ (m - m_rest)^2 / l                                               [J]

with ``GJ`` the torsional stiffness [N m^2] and ``l`` the Voronoi length [m]. The reference
twist depends on the edges through parallel transport (Bergou et al. 2008, 2010):
``dr/de = kb / (2|e|)``, ``dr/df = kb / (2|f|)``; its second derivatives are below. The
Hessian is exact for reference frames updated by time-parallel transport (tests/rods).
"""

from __future__ import annotations

from simfab._warp import wp
from simfab.rods._stencil import expand_grad, expand_hess, f64, hinge_geometry, mat11d, scatter11

# analytic derivatives only: no adjoint code (halves compile time)
wp.set_module_options({"enable_backward": False})


@wp.kernel
def _twist(x: wp.array(dtype=wp.vec3d), theta: wp.array(dtype=wp.float64), ref_twist: wp.array(dtype=wp.float64),
           nodes: wp.array2d(dtype=wp.int32), edges: wp.array2d(dtype=wp.int32),
           twist_bar: wp.array(dtype=wp.float64), stiff: wp.array(dtype=wp.float64),
           vor_len: wp.array(dtype=wp.float64),
           dofs: wp.array2d(dtype=wp.int32), slots: wp.array2d(dtype=wp.int32),
           need_grad: int, need_hess: int,
           energy: wp.array(dtype=wp.float64), grad: wp.array(dtype=wp.float64), hess: wp.array(dtype=wp.float64)):
    s = wp.tid()
    m = theta[edges[s, 1]] - theta[edges[s, 0]] + ref_twist[s]
    w = stiff[s] / vor_len[s]
    dm = m - twist_bar[s]
    half = f64(0.5)
    energy[s] = half * w * dm * dm
    if need_grad == 0 and need_hess == 0:
        return
    ne, nf, te, tf, chi, tt, kb = hinge_geometry(x, nodes, s)
    one = f64(1.0)
    two = f64(2.0)
    gm = expand_grad(kb / (two * ne), kb / (two * nf), -one, one)
    g = (w * dm) * gm
    H = mat11d()
    if need_hess != 0:
        quarter = f64(0.25)
        z3 = wp.vec3d(f64(0.0), f64(0.0), f64(0.0))
        a = te + tt
        b = tf + tt
        Hee = -quarter / (ne * ne) * (wp.outer(kb, a) + wp.outer(a, kb))
        Hff = -quarter / (nf * nf) * (wp.outer(kb, b) + wp.outer(b, kb))
        Hef = half / (ne * nf) * (two / chi * wp.skew(te) - wp.outer(kb, tt))
        Hm = expand_hess(Hee, Hef, Hff, z3, z3, z3, z3, f64(0.0), f64(0.0), f64(0.0))
        H = w * (wp.outer(gm, gm) + dm * Hm)
    scatter11(s, g, H, need_grad, need_hess, dofs, slots, grad, hess)


def launch_twist(dev, need_grad: bool, need_hess: bool) -> None:
    """Accumulate twisting energy per hinge into ``dev.e_twist`` (H,) and its gradient/Hessian
    into ``dev.grad`` / ``dev.hess`` for all hinges of all rods in one launch."""
    if dev.n_hinges == 0:
        return
    wp.launch(_twist, dim=dev.n_hinges, device=dev.device,
              inputs=[dev.x, dev.theta, dev.ref_twist, dev.hinge_nodes, dev.hinge_edges, dev.twist_bar,
                      dev.twist_stiff, dev.vor_len, dev.hinge_dofs, dev.hinge_slots, int(need_grad), int(need_hess)],
              outputs=[dev.e_twist, dev.grad, dev.hess])
