"""CSR matrix times vector or dense block through scipy's kernels directly.

``A @ v`` on a scipy CSR matrix dispatches through its operator (type and shape checks, about 10 us a
call); the insertion loop's inner work (conjugate gradients, the nodal gradient's scatter, the constraint
points' positions and forces) calls it thousands of times a run on arrays it built itself, so it calls
the kernels behind it, with the same sums in the same order.
"""

from __future__ import annotations

import numpy as np

try:  # the kernels of scipy's CSR @ vector and CSR @ dense (csr_matrix._matmul_vector / _multivector)
    from scipy.sparse import _sparsetools

    _CSR_MATVEC = _sparsetools.csr_matvec
    _CSR_MATVECS = _sparsetools.csr_matvecs
except (ImportError, AttributeError):  # pragma: no cover - another scipy: the operator instead
    _CSR_MATVEC = _CSR_MATVECS = None


def csr_matvec(A, v: np.ndarray) -> np.ndarray:
    """A @ v for a CSR matrix A (m, n) and a vector v (n,): scipy's kernel when v is a contiguous float64
    vector and A's values are float64, else the operator.

    Args:
        A: scipy CSR matrix (m, n).
        v: (n,) vector.

    Returns:
        (m,) float64.
    """
    if (_CSR_MATVEC is None or v.dtype != np.float64 or A.data.dtype != np.float64 or v.ndim != 1
            or not v.flags.c_contiguous):
        return A @ v
    m, n = A.shape
    out = np.zeros(m)
    _CSR_MATVEC(m, n, A.indptr, A.indices, A.data, v, out)
    return out


def csr_times(A, X: np.ndarray) -> np.ndarray:
    """A @ X for a CSR matrix A (m, n) and a dense X (n, c): scipy's kernel when X is C-contiguous float64
    and A's values are float64, else the operator.

    Args:
        A: scipy CSR matrix (m, n).
        X: (n, c) array.

    Returns:
        (m, c) float64.
    """
    m, n = A.shape  # (scipy's shape is a property: read once)
    if (_CSR_MATVECS is None or X.ndim != 2 or X.dtype != np.float64 or A.dtype != np.float64
            or not X.flags.c_contiguous or X.shape[0] != n):
        return A @ X
    out = np.zeros((m, X.shape[1]))
    _CSR_MATVECS(m, n, X.shape[1], A.indptr, A.indices, A.data, X.ravel(), out.ravel())
    return out
