"""Thread limits of the BLAS libraries around simfab's solver loops.

NumPy's and SciPy's OpenBLAS (``libscipy_openblas``) use every core for a matrix-vector product,
and a product that takes microseconds then waits for the library's helper threads to wake: in the
insertion loop's small dense products (the rigid-mode pin, U^T x with U (N, r <= 6); its Woodbury
solve) that cost 15-28 ms per call on clip3d's 19k unknowns at load ~7, 0.3-1 ms with one thread
(``python tools/bench.py insertion``; the same 10-step clip3d run, profiled: the pin's energy
17.9 -> 0.28 ms, gradient 15 -> 0.40 ms, Woodbury solve 28 -> 1.1 ms per call). The big linear
algebra does not go through that library: sparse factorizations run in CHOLMOD (cvxopt's own
OpenBLAS) or MKL PARDISO, whose threads are left alone.
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
