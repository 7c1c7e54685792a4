"""Sparse SPD factorizations on the systems simfab's Newton solves: which library, at which size.

``python tools/bench.py linear_solvers [--repeat 5] [--repeat-2d 200] [--libraries cholmod,pardiso,...] [--no-3d] [--table]``

Systems (stiffness of a Neo-Hookean part slightly stretched, PSD-projected, free block):

- ``knocker3d_p2``: the bundled knocker3d clip (scenes/coupling/knocker3d_part.npz, 4880 tets) with
  quadratic 10-node tets, base face clamped: ~25,000 free dofs, the size of the insertion run
  ``simfab couple simulate knocker3d --element-order 2`` whose factorizations take most of its time;
- ``rect2d``: a 2D rectangle of ~900 linear triangles (~1,000 dofs): the size the rest-shape
  optimizer solves thousands of times, where the fixed cost per call matters.

Per library (those installed): the symbolic analysis once [s], then ``repeat`` numeric
factorizations + one solve each with changed values (the Newton pattern): median wall time [s],
median process CPU time per call [s] (all threads), the relative residual |Ax-b|/|b|, the entries
of the factor where the library reports them. Libraries: ``cholmod`` (cvxopt's CHOLMOD,
supernodal, as SPDSolver uses it: with its OpenBLAS on AVX2 kernels, simfab.solve.linear.
import_cholmod), ``cholmod_simplicial``, ``splu`` (SciPy SuperLU), and when installed ``pardiso``
(MKL PARDISO on both cores, ``pip install mkl``; benchmarks/_pardiso.py) and ``pardiso_1thread``,
``cholespy``, ``qdldl``; ``spdsolver`` is simfab's SPDSolver as it is. No published reference
figure exists for this comparison.

Measured 2026-12-02 on the 2 shared cores at load 6-10 (wall times inflated by other jobs; CPU
times are the steadier figure). On Hessians captured from the knocker3d P2 insertion itself
(23,676 free dofs, 1.71 M entries, one pattern for all 167 solves of a 4-step run, 12 of them
exact repeats of the previous system): CHOLMOD 0.56 s CPU per factorization with the SSE3 kernels
that cvxopt's OpenBLAS 0.3.15 picks on this CPU, 0.27 s with its Haswell kernels (0.28 s
SkylakeX); MKL PARDISO 0.19-0.26 s CPU on one or two threads (6.6 M entries in its factor,
2.8 GFlop); CHOLMOD simplicial 2.9-4.2 s, cholespy (CHOLMOD simplicial) 2.6-3.5 s, qdldl 2.9 s,
SuperLU 1.8 s. This benchmark's run at load 9-10: CHOLMOD 0.368 s wall / 0.221 s CPU, PARDISO
0.338 s / 0.228 s (two threads), 0.390 s / 0.191 s (one). Peak memory of a factorization: CHOLMOD
+132 MB, PARDISO +160 MB, cholespy +210 MB. Installed size: cvxopt 65 MB (already a dependency),
mkl + intel-openmp + tbb 721 MB. Not usable: scikit-sparse and pydiso (no wheel for CPython 3.11
on Linux), python-mumps (its only cp311 wheel, 0.0.2, is built against NumPy 1). On the 2D system
CHOLMOD is fastest (~0.9 ms per call; PARDISO ~1.35 ms: a fixed cost per call). End to end,
``simfab couple simulate knocker3d --element-order 2 --steps 4`` ran no faster with PARDISO than
with the AVX2 CHOLMOD (106-142 s against 82-130 s, alternating runs; 67 s against 61 s of CPU), so
simfab keeps CHOLMOD. Reusing one factorization as the preconditioner of CG on the next Hessians
needed 5-15 CG iterations per Newton step (a refactorization whenever CG needed more than 10-15);
with a solve costing 1/10-1/20 of a factorization this is at best break-even, so simfab factorizes
every Newton step.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time

import numpy as np
import scipy.sparse as sp

from benchmarks._meshes import rect_model

ALL = ("spdsolver", "cholmod", "cholmod_simplicial", "pardiso", "pardiso_1thread", "splu", "cholespy", "qdldl")


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _system(name: str):
    """(A_ff CSR, label): the free block of a stretched part's PSD-projected stiffness."""
    from simfab.fem import elastic
    from simfab.fem.model import make_model

    if name == "knocker3d_p2":
        from simfab.coupling.scene import bundled_dir
        from simfab.fem.p2 import to_p2

        data = np.load(bundled_dir() / "knocker3d_part.npz")
        model = to_p2(make_model(data["points"], data["elements"], "PLA"))
        X = model.rest
        free = np.repeat(X[:, 0] >= X[:, 0].min() + 1e-6, 3)  # base's back face clamped
    else:
        model = rect_model(900)
        X = model.rest
        free = np.repeat(X[:, 0] > X[:, 0].min() + 1e-9, 2)
    x = X * 1.01  # slightly stretched: a Hessian with stress terms, not the rest stiffness
    H = sp.csr_matrix(elastic.energy_gradient_hessian(model, x)[2])
    idx = np.flatnonzero(free.ravel())
    A = sp.csr_matrix(H[idx][:, idx])
    A.sum_duplicates()
    A.sort_indices()
    return A, f"{model.n_elements} elements, order {2 if name == 'knocker3d_p2' else 1}"


def _mkl_threads(n: int) -> None:
    from benchmarks import _pardiso

    _pardiso._load().MKL_Set_Num_Threads(int(n))


def _lower_order(A: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(perm, rows, cols): A.data[perm] is the lower triangle column after column (= the upper
    triangle row after row), at (rows, cols); A canonical CSR. As SPDSolver's value map, so that
    the timings hold no per-call triangle extraction."""
    n = A.shape[0]
    rows = np.repeat(np.arange(n), np.diff(A.indptr))
    low = np.flatnonzero(A.indices <= rows)
    r, c = rows[low], A.indices[low]
    order = np.lexsort((r, c))
    return low[order], r[order], c[order]


def _library(name: str, A: sp.csr_matrix):
    """(analyse(), factor(M), solve(b), factor_nnz()) for one library (M: A's pattern, new
    values), or None when the library is not installed."""
    n = A.shape[0]
    st: dict = {}
    if name == "spdsolver":
        from simfab.solve.linear import SPDSolver

        s = SPDSolver()
        return (lambda: None, lambda M: st.__setitem__("M", M), lambda b: s.solve(st["M"], b), lambda: None)
    if name.startswith("cholmod"):
        from simfab.solve.linear import import_cholmod

        cholmod = import_cholmod()  # with the machine's BLAS kernels, as SPDSolver uses it
        import cvxopt

        def analyse():
            perm, r, c = st["map"] = _lower_order(A)
            st["A"] = cvxopt.spmatrix(cvxopt.matrix(A.data[perm]), cvxopt.matrix(r.astype(np.int64)),
                                      cvxopt.matrix(c.astype(np.int64)), (n, n))
            cholmod.options["supernodal"] = 0 if name == "cholmod_simplicial" else 2
            st["F"] = cholmod.symbolic(st["A"])
            cholmod.options["supernodal"] = 2

        def factor(M):
            st["A"].V = cvxopt.matrix(M.data[st["map"][0]])
            cholmod.numeric(st["A"], st["F"])

        def solve(b):
            x = cvxopt.matrix(b.copy())
            cholmod.solve(st["F"], x)
            return np.array(x).ravel()

        return analyse, factor, solve, lambda: None
    if name.startswith("pardiso"):
        from benchmarks import _pardiso as pardiso

        if not pardiso.available():  # pip install mkl
            return None

        def analyse():
            _mkl_threads(1 if name == "pardiso_1thread" else 2)
            perm, r, c = st["map"] = _lower_order(A)
            st["P"] = pardiso.PardisoCholesky(np.concatenate([[0], np.cumsum(np.bincount(c, minlength=n))]), r)

        def factor(M):
            st["P"].factor(M.data[st["map"][0]])

        return analyse, factor, lambda b: st["P"].solve(b), lambda: st["P"].factor_nnz
    if name == "splu":
        from scipy.sparse.linalg import splu

        def factor(M):
            st["lu"] = splu(sp.csc_matrix(M), permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})

        return (lambda: None, factor, lambda b: st["lu"].solve(b),
                lambda: int(st["lu"].L.nnz + st["lu"].U.nnz))
    if name == "cholespy":
        try:
            import cholespy
        except ImportError:
            return None

        def factor(M):
            C = sp.csr_matrix(M)
            st["s"] = cholespy.CholeskySolverD(n, C.indptr.astype(np.int32), C.indices.astype(np.int32),
                                               C.data, cholespy.MatrixType.CSR)

        def solve(b):
            x = np.zeros_like(b)
            st["s"].solve(b, x)
            return x

        return lambda: None, factor, solve, lambda: None
    if name == "qdldl":
        try:
            import qdldl
        except ImportError:
            return None

        def analyse():
            st["s"] = qdldl.Solver(sp.csc_matrix(A))

        return analyse, lambda M: st["s"].update(sp.csc_matrix(M)), lambda b: st["s"].solve(b), lambda: None
    raise ValueError(f"unknown library {name!r}")


def _measure(name: str, A: sp.csr_matrix, repeat: int, rng) -> dict | None:
    lib = _library(name, A)
    if lib is None:
        return None
    analyse, factor, solve, factor_nnz = lib
    t0 = time.perf_counter()
    analyse()
    t_an = time.perf_counter() - t0
    walls, cpus, res = [], [], []
    for k in range(repeat + 1):  # the first call also warms up (first numeric factorization, kernels)
        M = A.copy()
        M.data *= 1.0 + 0.1 * k  # new values, same pattern
        b = rng.standard_normal(A.shape[0])
        c0, t0 = _cpu(), time.perf_counter()
        factor(M)
        x = solve(b)
        t1, c1 = time.perf_counter(), _cpu()
        res.append(float(np.linalg.norm(M @ x - b) / np.linalg.norm(b)))
        if k:
            walls.append(t1 - t0)
            cpus.append(c1 - c0)
    nnz = factor_nnz()
    return dict(library=name, analyse_s=round(t_an, 4), factor_solve_s=float(f"{np.median(walls):.4g}"),
                cpu_per_call_s=float(f"{np.median(cpus):.4g}"), max_rel_residual=float(f"{max(res):.2g}"),
                factor_nnz=None if not nnz else int(nnz))


def run(argv) -> dict:
    ap = argparse.ArgumentParser(prog="bench.py linear_solvers", description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5, help="numeric factorizations per library, 3D (after one warm-up)")
    ap.add_argument("--repeat-2d", type=int, default=200, help="the same for the small 2D system")
    ap.add_argument("--libraries", default=",".join(ALL), help=f"comma-separated subset of {','.join(ALL)}")
    ap.add_argument("--no-3d", action="store_true", help="only the small 2D system")
    ap.add_argument("--table", action="store_true", help="also print a table on stderr")
    a = ap.parse_args(argv)
    names = [s for s in a.libraries.split(",") if s]
    rng = np.random.default_rng(0)
    out = {"benchmark": "linear_solvers", "reference": None,
           "note": "no published reference; wall times on 2 shared cores, CPU time counts all threads"}
    for system in (["rect2d"] if a.no_3d else ["rect2d", "knocker3d_p2"]):
        A, label = _system(system)
        slow = {"cholmod_simplicial", "cholespy", "qdldl", "splu"}
        reps = {nm: a.repeat_2d if system == "rect2d" else (1 if nm in slow else a.repeat) for nm in names}
        rows = [_measure(nm, A, reps[nm], rng) for nm in names]
        rows = [r for r in rows if r is not None]
        ref = next((r["factor_solve_s"] for r in rows if r["library"] == "cholmod"), None)
        for r in rows:
            r["speedup_vs_cholmod"] = None if not ref else round(ref / r["factor_solve_s"], 2)
        out[system] = {"mesh": label, "dofs": A.shape[0], "nnz": A.nnz, "rows": rows}
        if a.table:
            print(f"{system}: {label}, {A.shape[0]} free dofs, {A.nnz} entries", file=sys.stderr)
            print(f"{'library':20s} {'analyse s':>10s} {'factor+solve s':>15s} {'CPU s/call':>11s} "
                  f"{'residual':>9s} {'factor nnz':>11s} {'vs CHOLMOD':>10s}", file=sys.stderr)
            for r in rows:
                print(f"{r['library']:20s} {r['analyse_s']:10.3g} {r['factor_solve_s']:15.4g} {r['cpu_per_call_s']:11.4g} "
                      f"{r['max_rel_residual']:9.1e} {str(r['factor_nnz'] or '-'):>11s} "
                      f"{str(r['speedup_vs_cholmod'] or '-'):>10s}", file=sys.stderr)
    return out
