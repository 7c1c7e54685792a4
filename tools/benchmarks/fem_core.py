"""FEM core timings (kernels, assembly, factorization) at the model sizes of the coupling benchmarks.

    python tools/bench.py fem_core [--sizes 1040,5080,12063] [--repeat 7] [--seed 0]

prints one JSON object: per tet-mesh size, the median wall time [ms] of

- ``energy``, ``energy_gradient``: one kernel launch each (+ gradient scatter);
- ``energy_gradient_hessian``: energy, gradient and the PSD-projected Hessian assembled into CSR
  (analytic eigensystem in the kernel, values added straight into the fixed pattern);
- ``exact_and_projected_hessians``: both Hessians from one launch (for exact-first Newton);
- ``hessian_svd_route``: the same through the full SVD eigensystem of every element (the
  reference route; the default route avoids the SVD where the twist block is the only indefinite
  part);
- ``eigh_projection``: the alternative of projecting the (m, 12, 12) element blocks with numpy's
  batched ``eigh`` (projection alone, without assembly), for comparison;
- ``factorization``: one sparse Cholesky solve of the free-dof Hessian (CHOLMOD via
  :class:`SPDSolver`, symbolic analysis reused, as in every Newton iteration after the first);
- ``newton_static``: a full static solve (clamped beam-like block under an end load) with
  :func:`simfab.solve.newton.minimize`, and its iteration count.

Also a 2D plane-strain mesh of ~450 triangles. Meshes: a structured tet box (element counts of
the reference insertion models within a few %) and a Triangle mesh of a rectangle
(``benchmarks._meshes``). The published figures cover whole insertion runs only (see
``insertion``), so this benchmark reports absolute times.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import scipy.sparse as sp

from benchmarks._meshes import box_model, rect_model
from simfab.fem import elastic as nh
from simfab.solve.linear import SPDSolver
from simfab.solve.newton import minimize

DEFAULT_SIZES = (1040, 5080, 12063)  # tet counts of the reference insertion models
TRIANGLES_2D = 450


def _median_ms(fn, repeat: int) -> float:
    fn()  # warm-up (kernel load, caches)
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times) * 1e3)


def _static(model, rng):
    """End-loaded block clamped at x = min: Newton from rest. Returns (seconds, iterations)."""
    X = model.rest
    # slabs rather than planes, so unstructured meshes also clamp the rigid modes
    clamped = X[:, 0] <= X[:, 0].min() + 0.05 * np.ptp(X[:, 0])
    end = X[:, 0] >= X[:, 0].max() - 0.05 * np.ptp(X[:, 0])
    f = np.zeros_like(X)
    # load giving an end deflection of ~1% of the length (moderately nonlinear)
    E = model.material.youngs_modulus
    L = np.ptp(X[:, 0])
    hy = np.ptp(X[:, 1])
    width = np.ptp(X[:, 2]) if model.dim == 3 else model.thickness
    I = width * hy**3 / 12
    f[end, 1] = -0.03 * E * I / L**2 / end.sum()
    fl = f.ravel()

    def fun(x, need_h):
        if need_h:  # exact Newton steps when the exact Hessian is PD, projected otherwise
            e, g, Hx, Hp = nh.energy_gradient_hessians(model, x)
            return e - fl @ x, g.ravel() - fl, (Hx, Hp)
        e, g = nh.energy_gradient(model, x)
        return e - fl @ x, g.ravel() - fl, None

    t0 = time.perf_counter()
    res = minimize(fun, X.ravel(), free=np.repeat(~clamped, model.dim))
    return time.perf_counter() - t0, res.iterations


def _measure(model, repeat: int, rng) -> dict:
    x = model.rest + 1e-3 * model.mean_edge_length() * rng.standard_normal(model.rest.shape)
    out = {
        "elements": int(model.n_elements),
        "vertices": int(model.n_vertices),
        "dofs": int(model.n_dofs),
        "hessian_nnz": int(model.pattern.nnz),
        "energy_ms": _median_ms(lambda: nh.energy(model, x), repeat),
        "energy_gradient_ms": _median_ms(lambda: nh.energy_gradient(model, x), repeat),
        "energy_gradient_hessian_ms": _median_ms(lambda: nh.energy_gradient_hessian(model, x), repeat),
        "exact_and_projected_hessians_ms": _median_ms(lambda: nh.energy_gradient_hessians(model, x), repeat),
    }
    out["hessian_svd_route_ms"] = _median_ms(lambda: nh.energy_gradient_hessian(model, x, projection="svd"), repeat)
    blocks = nh.element_hessians(model, x, project_psd=False)

    def eigh_projection():
        w, Q = np.linalg.eigh(blocks)
        return (Q * np.maximum(w, 0.0)[:, None, :]) @ np.swapaxes(Q, 1, 2)

    out["eigh_projection_ms"] = _median_ms(eigh_projection, max(1, repeat // 2))
    H = nh.energy_gradient_hessian(model, x)[2]
    clamped = model.rest[:, 0] <= model.rest[:, 0].min() + 0.05 * np.ptp(model.rest[:, 0])
    free = np.repeat(~clamped, model.dim)
    Hf = sp.csr_matrix(H[free][:, free])
    solver = SPDSolver()
    rhs = rng.standard_normal(Hf.shape[0])
    out["factorization_ms"] = _median_ms(lambda: solver.solve(Hf, rhs), max(1, repeat // 2))
    secs, iters = _static(model, rng)
    out["newton_static_s"] = secs
    out["newton_static_iterations"] = int(iters)
    return out


def run(argv=None) -> dict:
    """Benchmark entry point: returns the JSON-able summary."""
    p = argparse.ArgumentParser(prog="bench.py fem_core", description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", default=",".join(map(str, DEFAULT_SIZES)), help="comma-separated tet counts")
    p.add_argument("--repeat", type=int, default=7)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    rng = np.random.default_rng(a.seed)
    result = {"benchmark": "fem_core", "machine_note": "median wall times, Warp CPU (single-threaded kernels)"}
    result["tri_2d"] = _measure(rect_model(TRIANGLES_2D), a.repeat, rng)
    result["tet_3d"] = [_measure(box_model(int(s)), a.repeat, rng) for s in a.sizes.split(",") if s]
    return result
