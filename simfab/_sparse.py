"""CSR matrix times vector through scipy's kernel directly.

``A @ v`` on a scipy CSR matrix dispatches through its operator (type and shape checks, about 10 us a
call); the solvers' inner loops (conjugate gradients, the nodal gradient's scatter) call it thousands of
times a run on vectors they built themselves, so they call the kernel behind it with the same sums.
"""

from __future__ import annotations

import numpy as np

try:  # the kernel of scipy's CSR @ vector (csr_matrix._matmul_vector)
    from scipy.sparse import _sparsetools

    _CSR_MATVEC = _sparsetools.csr_matvec
except (ImportError, AttributeError):  # pragma: no cover - another scipy: the operator instead
    _CSR_MATVEC = None


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
