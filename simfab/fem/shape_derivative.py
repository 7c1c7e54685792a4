"""Shape derivatives of the Neo-Hookean energy: how E(x; X) changes with the rest shape X at fixed
deformed positions x; linear (P1) and quadratic (P2) simplices through one path, the quadrature point.

Per quadrature point q (rest gradients G_qa, weights w_q of
:meth:`~simfab.fem.model.MeshModel.element_geometry`), varying the rest nodes changes the rest map by
K_q = sum_a dX_a (x) G_qa + I; at K = I

    dE_q/dK = w_q (Psi I - F^T P)                            (the Eshelby stress)
    dE/dX_a = sum_q (dE_q/dK) G_qa
    dQ_q/dK = w_q ((P : L) I - F^T dP[L] - L^T P),   L_q = sum_a w_a (x) G_qa   (mixed product along w)

The mixed product ``w^T d2E/dx dX`` is what the adjoint method needs
(:mod:`simfab.coupling.adjoint`); it is never formed as a matrix. Derivatives are with respect to
every node; :func:`linear_rest_derivative` chains a P2 model's edge nodes to their corners. Batched
numpy (evaluated once per converged step, off the hot path); checked against finite differences
(tests/fem/test_shape_derivative.py). The derivation: docs/methods.md, "simfab.fem.shape_derivative".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from simfab.fem.model import MeshModel


@dataclass(frozen=True, kw_only=True, eq=False)
class Quadrature:
    """A model's rest quadrature: grad_N (m, nq, k, dim) [1/m] the shape-function gradients G_qa at
    each point, weights (m, nq) [m^3] (2D: area * thickness)."""

    grad_N: np.ndarray
    weights: np.ndarray
    scatter: sp.csr_matrix  # (n, m k): sums per-element nodal rows into the nodes


def quadrature(model: MeshModel) -> Quadrature:
    """The :class:`Quadrature` of ``model`` from its ``element_geometry()``: P2 stores the
    gradients per point; a linear simplex stores Dm^-1 (rows: grad L_1..L_d, grad L_0 = -their sum)
    and its volume, the one-point rule."""
    cache = model._cache.get("shape_derivative_quadrature")
    if cache is not None:
        return cache
    geometry, weights = model.element_geometry()
    geometry, weights = np.asarray(geometry, float), np.asarray(weights, float)
    el = np.asarray(model.elements).ravel()
    scatter = sp.csr_matrix((np.ones(el.size), (el, np.arange(el.size))), shape=(model.n_vertices, el.size))
    if weights.ndim == 1:  # linear simplex: geometry is Dm^-1 (m, d, d)
        grad_L = np.concatenate([-geometry.sum(axis=1, keepdims=True), geometry], axis=1)
        q = Quadrature(grad_N=grad_L[:, None], weights=weights[:, None], scatter=scatter)
    else:
        q = Quadrature(grad_N=geometry, weights=weights, scatter=scatter)
    model._cache["shape_derivative_quadrature"] = q
    return q


@dataclass(frozen=True, kw_only=True, eq=False)
class _Kinematics:
    """Per point (m, nq, ...): F, J, F^-T, weights w, Lame parameters broadcast (m, 1)."""

    F: np.ndarray
    J: np.ndarray
    FiT: np.ndarray
    w: np.ndarray
    G: np.ndarray
    mu: np.ndarray
    lam: np.ndarray
    scatter: sp.csr_matrix


def _kinematics(model: MeshModel, x: np.ndarray) -> _Kinematics:
    x = np.asarray(x, float)
    q = quadrature(model)
    F = np.einsum("mai,mqaj->mqij", x[np.asarray(model.elements)], q.grad_N)
    J = np.linalg.det(F)
    if np.any(J <= 0):
        raise ValueError("shape derivative at an inverted element (det F <= 0)")
    FiT = np.swapaxes(np.linalg.inv(F), -1, -2)
    return _Kinematics(F=F, J=J, FiT=FiT, w=q.weights, G=q.grad_N, mu=np.asarray(model.mu, float)[:, None],
                       lam=np.asarray(model.lam, float)[:, None], scatter=q.scatter)


def _psi(k: _Kinematics) -> np.ndarray:
    d = k.F.shape[-1]
    logJ = np.log(k.J)
    return 0.5 * k.mu * (np.einsum("mqij,mqij->mq", k.F, k.F) - d) - k.mu * logJ + 0.5 * k.lam * logJ**2


def _pk1(k: _Kinematics) -> np.ndarray:
    """First Piola-Kirchhoff stress P = mu (F - F^-T) + lam log J F^-T (m, nq, d, d) [Pa]."""
    return k.mu[..., None, None] * (k.F - k.FiT) + (k.lam * np.log(k.J))[..., None, None] * k.FiT


def _to_nodes(model: MeshModel, k: _Kinematics, M: np.ndarray) -> np.ndarray:
    """Nodal derivatives (n, d) of per-point rest-map derivatives M_q = dq/dK_q (m, nq, d, d):
    sum_q M_q G_qa scattered to the nodes a (also F-derivatives to dq/dx: F_q = sum_a x_a (x) G_qa)."""
    d, n = M.shape[-1], model.n_vertices
    nodal = np.einsum("...mqij,mqaj->...mai", M, k.G)  # a stack (..., m, nq, d, d) gives (..., n, d)
    lead = nodal.shape[:-3]
    B = int(np.prod(lead, dtype=int))
    flat = np.moveaxis(nodal.reshape(B, -1, d), 0, 1).reshape(-1, B * d)  # (m k, B d)
    out = k.scatter @ flat
    return np.moveaxis(out.reshape(n, B, d), 1, 0).reshape(*lead, n, d)


def quadrature_energy(model: MeshModel, x: np.ndarray) -> float:
    """E(x; X) [J] of the model's rest shape X (the same value as :func:`simfab.fem.elastic.energy`,
    for the derivative tests)."""
    k = _kinematics(model, x)
    return float(np.sum(k.w * _psi(k)))


def rest_gradient(model: MeshModel, x: np.ndarray) -> np.ndarray:
    """dE/dX (n, d) [N]: the energy's derivative with respect to the rest positions at fixed x."""
    k = _kinematics(model, x)
    d = k.F.shape[-1]
    eshelby = _psi(k)[..., None, None] * np.eye(d) - np.swapaxes(k.F, -1, -2) @ _pk1(k)
    return _to_nodes(model, k, k.w[..., None, None] * eshelby)


def mixed_product(model: MeshModel, x: np.ndarray, w: np.ndarray) -> np.ndarray:
    """d/dX (w . dE/dx) (n, d) [N/m * m]: the mixed second derivative d2E/dx dX applied to the
    deformed-position direction w (n, d) (see the module docstring); a stack of directions
    (b, n, d) gives a stack of results (b, n, d) from one evaluation of the kinematics."""
    k = _kinematics(model, x)
    d = k.F.shape[-1]
    el = np.asarray(model.elements)
    w = np.asarray(w, float)
    single = w.ndim == 2
    W = w.reshape(-1, model.n_vertices, d)
    P = _pk1(k)
    FT = np.swapaxes(k.F, -1, -2)
    mu, c2 = k.mu[..., None, None], (k.mu - k.lam * np.log(k.J))[..., None, None]
    out = np.empty_like(W)
    chunk = max(1, int(2e6 // max(1, P.size)))  # directions per batch: ~2e6 doubles per array
    for b0 in range(0, len(W), chunk):
        L = np.einsum("bmai,mqaj->bmqij", W[b0:b0 + chunk][:, el], k.G)
        PL = np.einsum("mqij,bmqij->bmq", P, L)
        FiT_L = np.einsum("mqij,bmqij->bmq", k.FiT, L)
        dP = mu * L + c2 * (k.FiT @ np.swapaxes(L, -1, -2) @ k.FiT) + (k.lam * FiT_L)[..., None, None] * k.FiT
        M = PL[..., None, None] * np.eye(d) - FT @ dP - np.swapaxes(L, -1, -2) @ P
        out[b0:b0 + chunk] = _to_nodes(model, k, k.w[..., None, None] * M)
    return out[0] if single else out


def point_von_mises(model: MeshModel, x: np.ndarray) -> np.ndarray:
    """(m * nq,) von Mises stress [Pa] per quadrature point, element-major (linear simplices: (m,),
    one per element), sigma_vm = sqrt(3/2 dev2) mu / J with C = F F^T - I and dev2 = C : C - tr(C)^2
    / 3 (:func:`simfab.fem.elastic.det_and_von_mises`'s formula; P2: the points of
    :func:`simfab.design.stress.quadrature_von_mises`)."""
    k = _kinematics(model, x)
    return _von_mises(k)[0].ravel()


def _von_mises(k: _Kinematics):
    C = k.F @ np.swapaxes(k.F, -1, -2) - np.eye(k.F.shape[-1])
    tr = np.einsum("mqii->mq", C)
    dev2 = np.maximum(np.einsum("mqij,mqij->mq", C, C) - tr * tr / 3.0, 0.0)
    return np.sqrt(1.5 * dev2) * k.mu / k.J, C, tr, dev2


def von_mises_derivatives(model: MeshModel, x: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(dq/dx, dq/dX) (n, d) each of q = sum_p c_p sigma_vm,p over the quadrature points p (c
    (m * nq,) fixed weights [-], the order of :func:`point_von_mises`).

    d sigma_vm/dF = sigma_vm (d dev2/dF / (2 dev2) - F^-T), d dev2/dF = 4 C F - 4/3 tr(C) F; with
    S_p = c_p d sigma_vm,p/dF: dq/dx_a = sum_p S_p G_pa and, at fixed x (F -> F K^-1),
    dq/dK_p = -F^T S_p. A point with dev2 = 0 (no distortion) contributes nothing (sigma_vm is not
    differentiable there)."""
    k = _kinematics(model, x)
    vm, C, tr, dev2 = _von_mises(k)
    safe = np.where(dev2 > 0, dev2, 1.0)
    ddev = 4.0 * C @ k.F - (4.0 / 3.0) * tr[..., None, None] * k.F
    cw = np.asarray(c, float).reshape(vm.shape)
    S = (cw * vm)[..., None, None] * (ddev / (2.0 * safe[..., None, None]) - k.FiT)
    S[dev2 <= 0] = 0.0
    return _to_nodes(model, k, S), _to_nodes(model, k, -np.swapaxes(k.F, -1, -2) @ S)


def linear_rest_derivative(model: MeshModel, g: np.ndarray) -> np.ndarray:
    """A derivative g (n, d) [or a stack (b, n, d)] with respect to every node's rest position,
    chained to the corner positions (n_corners, d): the linear mesh's rest shape, on which a P2
    model built by :func:`simfab.fem.p2.to_p2` puts each edge node at its edge's midpoint,
    X_(n_c + i) = (X_a + X_b) / 2 for edges[i] = (a, b), so dq/dX_c = g_c + 1/2 sum of g over the
    edge nodes of c's edges. Linear models: g itself."""
    g = np.asarray(g, float)
    if model.element_order == 1:
        return g
    nc, n = model.n_corners, model.n_vertices
    edges = np.asarray(model.edges, np.int64)
    rows = np.r_[np.arange(nc), np.arange(nc, n), np.arange(nc, n)]
    cols = np.r_[np.arange(nc), edges[:, 0], edges[:, 1]]
    vals = np.r_[np.ones(nc), np.full(2 * (n - nc), 0.5)]
    D = sp.csr_matrix((vals, (rows, cols)), shape=(n, nc))  # dX/dX_corners
    G = g.reshape(-1, n, g.shape[-1])
    return np.stack([D.T @ gb for gb in G]).reshape(*g.shape[:-2], nc, g.shape[-1])
