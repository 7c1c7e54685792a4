"""The elastic energy of an FEM model of any element order: energy, gradient and Hessian.

Compressible Neo-Hookean material, ``Psi(F) = mu/2 (||F||_F^2 - d) - mu log J + lam/2 (log J)^2``
(2D: plane strain with ``model.thickness``), integrated over each element with the model's
quadrature rule (linear simplices: F constant, one point). The kernels and their equations are in
:mod:`simfab.fem.neohookean` (linear) and :mod:`simfab.fem.neohookean_p2` (quadratic); every function
here runs the one kernel launch over all elements that computes what it returns
(:func:`simfab.fem.workspace.launch`), with the kernels of ``model.element_order``.

Units: positions x (n, dim) [m] (or flat (n*dim,)); energy [J]; gradient dE/dx (n, dim) [N] with
the sign of the energy increase (the elastic nodal force is ``-gradient``); Hessians [N/m] over
dofs ordered (node, axis). The energy is +inf if det F <= 0 anywhere it is evaluated (P2: at any
quadrature point); such elements contribute nothing to the gradient and Hessian.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from simfab.errors import InputError
from simfab.fem.neohookean import LINEAR
from simfab.fem.workspace import ElementKernels, Hessian, Launch, launch

_PROJECTIONS = {"auto": Hessian.PROJECT, "svd": Hessian.PROJECT_SVD}


def kernels(model) -> ElementKernels:
    """The kernels of the model's element order.

    Args:
        model: the FEM model.

    Returns:
        :data:`~simfab.fem.neohookean.LINEAR` (order 1) or :data:`~simfab.fem.neohookean_p2.QUADRATIC` (2).
    """
    order = model.element_order
    if order == 1:
        return LINEAR
    if order == 2:
        # deferred for start-up time: defining the P2 kernels takes about half a second at import,
        # which runs on linear elements do not need
        from simfab.fem.neohookean_p2 import QUADRATIC

        return QUADRATIC
    raise InputError(f"no kernels for element order {order}", where="element_order")


def _mode(project_psd: bool, projection: str) -> Hessian:
    if not project_psd:
        return Hessian.EXACT
    if projection not in _PROJECTIONS:
        raise InputError(f"projection must be one of {sorted(_PROJECTIONS)}, got {projection!r}", where="projection")
    return _PROJECTIONS[projection]


def energy(model, x) -> float:
    """Elastic energy at positions x.

    Args:
        model: the FEM model (:class:`~simfab.fem.model.FemModel`, linear or P2).
        x: positions (n, dim) [m] (or flat (n*dim,)).

    Returns:
        The energy [J]; +inf if any element is inverted.
    """
    return launch(model, kernels(model), x, Launch.ENERGY).total_energy()


def energy_gradient(model, x) -> tuple[float, np.ndarray]:
    """Elastic energy and its gradient.

    Args:
        model: the FEM model (:class:`~simfab.fem.model.FemModel`, linear or P2).
        x: positions (n, dim) [m] (or flat (n*dim,)).

    Returns:
        (energy [J], gradient dE/dx (n, dim) [N]).
    """
    ws = launch(model, kernels(model), x, Launch.GRADIENT)
    return ws.total_energy(), ws.gradient()


def energy_gradient_hessian(model, x, *, project_psd: bool = True,
                            projection: str = "auto") -> tuple[float, np.ndarray, sp.csr_matrix]:
    """Elastic energy, gradient and Hessian.

    With ``project_psd`` the negative eigenvalues of d2Psi/dF2 are clamped to zero at every element
    (P2: every quadrature point), so the assembled Hessian is PSD; otherwise it is the exact Hessian.
    The CSR has the model's fixed pattern (``model.pattern``); its ``data`` is a fresh array the caller
    may modify (e.g. add contact blocks via ``pattern.block_slots``).

    Args:
        model: the FEM model (:class:`~simfab.fem.model.FemModel`, linear or P2).
        x: positions (n, dim) [m] (or flat (n*dim,)).
        project_psd: project per element (default) or return the exact Hessian.
        projection: "auto" removes the negative twist modes in closed form where dPsi/dJ <= 0 and uses
            the SVD eigensystem elsewhere; "svd" uses the SVD eigensystem everywhere (the reference
            route; the two agree to round-off).

    Returns:
        (energy [J], gradient (n, dim) [N], Hessian (n*dim, n*dim) CSR [N/m]).
    """
    ws = launch(model, kernels(model), x, Launch.HESSIAN, _mode(project_psd, projection))
    return ws.total_energy(), ws.gradient(), model.pattern.matrix(ws.csr_values())


def energy_gradient_hessians(model, x) -> tuple[float, np.ndarray, sp.csr_matrix, sp.csr_matrix]:
    """Elastic energy, gradient, exact and PSD-projected Hessians from a single kernel launch.

    For :func:`simfab.solve.newton.minimize` return ``(H_exact, H_psd)`` as the Hessian: it takes exact
    Newton steps whenever the exact Hessian is positive definite and falls back to the projected one.

    Args:
        model: the FEM model (:class:`~simfab.fem.model.FemModel`, linear or P2).
        x: positions (n, dim) [m] (or flat (n*dim,)).

    Returns:
        (energy [J], gradient (n, dim) [N], exact Hessian, projected Hessian), both CSR (n*dim, n*dim)
        [N/m] with the model's pattern.
    """
    ws = launch(model, kernels(model), x, Launch.HESSIAN, Hessian.BOTH)
    return (ws.total_energy(), ws.gradient(), model.pattern.matrix(ws.csr_values()),
            model.pattern.matrix(ws.csr_values(second=True)))


def element_hessians(model, x, *, project_psd: bool = True, projection: str = "auto") -> np.ndarray:
    """Per-element Hessian blocks.

    Args:
        model: the FEM model (:class:`~simfab.fem.model.FemModel`, linear or P2).
        x: positions (n, dim) [m] (or flat (n*dim,)).
        project_psd: as in :func:`energy_gradient_hessian`.
        projection: as in :func:`energy_gradient_hessian`.

    Returns:
        (m, k*dim, k*dim) [N/m], dofs ordered (local node, axis).
    """
    ws = launch(model, kernels(model), x, Launch.BLOCKS, _mode(project_psd, projection))
    return ws.hess.numpy().copy()


def det_F(model, x) -> np.ndarray:
    """det F per element.

    Args:
        model: the FEM model (:class:`~simfab.fem.model.FemModel`, linear or P2).
        x: positions (n, dim) [m] (or flat (n*dim,)).

    Returns:
        (m,) [-] (P2: the smallest over the quadrature points); <= 0 means inverted.
    """
    return launch(model, kernels(model), x, Launch.ENERGY).outputs()[1].copy()


def det_and_von_mises(model, x) -> tuple[np.ndarray, np.ndarray]:
    """det F and von Mises stress per element in one launch.

    The isotropic terms of sigma = (mu (B - I) + lam log J I) / J (B = F F^T; in plane strain
    B = diag(F F^T, 1)) drop out of the deviator, so sigma_vm = sqrt(3/2) mu |dev B| / J with
    |dev B|^2 = C:C - tr(C)^2 / 3 (C = B - I): no inverse, logarithm or 3x3 stress tensor per element (this
    runs once per insertion step). ``simfab.fem.stress`` re-exports it; the tests check it against the
    same formula in NumPy.

    Args:
        model: the FEM model (:class:`~simfab.fem.model.FemModel`, linear or P2).
        x: positions (n, dim) [m] (or flat (n*dim,)).

    Returns:
        (det F (m,) [-], von Mises stress (m,) [Pa]) (P2: the smallest det F and the largest stress over
        the quadrature points); +inf stress where det F <= 0.
    """
    det, vm = launch(model, kernels(model), x, Launch.STRESS).stresses()
    return det.copy(), vm.copy()
