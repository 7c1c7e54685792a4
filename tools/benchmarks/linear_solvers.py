"""Sparse SPD factorizations on the systems simfab's Newton solves: which library, at which size.

``python tools/bench.py linear_solvers [--repeat 5] [--repeat-2d 200] [--libraries cholmod,pardiso,...]
[--no-3d] [--table]``; ``--amg``, ``--ordering`` and ``--pmg`` (CG with the two-level P2 -> P1
p-multigrid of simfab.solve.pmg) compare CHOLMOD with the alternatives at the large end on the
insertion scaling levels' Hessians (docs/benchmarks.md, section 1b).

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

simfab keeps CHOLMOD (supernodal, AVX2 kernels) and factorizes at every Newton step: on the
knocker3d P2 Hessians MKL PARDISO is no faster end to end, and reusing a factorization as the
preconditioner of CG on the next Hessians is at best break-even (a solve costs 1/10-1/20 of a
factorization, CG needs 5-15 iterations). The measurements are in docs/decisions.md ("Sparse
factorization").
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
    ap.add_argument("--amg", action="store_true",
                    help="CHOLMOD against pyamg's smoothed-aggregation AMG + CG on clip3d's P2 Hessians at --factors")
    ap.add_argument("--factors", default="1,2,4,8", help="--amg: clip3d's tet-count factors (insertion --scaling's)")
    ap.add_argument("--ordering", default=None, metavar="SCENE:F,F,...;SCENE:F,...",
                    help="CHOLMOD's AMD ordering against METIS nested dissection (pymetis) on the scaling levels' "
                         "Hessians, e.g. 'clip3d:1,2,4,8;claw3d:1,2,4'")
    ap.add_argument("--pmg", default=None, metavar="SCENE:F,F,...;SCENE:F,...",
                    help="CHOLMOD against CG preconditioned by the two-level P2 -> P1 p-multigrid "
                         "(simfab.solve.pmg) on the scaling levels' Hessians at rest and mid-insertion, "
                         "e.g. 'clip3d:1,2,4,8;claw3d:1,2'")
    ap.add_argument("--smoothers", default="chebyshev:2,chebyshev:3,sgs:2", metavar="KIND:SWEEPS,...",
                    help="--pmg: the smoothers compared (sgs needs pyamg)")
    ap.add_argument("--snapshots", type=int, default=2,
                    help="--pmg: mid-insertion Hessians per level (the first Newton solve of steps spread over "
                         "the insertion; 0: the rest shape's only)")
    a = ap.parse_args(argv)
    if a.pmg:
        from simfab.errors import InputError

        try:
            levels = [(sc, float(f)) for part in a.pmg.split(";") for sc, fs in [part.split(":")]
                      for f in fs.split(",")]
            smoothers = [(k, int(n)) for k, n in (t.split(":") for t in a.smoothers.split(","))]
        except ValueError:
            raise InputError(f"--pmg must be SCENE:F,F;SCENE:F and --smoothers KIND:N,KIND:N, got {a.pmg!r}, "
                             f"{a.smoothers!r}") from None
        return pmg_against_cholmod(levels, smoothers, a.snapshots)
    if a.amg:
        return amg_against_cholmod([float(f) for f in a.factors.split(",")])
    if a.ordering:
        from simfab.errors import InputError

        try:
            levels = [(sc, float(f)) for part in a.ordering.split(";") for sc, fs in [part.split(":")]
                      for f in fs.split(",")]
        except ValueError:
            raise InputError(f"--ordering must be SCENE:F,F;SCENE:F, got {a.ordering!r}") from None
        return ordering_against_amd(levels)
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
                print(f"{r['library']:20s} {r['analyse_s']:10.3g} {r['factor_solve_s']:15.4g} "
                      f"{r['cpu_per_call_s']:11.4g} {r['max_rel_residual']:9.1e} {str(r['factor_nnz'] or '-'):>11s} "
                      f"{str(r['speedup_vs_cholmod'] or '-'):>10s}", file=sys.stderr)
    return out


def rigid_modes(X: np.ndarray) -> np.ndarray:
    """(n dim, 6 or 3) the rigid-body motions of points X (n, dim): translations and linearized
    rotations, the near-null space of elasticity that smoothed aggregation keeps on every level."""
    n, dim = X.shape
    c = X - X.mean(0)
    cols = []
    for k in range(dim):
        t = np.zeros((n, dim))
        t[:, k] = 1.0
        cols.append(t.ravel())
    axes = [(0, 1), (1, 2), (0, 2)] if dim == 3 else [(0, 1)]
    for i, j in axes:
        r = np.zeros((n, dim))
        r[:, i], r[:, j] = -c[:, j], c[:, i]
        cols.append(r.ravel())
    return np.column_stack(cols)


def amg_against_cholmod(factors) -> dict:
    """Per clip3d level (P2, the insertion benchmark's case at FACTOR x its tets; the free block of
    the PSD Hessian at the rest shape, the rigid-mode regularization included, as the floor uses):
    CHOLMOD's analysis and numeric factorization + solve (fastest of 2), and pyamg's smoothed
    aggregation (rigid-body near-null space, symmetric strength, Jacobi prolongation smoothing)
    setup and CG to a relative residual of 1e-2 (an inexact-Newton forcing term) and 1e-8."""
    import pyamg
    from scipy.sparse.linalg import cg

    from benchmarks._scaling import level_overrides
    from benchmarks.insertion import ORIGINAL_SIZE
    from simfab.coupling.layout import regularize
    from simfab.coupling.scene import load_coupling_scene
    from simfab.fem.elastic import energy_gradient_hessian
    from simfab.solve.linear import SPDSolver

    rows = []
    for f in factors:
        base = {k: dict(v) for k, v in ORIGINAL_SIZE["clip3d"].items()}
        cm = load_coupling_scene("clip3d", overrides={"compliant": level_overrides("clip3d", f, base)})
        X = np.asarray(cm.fem.rest)
        _, _, H = energy_gradient_hessian(cm.fem, X)
        regularize(cm, H)
        free = np.flatnonzero(np.asarray(cm.free).ravel())
        A = sp.csr_matrix(H)[free][:, free].tocsr()
        b = np.random.default_rng(0).standard_normal(len(free))
        s = SPDSolver()
        t0, c0 = time.perf_counter(), _cpu()
        s.solve(A, b)
        t_first = time.perf_counter() - t0
        best = (np.inf, np.inf)
        for _ in range(2):
            A.data *= 1.0 + 1e-9
            t0, c0 = time.perf_counter(), _cpu()
            x = s.solve(A, b)
            best = min(best, (time.perf_counter() - t0, _cpu() - c0))
        res_ch = float(np.linalg.norm(A @ x - b) / np.linalg.norm(b))
        B = rigid_modes(X)[free]
        t0, c0 = time.perf_counter(), _cpu()
        ml = pyamg.smoothed_aggregation_solver(A, B=B, symmetry="symmetric", strength=("symmetric", {"theta": 0.0}),
                                               smooth="jacobi", max_coarse=500)
        t_setup, c_setup = time.perf_counter() - t0, _cpu() - c0
        M = ml.aspreconditioner(cycle="V")
        row = {"factor": f, "tets": int(cm.fem.n_elements), "free_dofs": int(len(free)), "nnz": int(A.nnz),
               "cholmod_first_s": round(t_first, 3), "cholmod_factor_solve_s": round(best[0], 3),
               "cholmod_factor_solve_cpu_s": round(best[1], 3), "cholmod_residual": res_ch,
               "amg_setup_s": round(t_setup, 3), "amg_setup_cpu_s": round(c_setup, 3),
               "amg_levels": len(ml.levels), "amg_operator_complexity": round(float(ml.operator_complexity()), 2)}
        for rtol in (1e-2, 1e-8):
            it = [0]
            t0, c0 = time.perf_counter(), _cpu()
            y, info = cg(A, b, rtol=rtol, maxiter=2000, M=M, callback=lambda _x: it.__setitem__(0, it[0] + 1))
            key = f"cg_{rtol:g}"
            row[key] = {"iterations": it[0], "seconds": round(time.perf_counter() - t0, 3),
                        "cpu_seconds": round(_cpu() - c0, 3), "converged": info == 0,
                        "residual": float(np.linalg.norm(A @ y - b) / np.linalg.norm(b))}
        rows.append(row)
        print(f"x{f:g} {row['tets']} tets {row['free_dofs']} dofs: CHOLMOD {row['cholmod_factor_solve_s']} s; "
              f"AMG setup {row['amg_setup_s']} s, CG 1e-2 {row['cg_0.01']}, 1e-8 {row['cg_1e-08']}", file=sys.stderr)
    return {"benchmark": "linear_solvers --amg", "system": "clip3d P2 free Hessian at rest (PSD, regularized)",
            "rows": rows}


def _level_hessian(scene: str, factor: float):
    """(A_ff CSR, node of each free dof): the free block of the insertion-scaling level's PSD Hessian
    at the rest shape, the rigid-mode regularization included (as the factorization floor uses)."""
    from benchmarks._scaling import level_overrides
    from benchmarks.insertion import ORIGINAL_SIZE
    from simfab.coupling.layout import regularize
    from simfab.coupling.scene import load_coupling_scene
    from simfab.fem.elastic import energy_gradient_hessian

    base = {k: dict(v) for k, v in ORIGINAL_SIZE.get(scene, {}).items()}
    cm = load_coupling_scene(scene, overrides={**base, "compliant": level_overrides(scene, factor, base)})
    _, _, H = energy_gradient_hessian(cm.fem, np.asarray(cm.fem.rest))
    regularize(cm, H)
    free = np.flatnonzero(np.asarray(cm.free).ravel())
    return sp.csr_matrix(H)[free][:, free].tocsr(), free // cm.dim, int(cm.fem.n_elements)


def nested_dissection(A: sp.csr_matrix, node: np.ndarray) -> np.ndarray:
    """A fill-reducing permutation of A's unknowns (new -> old): METIS nested dissection of the mesh's
    vertex graph (the unknowns of one vertex kept together)."""
    try:
        import pymetis
    except ImportError:
        from simfab.errors import InputError

        raise InputError("--ordering needs pymetis (pip install pymetis)") from None
    uniq, nid = np.unique(node, return_inverse=True)
    P = sp.csr_matrix((np.ones(len(nid)), (np.arange(len(nid)), nid)), shape=(len(nid), len(uniq)))
    G = (P.T @ (abs(A) > 0).astype(float) @ P).tocsr()
    G.setdiag(0)
    G.eliminate_zeros()
    order_nodes = np.asarray(pymetis.nested_dissection(pymetis.CSRAdjacency(G.indptr, G.indices))[0])
    by_node = np.argsort(nid, kind="stable")
    starts = np.concatenate([[0], np.cumsum(np.bincount(nid, minlength=len(uniq)))])
    return np.concatenate([by_node[starts[k]:starts[k + 1]] for k in order_nodes])


def ordering_against_amd(levels) -> dict:
    """Per (scene, factor): entries of CHOLMOD's supernodal factor L and the factorization's flops
    (sum of the squared column counts of L), the ordering's CPU seconds and
    the numeric factorization's and a solve's CPU seconds (fastest of 3) with CHOLMOD's own ordering
    (cvxopt's CHOLMOD is built without METIS: AMD) and with METIS nested dissection (``pymetis``)."""
    import cvxopt

    from simfab.solve.linear import import_cholmod

    cholmod = import_cholmod()
    rows = []
    for scene, f in levels:
        A, node, tets = _level_hessian(scene, f)
        lo = sp.tril(A).tocoo()
        row = {"scene": scene, "factor": f, "tets": tets, "free_dofs": A.shape[0], "nnz": int(A.nnz)}
        for label in ("amd", "metis_nd"):
            Ac = cvxopt.spmatrix(cvxopt.matrix(lo.data), cvxopt.matrix(lo.row.astype(np.int64)),
                                 cvxopt.matrix(lo.col.astype(np.int64)), A.shape)
            c0 = _cpu()
            perm = None if label == "amd" else nested_dissection(A, node)
            t_order = _cpu() - c0
            saved = dict(cholmod.options)
            cholmod.options["supernodal"] = 1
            cholmod.options["nmethods"] = 0 if perm is None else 1  # 1: the given permutation only
            try:
                F = (cholmod.symbolic(Ac) if perm is None
                     else cholmod.symbolic(Ac, p=cvxopt.matrix(perm.astype(np.int64))))
            finally:  # CHOLMOD keeps a setting once made: nmethods back to its default, 0
                cholmod.options.clear()
                cholmod.options.update({"nmethods": 0, **saved})
            fact, solve = np.inf, np.inf
            for _ in range(3):
                c0 = _cpu()
                cholmod.numeric(Ac, F)
                fact = min(fact, _cpu() - c0)
                x = cvxopt.matrix(np.ones(A.shape[0]))
                c0 = _cpu()
                cholmod.solve(F, x)
                solve = min(solve, _cpu() - c0)
            L = cholmod.getfactor(F)
            counts = np.bincount(np.asarray(L.J, dtype=np.int64).ravel(), minlength=A.shape[0]).astype(float)
            row[label] = {"factor_entries": len(L.V), "factor_gflop": round(float(counts @ counts) / 1e9, 3),
                          "ordering_cpu_s": round(t_order, 3),
                          "factorization_cpu_s": round(fact, 3), "solve_cpu_s": round(solve, 4)}
        rows.append(row)
        print(f"{scene} x{f:g} {row['free_dofs']} dofs: AMD {row['amd']}; METIS ND {row['metis_nd']}", file=sys.stderr)
    return {"benchmark": "linear_solvers --ordering", "system": "free PSD Hessian at rest (regularized)", "rows": rows}


class _Captured(Exception):
    """Stops an insertion once its Hessians are captured."""


def _insertion_systems(cm, count: int) -> list:
    """``count`` Newton systems of ``cm``'s insertion run with direct solves (the first solve of steps
    spread evenly over the insertion's steps, after the first): dicts with the free block A (CSR), b,
    the pin's U (free rows) and mu (None, 0.0 without a pin), the diagonal shift the direct solver
    factorized A with (where A alone is indefinite along the pinned motions,
    simfab.coupling.rigid.PinnedSolver) and the step."""
    from simfab.coupling import stepper
    from simfab.coupling.simulate import simulate_insertion
    from simfab.solve import linear

    n_steps = len(cm.s_steps)
    picks = [int(round(n_steps * (k + 1) / (count + 1))) for k in range(count)]
    state = {"step": 0, "taken": set()}
    out = []

    def record(A, free, b, U=None, mu=0.0, shift=0.0):
        step = state["step"]
        if picks and step >= picks[0] and step not in state["taken"] and np.ndim(b) == 1:
            state["taken"].add(step)
            picks.pop(0)
            A = sp.csr_matrix(A)[free][:, free].tocsr()
            out.append({"A": A, "b": np.array(b, dtype=float), "U": None if U is None else np.array(U),
                        "mu": float(mu), "shift": float(shift), "step": step})
            if not picks:
                raise _Captured

    orig_free, orig_update = linear.SPDSolver.solve_free, linear.SPDSolver.solve_free_update

    def solve_free(self, A, free, b):
        record(A, free, b)
        return orig_free(self, A, free, b)

    def solve_free_update(self, A, free, b, U, mu, shift=0.0):
        record(A, free, b, U, mu, shift)
        return orig_update(self, A, free, b, U, mu, shift)

    def callback(k, _step):
        state["step"] = k + 1

    linear.SPDSolver.solve_free, linear.SPDSolver.solve_free_update = solve_free, solve_free_update
    # every Newton system through the direct solver (no lagged or multigrid solve bypasses the capture)
    orig_step_solver, stepper.step_solver = stepper.step_solver, lambda _model: linear.SPDSolver()
    try:
        simulate_insertion(cm, callback=callback)
    except _Captured:
        pass
    finally:
        linear.SPDSolver.solve_free, linear.SPDSolver.solve_free_update = orig_free, orig_update
        stepper.step_solver = orig_step_solver
    return out


def pmg_against_cholmod(levels, smoothers, snapshots: int) -> dict:
    """Per (scene, factor) and per system (the rest shape's free PSD Hessian, regularized, as the floor
    uses, with a random right-hand side; then ``snapshots`` Newton systems of the insertion, the pin's
    rank-6 term included, with their own right-hand sides): CHOLMOD's numeric factorization + solve
    (CPU seconds, fastest of 2, its analysis done before) against CG preconditioned by
    :class:`simfab.solve.pmg.TwoLevelP2` per smoother: setup CPU seconds (the Galerkin product, the
    coarse factorization, the eigenvalue estimate; fastest of 2 repeated setups, as the run's later
    Newton solves do them: the coarse analysis done before, the power method warm-started), CG
    iterations and CPU seconds to relative residuals 1e-2 and 1e-8, and the error against CHOLMOD's
    solution at 1e-8. NumPy's BLAS on one thread, as in the insertion loop."""
    from benchmarks._scaling import level_overrides
    from benchmarks.insertion import ORIGINAL_SIZE
    from simfab._threads import single_threaded_blas
    from simfab.coupling.layout import regularize
    from simfab.coupling.scene import load_coupling_scene
    from simfab.fem.elastic import energy_gradient_hessian
    from simfab.solve.linear import SPDSolver, conjugate_gradients
    from simfab.solve.pmg import SmootherConfig, TwoLevelP2, corner_prolongation

    rows = []
    for scene, f in levels:
        base = {k: dict(v) for k, v in ORIGINAL_SIZE.get(scene, {}).items()}
        cm = load_coupling_scene(scene, overrides={**base, "compliant": level_overrides(scene, f, base)})
        m = cm.fem
        free = np.flatnonzero(np.asarray(cm.free).ravel())
        _, _, H = energy_gradient_hessian(m, np.asarray(m.rest))
        regularize(cm, H)
        A0 = sp.csr_matrix(H)[free][:, free].tocsr()
        systems = [{"A": A0, "b": np.random.default_rng(0).standard_normal(len(free)), "U": None, "mu": 0.0,
                    "shift": 0.0, "step": None}]
        if snapshots:
            systems += _insertion_systems(cm, snapshots)
        P = corner_prolongation(m.n_corners, m.edges, m.dim, free)
        d0 = A0.diagonal()  # the barrier's stiffness shows as diagonal entries above the rest shape's
        with single_threaded_blas():
            for sysm in systems:
                A, b, U, mu, shift = sysm["A"], sysm["b"], sysm["U"], sysm["mu"], sysm["shift"]
                row = {"scene": scene, "factor": f, "tets": int(m.n_elements), "free_dofs": len(free),
                       "coarse_unknowns": P.shape[1], "nnz": int(A.nnz),
                       "system": "rest" if sysm["step"] is None else f"step {sysm['step']}",
                       "max_diagonal_over_rest": round(float(np.max(A.diagonal() / d0)), 2),
                       "shift_over_mu": shift / mu if mu else 0.0}
                s = SPDSolver()
                idx = np.arange(len(free))

                def direct(s=s, A=A, b=b, U=U, mu=mu, shift=shift):  # shifted: the factorization of the
                    # preconditioner PinnedSolver's CG then iterates with (its iterations not counted)
                    return s.solve_free(A, idx, b) if U is None else s.solve_free_update(A, idx, b, U, mu, shift)

                try:
                    x = direct()
                except Exception as e:  # an indefinite exact Hessian: Newton then takes the projected one
                    row["cholmod"] = f"failed: {type(e).__name__}"
                    rows.append(row)
                    print(row, file=sys.stderr)
                    continue
                best = np.inf
                for _ in range(2):
                    A.data *= 1.0 + 1e-12  # new values: a numeric factorization each time
                    c0 = _cpu()
                    x = direct()
                    best = min(best, _cpu() - c0)
                row["cholmod_factor_solve_cpu_s"] = round(best, 4)
                for kind, sweeps in smoothers:
                    pre = TwoLevelP2(P, SmootherConfig(kind=kind, sweeps=sweeps))
                    if kind == "sgs" and U is not None:
                        row[f"{kind}{sweeps}"] = "n/a (low-rank term)"
                        continue
                    pre.setup(A, U, mu, shift)
                    setup = np.inf
                    for _ in range(2):
                        c0 = _cpu()
                        pre.setup(A, U, mu, shift)
                        setup = min(setup, _cpu() - c0)
                    res = {"setup_cpu_s": round(setup, 4)}
                    bn = float(np.linalg.norm(b))
                    for rtol in (1e-2, 1e-8):
                        c0 = _cpu()
                        try:
                            r = conjugate_gradients(pre.apply, pre, b, max_iter=1000,
                                                    converged=lambda _r, rn, t=rtol * bn: rn <= t)
                        except Exception as e:
                            res[f"cg_{rtol:g}"] = f"failed: {type(e).__name__}"
                            continue
                        res[f"cg_{rtol:g}"] = {"iterations": r.iterations, "cpu_s": round(_cpu() - c0, 4),
                                               "converged": r.converged}
                        if rtol == 1e-8 and not shift:
                            res["error_vs_cholmod"] = float(f"{np.linalg.norm(r.x - x) / np.linalg.norm(x):.2g}")
                    row[f"{kind}{sweeps}"] = res
                rows.append(row)
                print(row, file=sys.stderr)
    return {"benchmark": "linear_solvers --pmg",
            "system": "free Hessian at rest (PSD, regularized) and Newton systems mid-insertion", "rows": rows}
