"""Cauchy and von Mises stress of the Neo-Hookean model, per element.

sigma = J^-1 P F^T with P = mu (F - F^-T) + lam log J F^-T (first Piola-Kirchhoff), which
simplifies to sigma = (mu (F F^T - I) + lam log J I) / J.

Plane strain (2D): the body is embedded in 3D with F_zz = 1, so the in-plane block follows from
the 2D F, sigma_xz = sigma_yz = 0 and sigma_zz = lam log J / J (non-zero: the out-of-plane
direction is constrained, not stress-free).
"""

from __future__ import annotations

import numpy as np

from simfab.fem.elastic import det_and_von_mises  # (the Warp kernel; its formula is documented there)
from simfab.fem.model import FemModel, edge_matrices


def deformation_gradient(model: FemModel, x) -> np.ndarray:
    """F = Ds Dm^-1 per element, (m, dim, dim) [-] at positions x (n, dim) [m]."""
    return edge_matrices(model.check_positions(x), model.elements) @ model.Dm_inv


def cauchy_stress(model: FemModel, x) -> np.ndarray:
    """Cauchy (true) stress per element, (m, 3, 3) [Pa], tension positive.

    In 2D the (2, 2) entry is the plane-strain sigma_zz. Elements with det F <= 0 have no
    defined stress: a ValueError is raised for them (callers check ``det_F`` first).
    """
    F = deformation_gradient(model, x)
    J = np.linalg.det(F)
    if np.any(J <= 0):
        raise ValueError(f"{int((J <= 0).sum())} inverted elements (det F <= 0): Cauchy stress undefined")
    d = model.dim
    logJ = np.log(J)
    mu, lam = model.mu[:, None, None], model.lam[:, None, None]
    eye = np.eye(d)[None]
    s_in = (mu * (F @ np.swapaxes(F, 1, 2) - eye) + lam * logJ[:, None, None] * eye) / J[:, None, None]
    if d == 3:
        return s_in
    out = np.zeros((F.shape[0], 3, 3))
    out[:, :2, :2] = s_in
    out[:, 2, 2] = model.lam * logJ / J
    return out


def von_mises_from_cauchy(sigma: np.ndarray) -> np.ndarray:
    """von Mises stress sqrt(3/2 s:s), s = deviatoric part of sigma (..., 3, 3) [Pa]."""
    tr = np.trace(sigma, axis1=-2, axis2=-1)
    s = sigma - tr[..., None, None] / 3.0 * np.eye(3)
    return np.sqrt(1.5 * np.einsum("...ij,...ij->...", s, s))


def von_mises(model: FemModel, x) -> np.ndarray:
    """von Mises equivalent stress per element (m,) [Pa] (plane strain includes sigma_zz).
    Inverted elements (det F <= 0) raise ValueError."""
    J, vm = det_and_von_mises(model, x)
    if np.any(J <= 0):
        raise ValueError(f"{int((J <= 0).sum())} inverted elements (det F <= 0): von Mises stress undefined")
    return vm
