"""IPC-style log barrier keeping points outside a rigid object, with energy, gradient and Hessian.

Scalar barrier on a distance d > 0 with activation distance dhat (Li et al. 2020, IPC):

    b(d)   = -(d - dhat)^2 log(d / dhat)                       for 0 < d < dhat, else 0
    b'(d)  = -2 (d - dhat) log(d / dhat) - (d - dhat)^2 / d
    b''(d) = -2 log(d / dhat) - 4 (d - dhat) / d + (d - dhat)^2 / d^2

b is C2 at d = dhat, positive and convex on (0, dhat), and b -> +inf as d -> 0. Units: b in m^2.

Contact energy on constraint points y_j = sum_a w_ja x_a (mesh vertices or points interpolated on
boundary edges/faces), with d_j = -psi(y_j) the IMLS distance to O (psi > 0 inside O):

    B(x) = kappa * sum_j b(d_j)            kappa [N/m] (so B is in J)
    dB/dy_j   = kappa b'(d_j) grad d_j                      (grad d = -grad psi)
    d2B/dy_j2 = kappa (b''(d_j) grad d grad d^T + b'(d_j) hess d)   projected to PSD per point
    and onto vertices: dB/dx_a = sum_j w_ja dB/dy_j, d2B/dx_a dx_b = sum_j w_ja w_jb d2B/dy_j2.
"""

from __future__ import annotations

import numpy as np


def barrier_terms(d: np.ndarray, dhat: float, terms: int = 3) -> tuple:
    """(b, b', b'') at distances strictly inside the active range, 0 < d < dhat (k,), from one log:
    the hot path of an objective, which selects its active points first; the first ``terms`` of
    them only (each computed alike whichever are asked for)."""
    r = d - dhat
    log = np.log(d / dhat)
    out = (-(r**2) * log,)
    if terms > 1:
        out += (-2.0 * r * log - r**2 / d,)
    if terms > 2:
        out += (-2.0 * log - 4.0 * r / d + r**2 / d**2,)
    return out


def _on_active(d: np.ndarray, dhat, term: int, at_zero: float) -> np.ndarray:
    """Term ``term`` of :func:`barrier_terms` elementwise over any d: 0 for d >= dhat, ``at_zero``
    for d <= 0 (``dhat`` a scalar or one per distance)."""
    d = np.asarray(d, float)
    out = np.zeros_like(d)
    act = d < dhat
    pos = act & (d > 0)
    out[pos] = barrier_terms(d[pos], dhat if np.ndim(dhat) == 0 else np.asarray(dhat)[pos], term + 1)[term]
    out[act & ~pos] = at_zero
    return out


def _all_terms(d: np.ndarray, dhat, terms: int = 3) -> tuple:
    """The first ``terms`` of (:func:`barrier`, :func:`barrier_gradient`, :func:`barrier_hessian`)
    at d (k,) from one pass."""
    d = np.asarray(d, float)
    act = d < dhat
    pos = act & (d > 0)
    zero = act & ~pos
    out = ()
    for t, at_zero in zip(barrier_terms(d[pos], dhat if np.ndim(dhat) == 0 else np.asarray(dhat)[pos], terms),
                          (np.inf, 0.0, 0.0)):
        o = np.zeros_like(d)
        o[pos] = t
        o[zero] = at_zero
        out += (o,)
    return out


def barrier_value(d: np.ndarray, dhat) -> np.ndarray:
    """b(d) (k,) [m^2] at distances strictly inside the active range, 0 < d < dhat (the first term
    of :func:`barrier_terms` alone: a line search's value)."""
    r = d - dhat
    return -(r**2) * np.log(d / dhat)


def barrier(d: np.ndarray, dhat: float) -> np.ndarray:
    """The barrier b(d) elementwise.

    Args:
        d: distances [m].
        dhat: activation distance [m].

    Returns:
        b(d) [m^2]; +inf for d <= 0, 0 for d >= dhat.
    """
    return _on_active(d, dhat, 0, np.inf)


def barrier_gradient(d: np.ndarray, dhat: float) -> np.ndarray:
    """b'(d) [m] elementwise (<= 0); 0 for d >= dhat. Requires d > 0 where active."""
    return _on_active(d, dhat, 1, 0.0)


def barrier_hessian(d: np.ndarray, dhat: float) -> np.ndarray:
    """b''(d) [-] elementwise (>= 0); 0 for d >= dhat. Requires d > 0 where active."""
    return _on_active(d, dhat, 2, 0.0)


def project_psd(H: np.ndarray) -> np.ndarray:
    """Clamp negative eigenvalues of symmetric blocks (k, d, d) to zero."""
    if len(H) == 0:
        return H
    Hs = 0.5 * (H + np.swapaxes(H, 1, 2))
    w, V = np.linalg.eigh(Hs)
    w = np.maximum(w, 0.0)
    return np.einsum("kij,kj,klj->kil", V, w, V)


def point_barrier(dist: np.ndarray, grad_dist: np.ndarray, hess_dist: np.ndarray | None, dhat: float, kappa: float,
                  *, psd: bool = True):
    """Barrier energy and per-point derivatives from distances and their derivatives.

    Args:
        dist: (k,) distances d_j [m].
        grad_dist: (k, dim) their gradients [-].
        hess_dist: (k, dim, dim) their Hessians [1/m], or None (no Hessian).
        dhat: activation distance [m], a scalar or one per point (k,).
        kappa: barrier stiffness [N/m].
        psd: project each point's Hessian block to PSD.

    Returns:
        (B [J], g (k, dim) [N], H (k, dim, dim) [N/m] or None).
    """
    terms = 2 if hess_dist is None else 3
    if len(dist) and (np.minimum.reduce(dist) <= 0.0 or np.count_nonzero(dist >= dhat)):  # not all active
        b, db, *ddb = _all_terms(dist, dhat, terms)
    else:
        b, db, *ddb = barrier_terms(dist, dhat, terms)
    E = kappa * float(np.add.reduce(b))  # (b.sum() without its wrapper)
    g = kappa * db[:, None] * grad_dist
    if hess_dist is None:
        return E, g, None
    ddb = ddb[0]
    H = kappa * (ddb[:, None, None] * np.einsum("ki,kj->kij", grad_dist, grad_dist) + db[:, None, None] * hess_dist)
    if psd:
        H = project_psd(H)
    return E, g, H
