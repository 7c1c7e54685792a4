"""Shape derivatives of the linear-simplex Neo-Hookean energy: how E(x; X) changes with the rest
shape X at fixed deformed positions x, side by side with the energy they differentiate.

Per element (see :mod:`simfab.fem.neohookean` for Psi and P): F = Ds Dm^-1 with Dm the rest edge
matrix, V = |det Dm| / d! (times the thickness in 2D), E_e = V Psi(F). Varying the rest edges,
dF = -F dDm Dm^-1 and dV = V tr(Dm^-1 dDm), so

    dE_e/dDm = V (Psi I - F^T P) Dm^-T                       (the Eshelby stress, pulled to the edges)

and for a fixed direction w (n, dim) of the deformed positions, with L = Dw Dm^-1 (Dw: w's edge
matrix) and Q = w . dE/dx = V P : L, the mixed second derivative applied to w is

    dQ/dDm = V ((P : L) I - F^T dP[L] - L^T P) Dm^-T,
    dP[L]  = mu L + (mu - lam log J) F^-T L^T F^-T + lam (F^-T : L) F^-T       (Neo-Hookean)

(dP[L]: P's derivative along L). Edge-matrix derivatives G (dim, dim) go to the nodes as
dX_i = G[:, i-1] (i = 1..d), dX_0 = -sum_i G[:, i-1]. The mixed product ``w^T d2E/dx dX`` is what the
adjoint method needs (``lambda^T d2E/dx dX``, :mod:`simfab.coupling.adjoint`); it is never formed as
a matrix. The Lame parameters are per element and do not depend on X.

Written in batched numpy over the elements (one einsum per term): the derivatives are evaluated
once per converged insertion step, beside one sparse factorization, so they are not on the hot path.
Linear elements only (the rest-shape optimizer's models); checked against finite differences of
:func:`simfab.fem.elastic.energy` / ``energy_gradient`` on perturbed rest shapes.
"""

from __future__ import annotations

import numpy as np

from simfab.fem.model import FemModel


def _kinematics(model: FemModel, x: np.ndarray):
    """(F (m, d, d), J (m,), F^-T, Dm^-1, V (m,), mu, lam) at positions x (n, d)."""
    x = np.asarray(x, float)
    el = np.asarray(model.elements)
    Ds = np.swapaxes(x[el[:, 1:]] - x[el[:, :1]], 1, 2)  # (m, d, d): columns x_i - x_0
    Dmi = np.asarray(model.Dm_inv, float)
    F = Ds @ Dmi
    J = np.linalg.det(F)
    if np.any(J <= 0):
        raise ValueError("shape derivative at an inverted element (det F <= 0)")
    FiT = np.swapaxes(np.linalg.inv(F), 1, 2)
    return F, J, FiT, Dmi, np.asarray(model.volume, float), np.asarray(model.mu, float), np.asarray(model.lam, float)


def _pk1(F, J, FiT, mu, lam):
    """First Piola-Kirchhoff stress P = mu (F - F^-T) + lam log J F^-T (m, d, d) [Pa]."""
    return mu[:, None, None] * (F - FiT) + (lam * np.log(J))[:, None, None] * FiT


def _to_nodes(model: FemModel, G: np.ndarray) -> np.ndarray:
    """Scatter per-element edge-matrix derivatives G (m, d, d) to nodal derivatives (n, d)."""
    el = np.asarray(model.elements)
    n, d = model.n_vertices, G.shape[1]
    cols = np.swapaxes(G, 1, 2)  # (m, d nodes 1..d, d components)
    nodal = np.concatenate([-cols.sum(axis=1, keepdims=True), cols], axis=1)  # (m, d+1, d)
    out = np.zeros((n, d))
    np.add.at(out, el.ravel(), nodal.reshape(-1, d))
    return out


def energy(model: FemModel, x: np.ndarray) -> float:
    """E(x; X) [J] of the model's rest shape X (the same value as :func:`simfab.fem.elastic.energy`,
    for the derivative tests)."""
    F, J, _, _, V, mu, lam = _kinematics(model, x)
    d = F.shape[1]
    logJ = np.log(J)
    psi = 0.5 * mu * (np.einsum("mij,mij->m", F, F) - d) - mu * logJ + 0.5 * lam * logJ**2
    return float(np.sum(V * psi))


def rest_gradient(model: FemModel, x: np.ndarray) -> np.ndarray:
    """dE/dX (n, d) [N]: the energy's derivative with respect to the rest positions at fixed x."""
    F, J, FiT, Dmi, V, mu, lam = _kinematics(model, x)
    d = F.shape[1]
    logJ = np.log(J)
    psi = 0.5 * mu * (np.einsum("mij,mij->m", F, F) - d) - mu * logJ + 0.5 * lam * logJ**2
    P = _pk1(F, J, FiT, mu, lam)
    eshelby = psi[:, None, None] * np.eye(d) - np.swapaxes(F, 1, 2) @ P
    return _to_nodes(model, V[:, None, None] * eshelby @ np.swapaxes(Dmi, 1, 2))


def mixed_product(model: FemModel, x: np.ndarray, w: np.ndarray) -> np.ndarray:
    """d/dX (w . dE/dx) (n, d) [N/m * m]: the mixed second derivative d2E/dx dX applied to the
    deformed-position direction w (n, d) (see the module docstring); a stack of directions
    (b, n, d) gives a stack of results (b, n, d) from one evaluation of the kinematics."""
    F, J, FiT, Dmi, V, mu, lam = _kinematics(model, x)
    d = F.shape[1]
    el = np.asarray(model.elements)
    w = np.asarray(w, float)
    single = w.ndim == 2
    W = w.reshape(-1, model.n_vertices, d)
    P = _pk1(F, J, FiT, mu, lam)
    FT, DmiT = np.swapaxes(F, 1, 2), np.swapaxes(Dmi, 1, 2)
    out = np.empty_like(W)
    for b, wb in enumerate(W):
        Dw = np.swapaxes(wb[el[:, 1:]] - wb[el[:, :1]], 1, 2)
        L = Dw @ Dmi
        PL = np.einsum("mij,mij->m", P, L)
        FiT_L = np.einsum("mij,mij->m", FiT, L)
        dP = (mu[:, None, None] * L + (mu - lam * np.log(J))[:, None, None] * (FiT @ np.swapaxes(L, 1, 2) @ FiT)
              + (lam * FiT_L)[:, None, None] * FiT)
        G = PL[:, None, None] * np.eye(d) - FT @ dP - np.swapaxes(L, 1, 2) @ P
        out[b] = _to_nodes(model, V[:, None, None] * G @ DmiT)
    return out[0] if single else out


def von_mises(model: FemModel, x: np.ndarray) -> np.ndarray:
    """(m,) von Mises stress [Pa], sigma_vm = sqrt(3/2 dev2) mu / J with C = F F^T - I and
    dev2 = C : C - tr(C)^2 / 3 (:func:`simfab.fem.stress.det_and_von_mises`'s formula)."""
    F, J, _, _, _, mu, _ = _kinematics(model, x)
    C = F @ np.swapaxes(F, 1, 2) - np.eye(F.shape[1])
    tr = np.einsum("mii->m", C)
    dev2 = np.maximum(np.einsum("mij,mij->m", C, C) - tr * tr / 3.0, 0.0)
    return np.sqrt(1.5 * dev2) * mu / J


def von_mises_derivatives(model: FemModel, x: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(dq/dx, dq/dX) (n, d) each of q = sum_e c_e sigma_vm,e (c (m,) fixed weights [-]).

    d sigma_vm/dF = sigma_vm (d dev2/dF / (2 dev2) - F^-T), d dev2/dF = 4 C F - 4/3 tr(C) F; with
    S_e = c_e d sigma_vm,e/dF: dq/dDs = S Dm^-T (to the nodes as the energy gradient) and, at
    fixed x, dq/dDm = -F^T S Dm^-T. An element with dev2 = 0 (no distortion) contributes nothing
    (sigma_vm is not differentiable there)."""
    F, J, FiT, Dmi, _, mu, _ = _kinematics(model, x)
    C = F @ np.swapaxes(F, 1, 2) - np.eye(F.shape[1])
    tr = np.einsum("mii->m", C)
    dev2 = np.maximum(np.einsum("mij,mij->m", C, C) - tr * tr / 3.0, 0.0)
    vm = np.sqrt(1.5 * dev2) * mu / J
    safe = np.where(dev2 > 0, dev2, 1.0)
    ddev = 4.0 * C @ F - (4.0 / 3.0) * tr[:, None, None] * F
    S = (np.asarray(c, float) * vm)[:, None, None] * (ddev / (2.0 * safe[:, None, None]) - FiT)
    S[dev2 <= 0] = 0.0
    DmiT = np.swapaxes(Dmi, 1, 2)
    return _to_nodes(model, S @ DmiT), _to_nodes(model, -np.swapaxes(F, 1, 2) @ S @ DmiT)
