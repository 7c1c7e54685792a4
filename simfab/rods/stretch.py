"""Stretching energy of discrete elastic rods: energy, gradient and Hessian in one Warp kernel.

For an edge from node a to node b with rest length ``L`` [m] and axial stiffness ``EA`` [N]:

    eps = |e| / L - 1,   E = 1/2 EA eps^2 L                                       [J]
    dE/de = EA eps t
    d2E/de2 = EA / L t t^T + EA eps / |e| (I - t t^T)

and ``d/dx_a = -d/de``, ``d/dx_b = d/de``. Local DOFs: [x_a (0:3), x_b (3:6)].
"""

from __future__ import annotations

from simfab._warp import wp
from simfab.rods._stencil import f64

# analytic derivatives only: no adjoint code (halves compile time)
wp.set_module_options({"enable_backward": False})


@wp.kernel
def _stretch(x: wp.array(dtype=wp.vec3d), edges: wp.array2d(dtype=wp.int32),
             rest_len: wp.array(dtype=wp.float64), stiff: wp.array(dtype=wp.float64),
             dofs: wp.array2d(dtype=wp.int32), slots: wp.array2d(dtype=wp.int32),
             need_grad: int, need_hess: int,
             energy: wp.array(dtype=wp.float64), grad: wp.array(dtype=wp.float64), hess: wp.array(dtype=wp.float64)):
    s = wp.tid()
    e = x[edges[s, 1]] - x[edges[s, 0]]
    L = rest_len[s]
    k = stiff[s]
    n = wp.length(e)
    t = e / n
    eps = n / L - f64(1.0)
    energy[s] = f64(0.5) * k * eps * eps * L
    if need_grad != 0:
        ge = k * eps * t
        for c in range(3):
            da = dofs[s, c]
            db = dofs[s, 3 + c]
            if da >= 0:
                wp.atomic_add(grad, da, -ge[c])
            if db >= 0:
                wp.atomic_add(grad, db, ge[c])
    if need_hess != 0:
        tt = wp.outer(t, t)
        He = (k / L) * tt + (k * eps / n) * (wp.identity(n=3, dtype=wp.float64) - tt)
        for i in range(3):
            for j in range(3):
                v = He[i, j]
                k00 = slots[s, i * 6 + j]
                k01 = slots[s, i * 6 + 3 + j]
                k10 = slots[s, (3 + i) * 6 + j]
                k11 = slots[s, (3 + i) * 6 + 3 + j]
                if k00 >= 0:
                    wp.atomic_add(hess, k00, v)
                if k01 >= 0:
                    wp.atomic_add(hess, k01, -v)
                if k10 >= 0:
                    wp.atomic_add(hess, k10, -v)
                if k11 >= 0:
                    wp.atomic_add(hess, k11, v)


def launch_stretch(dev, need_grad: bool, need_hess: bool) -> None:
    """Accumulate stretching energy per edge into ``dev.e_stretch`` (E,) and its gradient/Hessian
    into ``dev.grad`` / ``dev.hess`` for all edges of all rods in one launch."""
    if dev.n_edges == 0:
        return
    wp.launch(_stretch, dim=dev.n_edges, device=dev.device,
              inputs=[dev.x, dev.edges, dev.rest_len, dev.stretch_stiff, dev.edge_dofs, dev.edge_slots,
                      int(need_grad), int(need_hess)],
              outputs=[dev.e_stretch, dev.grad, dev.hess])
