"""Thread limits of the BLAS libraries around simfab's solver loops.

NumPy's and SciPy's OpenBLAS (``libscipy_openblas``) use every core for a matrix-vector product,
and a product that takes microseconds then waits for the library's helper threads to wake. The
insertion loop's small dense products (the rigid-mode pin, U^T x with U (N, r <= 6), and its
Woodbury solve) run much faster on one thread (docs/decisions.md, "One BLAS thread in the
insertion loop"). The big linear algebra
does not go through that library: sparse factorizations run in CHOLMOD (cvxopt's own OpenBLAS) or
MKL PARDISO, whose threads are left alone.
"""

from __future__ import annotations

import contextlib

_SELECTION = None


@contextlib.contextmanager
def single_threaded_blas():
    """Within the block NumPy's / SciPy's OpenBLAS run on one thread (restored afterwards)."""
    global _SELECTION
    if _SELECTION is None:
        from threadpoolctl import ThreadpoolController

        _SELECTION = ThreadpoolController().select(prefix="libscipy_openblas")
    with _SELECTION.limit(limits=1):
        yield
