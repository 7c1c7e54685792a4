"""Sparse Cholesky through Intel MKL PARDISO (the ``mkl`` wheel's ``libmkl_rt``), called via ctypes:
the PARDISO rows of ``tools/bench.py linear_solvers`` (when ``pip install mkl`` was run).

simfab does not use it: with cvxopt's OpenBLAS on its AVX2 kernels (simfab.solve.linear.import_cholmod)
CHOLMOD takes the same CPU time per factorization as PARDISO on the 3D P2 insertion Hessians, and
the knocker3d P2 insertion ran no faster end to end with PARDISO on the 2 shared cores, so the
~700 MB MKL dependency did not pay (see the benchmark's docstring). A handle for one sparsity pattern
(upper triangle, CSR, zero-based) with a symbolic analysis (phase 11: METIS nested-dissection
ordering and the supernode tree) done once, then numeric factorizations (phase 22) and solves
(phase 33) reusing it. The matrix type is real SPD (mtype 2): a non-positive pivot is reported
as error -4 and a PardisoError with code NOT_POSITIVE_DEFINITE (what simfab's Newton solver would need to tell an
indefinite exact Hessian from a positive-definite one).

``mkl`` has wheels for x86-64 only; :func:`available` says whether the library loaded.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import glob
import os
import sys
import weakref

import numpy as np

_LIB = None  # the loaded mkl_rt, False when it could not be loaded

# PARDISO error codes (MKL reference, pardiso "error" argument)
_ERRORS = {-1: "input inconsistent", -2: "not enough memory", -3: "reordering problem",
           -4: "zero or negative pivot", -5: "unclassified (internal) error", -6: "reordering failed",
           -7: "diagonal matrix is singular", -8: "32-bit integer overflow", -9: "not enough memory for OOC",
           -10: "error opening OOC files", -11: "read/write error with OOC files"}
NOT_POSITIVE_DEFINITE = -4


class PardisoError(RuntimeError):
    """PARDISO returned a non-zero error code (``code``)."""

    def __init__(self, code: int, phase: int):
        self.code = code
        super().__init__(f"MKL PARDISO phase {phase}: error {code} ({_ERRORS.get(code, 'unknown')})")


def _load():
    """Load libmkl_rt once: the ``mkl`` wheel puts it in ``<prefix>/lib``; a system MKL is found
    by the loader. Returns the ctypes library or None."""
    global _LIB
    if _LIB is None:
        # MKL's OpenMP threads otherwise spin for 200 ms after each factorization, taking a core
        # from whatever runs next (assembly, other processes); waking them costs microseconds.
        # Read when the OpenMP runtime starts (the first factorization); a user's setting wins.
        os.environ.setdefault("KMP_BLOCKTIME", "0")
        names = [ctypes.util.find_library("mkl_rt")]
        for prefix in dict.fromkeys((sys.prefix, sys.base_prefix)):
            names += sorted(glob.glob(os.path.join(prefix, "lib", "libmkl_rt.so*")), key=len)
        _LIB = False
        for name in filter(None, names):
            try:
                lib = ctypes.CDLL(name)
                lib.pardiso  # noqa: B018 - the symbol must exist
            except (OSError, AttributeError):
                continue
            _set_prototypes(lib)
            _LIB = lib
            break
    return _LIB or None


def available() -> bool:
    """Whether MKL PARDISO can be used (the ``mkl`` wheel is installed on an x86-64 machine)."""
    return _load() is not None


def _set_prototypes(lib) -> None:
    i32p = ctypes.POINTER(ctypes.c_int32)
    lib.pardiso.argtypes = [ctypes.c_void_p, i32p, i32p, i32p, i32p, i32p, ctypes.c_void_p, i32p, i32p,
                            i32p, i32p, i32p, i32p, ctypes.c_void_p, ctypes.c_void_p, i32p]
    lib.pardiso.restype = None


def _iparm() -> np.ndarray:
    """PARDISO control parameters (MKL's 1-based iparm(k) is ``p[k-1]`` here)."""
    p = np.zeros(64, dtype=np.int32)
    p[0] = 1  # not all defaults: the values below are used
    p[1] = 2  # fill-in reducing ordering: METIS nested dissection
    p[7] = 0  # iterative refinement: only when pivots were perturbed (never for SPD input)
    p[9] = 13  # pivot perturbation 1e-13 (not used by the Cholesky of mtype 2)
    p[17] = -1  # report the number of entries in the factor (iparm(18))
    p[34] = 1  # zero-based ia/ja (C indexing): no index copies per call
    return p


class PardisoCholesky:
    """Cholesky factorization of a real SPD matrix of one fixed sparsity pattern with MKL PARDISO.

    Parameters
    ----------
    indptr, indices : CSR pattern of the *upper* triangle (diagonal included), zero-based,
        column indices sorted within each row; (n+1,) and (nnz,) int.

    ``factor(values)`` takes the (nnz,) float64 values in that pattern's order; ``solve(b)`` takes
    b (n,) or (n, k) and returns x of the same shape. The MKL memory of the factorization is freed
    when the object is garbage collected.
    """

    _MAXFCT = ctypes.c_int32(1)
    _MNUM = ctypes.c_int32(1)
    _MTYPE = ctypes.c_int32(2)  # real symmetric positive definite
    _MSGLVL = ctypes.c_int32(0)

    def __init__(self, indptr: np.ndarray, indices: np.ndarray):
        lib = _load()
        if lib is None:  # pragma: no cover - callers check available()
            raise RuntimeError("MKL PARDISO is not available (pip install mkl)")
        self._lib = lib
        self.n = len(indptr) - 1
        self._ia = np.ascontiguousarray(indptr, dtype=np.int32)
        self._ja = np.ascontiguousarray(indices, dtype=np.int32)
        self._a = np.zeros(len(self._ja))
        self._pt = np.zeros(64, dtype=np.int64)  # PARDISO's internal handle (64 pointers)
        self._iparm = _iparm()
        self._perm = np.zeros(1, dtype=np.int32)
        self._factored = False
        self._call(11, self._a, None)  # symbolic analysis: depends on the pattern only
        weakref.finalize(self, _release, lib, self._pt, self._ia, self._ja, self.n)

    @property
    def factor_nnz(self) -> int:
        """Entries in the factor (PARDISO iparm(18), after the analysis)."""
        return int(self._iparm[17])

    def factor(self, values: np.ndarray) -> None:
        """Numeric Cholesky factorization with ``values`` (nnz,) in the pattern's order. Raises
        PardisoError (code NOT_POSITIVE_DEFINITE for a matrix that is not positive definite)."""
        np.copyto(self._a, values)  # PARDISO keeps pointers between phases: keep our own copy
        self._factored = False
        self._call(22, self._a, None)
        self._factored = True

    def solve(self, b: np.ndarray) -> np.ndarray:
        """x with A x = b for the last factorized A; b (n,) or (n, k)."""
        if not self._factored:
            raise RuntimeError("PardisoCholesky.solve before a successful factor")
        b = np.asarray(b, dtype=np.float64)
        bf = np.asfortranarray(b.reshape(self.n, -1))  # PARDISO: right-hand sides column after column
        return self._call(33, self._a, bf).reshape(b.shape)

    def _call(self, phase: int, a: np.ndarray, b: np.ndarray | None) -> np.ndarray | None:
        nrhs = 1 if b is None else b.shape[1]
        x = None if b is None else np.empty_like(b, order="F")
        err = ctypes.c_int32(0)
        i32p = ctypes.POINTER(ctypes.c_int32)
        self._lib.pardiso(self._pt.ctypes.data, ctypes.byref(self._MAXFCT), ctypes.byref(self._MNUM),
                          ctypes.byref(self._MTYPE), ctypes.byref(ctypes.c_int32(phase)),
                          ctypes.byref(ctypes.c_int32(self.n)), a.ctypes.data, self._ia.ctypes.data_as(i32p),
                          self._ja.ctypes.data_as(i32p), self._perm.ctypes.data_as(i32p),
                          ctypes.byref(ctypes.c_int32(nrhs)), self._iparm.ctypes.data_as(i32p),
                          ctypes.byref(self._MSGLVL), None if b is None else b.ctypes.data,
                          None if x is None else x.ctypes.data, ctypes.byref(err))
        if err.value != 0:
            raise PardisoError(int(err.value), phase)
        return x


def _release(lib, pt, ia, ja, n) -> None:
    """Phase -1: free all of PARDISO's memory for the handle ``pt``."""
    err = ctypes.c_int32(0)
    i32p = ctypes.POINTER(ctypes.c_int32)
    one, mtype, msg = ctypes.c_int32(1), ctypes.c_int32(2), ctypes.c_int32(0)
    iparm = _iparm()
    dummy = np.zeros(1)
    perm = np.zeros(1, dtype=np.int32)
    lib.pardiso(pt.ctypes.data, ctypes.byref(one), ctypes.byref(one), ctypes.byref(mtype),
                ctypes.byref(ctypes.c_int32(-1)), ctypes.byref(ctypes.c_int32(n)), dummy.ctypes.data,
                ia.ctypes.data_as(i32p), ja.ctypes.data_as(i32p), perm.ctypes.data_as(i32p), ctypes.byref(one),
                iparm.ctypes.data_as(i32p), ctypes.byref(msg), None, None, ctypes.byref(err))
