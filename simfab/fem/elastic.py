"""The elastic energy of any FEM model, linear or quadratic: one import for callers that should
not care about the element order (e.g. the insertion simulation once it runs on P2 parts).

Each function has the signature of its :mod:`simfab.fem.neohookean` namesake and forwards to it
for a :class:`~simfab.fem.model.FemModel` and to :mod:`simfab.fem.neohookean_p2` for a
:class:`~simfab.fem.p2.P2Model` (there det F is the smallest and the von Mises stress the largest
value over each element's quadrature points).
"""

from __future__ import annotations

from types import ModuleType


def kernels(model) -> ModuleType:
    """The Neo-Hookean module for the model's element order."""
    from simfab.fem.p2 import P2Model

    if isinstance(model, P2Model):
        from simfab.fem import neohookean_p2 as mod
    else:
        from simfab.fem import neohookean as mod
    return mod


def energy(model, x) -> float:
    """Elastic energy [J]; +inf if any element is inverted."""
    return kernels(model).energy(model, x)


def energy_gradient(model, x):
    """(energy [J], gradient (n, dim) [N])."""
    return kernels(model).energy_gradient(model, x)


def energy_gradient_hessian(model, x, *, project_psd: bool = True):
    """(energy [J], gradient (n, dim) [N], Hessian CSR (n*dim, n*dim) [N/m], PSD-projected or exact)."""
    return kernels(model).energy_gradient_hessian(model, x, project_psd=project_psd)


def energy_gradient_hessians(model, x):
    """(energy, gradient, exact Hessian, PSD-projected Hessian) from one launch."""
    return kernels(model).energy_gradient_hessians(model, x)


def element_hessians(model, x, *, project_psd: bool = True):
    """Per-element Hessian blocks (m, k*dim, k*dim) [N/m]."""
    return kernels(model).element_hessians(model, x, project_psd=project_psd)


def det_F(model, x):
    """det F per element (m,) (P2: the smallest over the quadrature points)."""
    return kernels(model).det_F(model, x)


def det_and_von_mises(model, x):
    """(det F (m,) [-], von Mises stress (m,) [Pa]) per element (P2: min / max over the points)."""
    return kernels(model).det_and_von_mises(model, x)
