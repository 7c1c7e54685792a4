"""The stress the yield constraint reads: von Mises averaged over a critical distance.

Linear elasticity puts a stress singularity at every sharp re-entrant corner, and the design parts
have such corners (slots, jaw roots): the largest element stress has no mesh-converged value. The
Theory of Critical Distances (Taylor 2007) judges notched parts by the stress averaged over a
material length instead: every element's von Mises stress is replaced by the volume-weighted mean
over the elements whose centroids lie within ``radius`` of its own centroid,

    sigma_bar_e = sum_{f : |c_f - c_e| <= r} V_f sigma_f / sum_{f : ...} V_f

and the constraint reads max_e sigma_bar_e over the insertion. The mean of an integrable
singularity over a fixed ball converges with refinement. The default radius, 0.5 mm, is half of
PLA's critical distance L = (K_IC / sigma_u)^2 / pi (the TCD point method's distance). A mesh
coarser than the radius averages each element with itself (the raw element maximum).

:func:`p2_averaged_von_mises` applies the same definition at the quadrature points of quadratic
(P2) elements, each point a cell of volume V_e w_q at its rest position:

    sigma_bar_q = sum_{p : |X_p - X_q| <= r} V_p sigma_p / sum_{p : ...} V_p

which for linear elements (one point, the centroid) is the element formula above. Full notes (the
singularity's exponent, PLA's K_IC and sigma_u): docs/methods.md, "simfab.design.stress".
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from simfab.fem.p2 import corner_gradients

#: Default averaging radius [m] ([design] stress_radius).
STRESS_RADIUS = 0.5e-3


def averaging_matrix(fem, radius: float) -> sp.csr_matrix:
    """(m, m) row-stochastic matrix A with (A sigma)_e = sigma_bar_e (memoized on ``fem`` per radius)."""
    cache = fem.__dict__.setdefault("_stress_averaging", {}) if hasattr(fem, "__dict__") else {}
    A = cache.get(radius)
    if A is None:
        c = np.asarray(fem.rest, float)[np.asarray(fem.elements)].mean(axis=1)
        A = cache[radius] = _ball_mean_matrix(c, np.abs(np.asarray(fem.volume, float)), radius)
    return A


def averaged_von_mises(fem, von_mises: np.ndarray, radius: float) -> float:
    """max_e sigma_bar_e [Pa] of per-element von Mises stresses (m,) [Pa]."""
    return float((averaging_matrix(fem, radius) @ np.asarray(von_mises, float)).max())


def _ball_mean_matrix(c: np.ndarray, V: np.ndarray, radius: float) -> sp.csr_matrix:
    """(k, k) row-stochastic A, (A s)_i = sum_{|c_j - c_i| <= r} V_j s_j / sum V_j, of cells at c (k, dim)."""
    pairs = cKDTree(c).query_pairs(radius, output_type="ndarray")
    k = len(c)
    rows = np.r_[np.arange(k), pairs[:, 0], pairs[:, 1]]
    cols = np.r_[np.arange(k), pairs[:, 1], pairs[:, 0]]
    A = sp.csr_matrix((V[cols], (rows, cols)), shape=(k, k))
    return (sp.diags(1.0 / np.asarray(A.sum(axis=1)).ravel()) @ A).tocsr()


def quadrature_von_mises(fem, x) -> np.ndarray:
    """von Mises stress (m, nq) [Pa] at a P2 model's quadrature points, deformed positions x (n, dim)
    [m]: F(L) = sum_i L_i F_i from the corner gradients (F is affine over an element), sigma_vm =
    sqrt(3/2) mu |dev(F F^T - I)| / J (:func:`simfab.fem.elastic.det_and_von_mises`; plane strain in
    2D: the out-of-plane entry of F F^T - I is 0); +inf where det F <= 0. J, tr C and |C|^2 of the
    small matrices are written out entry by entry (one array operation over all points each, where
    numpy's batched determinant and product loop over the matrices one at a time: ~6x slower)."""
    Fc = corner_gradients(fem, x)
    m, c, d, _ = Fc.shape
    F = np.matmul(fem.qp_bary, Fc.reshape(m, c, d * d)).reshape(m, -1, d, d)
    f = [[F[..., i, j] for j in range(d)] for i in range(d)]
    if d == 2:
        J = f[0][0] * f[1][1] - f[0][1] * f[1][0]
    else:
        J = (f[0][0] * (f[1][1] * f[2][2] - f[1][2] * f[2][1]) - f[0][1] * (f[1][0] * f[2][2] - f[1][2] * f[2][0])
             + f[0][2] * (f[1][0] * f[2][1] - f[1][1] * f[2][0]))
    tr, sq = 0.0, 0.0  # of C = F F^T - I (symmetric: each off-diagonal entry twice in |C|^2)
    for i in range(d):
        for k in range(i, d):
            cik = sum(f[i][j] * f[k][j] for j in range(d)) - (1.0 if i == k else 0.0)
            if i == k:
                tr = tr + cik
                sq = sq + cik * cik
            else:
                sq = sq + 2.0 * cik * cik
    dev = np.sqrt(1.5 * np.maximum(sq - tr * tr / 3.0, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(J > 0, dev * np.asarray(fem.mu)[:, None] / J, np.inf)


def quadrature_averaging_matrix(fem, radius: float) -> sp.csr_matrix:
    """(m nq, m nq) row-stochastic matrix A averaging a P2 model's quadrature-point stresses
    (element-major, as ``quadrature_von_mises(fem, x).ravel()``) over the points within ``radius``
    [m], weighted by their quadrature weights (memoized on ``fem`` per radius)."""
    cache = fem.__dict__.setdefault("_stress_averaging_qp", {}) if hasattr(fem, "__dict__") else {}
    A = cache.get(radius)
    if A is None:
        c = _qp_rest(fem)
        A = cache[radius] = _ball_mean_matrix(c.reshape(-1, fem.dim), np.abs(np.asarray(fem.qp_weight)).ravel(), radius)
    return A


def p2_averaged_von_mises(fem, x, radius: float) -> float:
    """max_q sigma_bar_q [Pa] of a P2 model at positions x (n, dim) [m] (module docstring;
    :func:`quadrature_averaging_matrix`)."""
    return float((quadrature_averaging_matrix(fem, radius) @ quadrature_von_mises(fem, x).ravel()).max())


def record_averaged_von_mises(fem, record, radius: float) -> float:
    """The averaged von Mises maximum [Pa] of one insertion record (``x``, ``von_mises``) on ``fem``:
    per element (:func:`averaged_von_mises` of the record's element stresses) on linear elements, at
    the quadrature points on P2 (:func:`p2_averaged_von_mises`: the record keeps only each P2
    element's largest point stress, which is biased high and not differentiable)."""
    if getattr(fem, "element_order", 1) == 2:
        return p2_averaged_von_mises(fem, record.x, radius)
    return averaged_von_mises(fem, record.von_mises, radius)


def _qp_rest(fem) -> np.ndarray:
    """Rest positions (m, nq, dim) [m] of a P2 model's quadrature points (affine elements)."""
    corners = np.asarray(fem.rest)[np.asarray(fem.elements)[:, : fem.dim + 1]]
    return np.einsum("qc,mcd->mqd", fem.qp_bary, corners)
