"""Projected Newton's method with a backtracking (Armijo) line search.

Generic over the objective: ``fun(x, need_hessian) -> (f, g, H)`` with a positive semi-definite
sparse Hessian. Each iteration solves ``H_ff dx_f = -g_f`` on the free dofs with a sparse Cholesky
factorization (:class:`simfab.solve.linear.SPDSolver`), then backtracks along ``dx`` until the Armijo
condition holds at an admissible point. Exact-first steps: ``H`` may be a pair ``(H_exact, H_psd)``
(each possibly a callable building it on demand); the exact one is used while it factorizes.
Chord steps (``NewtonConfig.chord_within``): near the target an iterate may reuse the solve's last
factorization instead of a fresh Hessian (the stopping rule is the same).

Feasibility hooks: ``max_step(x, dx) -> alpha_max`` caps the step before the line search;
``admissible(x) -> bool`` rejects trial points (as does an objective of +inf or NaN).

Convergence, on the free dofs: ``||g_f||_inf <= grad_tol * scale`` (``options.grad_scale``, else the
start's residual); or ``||dx_f||_inf <= step_tol * x_scale``; or the predicted decrease is below
round-off and no step along the Newton direction reduces the gradient norm. Anything else raises
:class:`simfab.errors.ConvergenceError` naming the iteration count and the residual; a result that
did not converge is never returned. The criteria in full: docs/methods.md, "simfab.solve.newton".
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import scipy.sparse as sp

from simfab.errors import ConvergenceError
from simfab.solve.linear import NotPositiveDefinite, SPDSolver, free_block_map

Objective = Callable[[np.ndarray, bool], tuple]


@dataclass(frozen=True, kw_only=True)
class NewtonConfig:
    """Stopping and line-search parameters of :func:`minimize` (see the module docstring)."""

    max_iter: int = 50
    grad_tol: float = 1e-8  # relative to ||g_f(x0)||_inf unless grad_scale is given
    grad_scale: float | None = None  # absolute gradient scale [units of g]; None: ||g_f(x0)||_inf
    step_tol: float = 1e-12  # Newton step relative to x_scale
    x_scale: float | None = None  # length scale of x [units of x]; None: max(||x0_f||_inf, 1)
    armijo: float = 1e-4  # sufficient-decrease constant c1 in f(x+a dx) <= f + c1 a g.dx
    backtrack: float = 0.5  # step shrink factor per rejected trial
    max_backtracks: int = 40
    roundoff: float = 1e-12  # decrease (relative to |f|) below which f cannot resolve it
    # When the first (full or capped) trial fails the sufficient-decrease test but changes f by at most
    # this (relative to |f|), it is taken if it lowers the gradient norm, without backtracking: f is a
    # sum of terms that cancel, so its rounding is ulps of the terms, not of f (an inexact Newton step
    # near a tight target lands where f no longer resolves the decrease while the gradient still does),
    # and shorter trials would pass or fail the test on that rounding alone
    roundoff_terms: float = 1e-10
    # Evaluate the Hessian already at the first trial point of each line search: when most full
    # (or capped) steps are accepted, this saves a separate value/gradient evaluation per
    # iteration; a rejected first trial wastes one Hessian evaluation.
    eager_hessian: bool = False
    # ... except when the gradient is already within this factor of the target: Newton converging
    # quadratically, the trial is then most likely the last iterate and its Hessian never used
    # (0: always eager)
    eager_above_tol: float = 0.0
    # Exact-first Hessians (see the module docstring): False stops trying the exact Hessian for the
    # rest of the solve once its factorization has failed (a failed attempt costs up to a whole
    # factorization, and where the exact Hessian is indefinite it mostly stays so until convergence)
    retry_exact: bool = True
    # Offer the exact Hessian from the first iteration (False: the projected one throughout, e.g.
    # when the caller's previous, similar solve found the exact one indefinite)
    exact_first: bool = True
    # Regularization when the Cholesky factorization fails: H + shift * mean|diag H| * I with
    # shift starting at reg_initial, multiplied by reg_growth per failure, at most reg_max.
    reg_initial: float = 1e-10
    reg_growth: float = 100.0
    reg_max: float = 1e2
    # Chord steps: when an accepted trial was evaluated without its Hessian and its gradient is
    # within this factor of the target, the next step reuses the solve's last factorization (no
    # Hessian assembly, no factorization: one solve) instead of a fresh Newton step; 0: never. A
    # further chord step follows only while each cut the gradient by at least chord_contraction;
    # otherwise (or when the factorization cannot be reused) the Hessian is evaluated as usual.
    chord_within: float = 0.0
    chord_contraction: float = 0.1

    def __post_init__(self):
        checks = {
            "max_iter": self.max_iter >= 1,
            "grad_tol": self.grad_tol >= 0,
            "grad_scale": self.grad_scale is None or self.grad_scale > 0,
            "step_tol": self.step_tol >= 0,
            "x_scale": self.x_scale is None or self.x_scale > 0,
            "armijo": 0 < self.armijo < 0.5,
            "backtrack": 0 < self.backtrack < 1,
            "max_backtracks": self.max_backtracks >= 0,
            "roundoff": self.roundoff >= 0,
            "roundoff_terms": self.roundoff_terms >= 0,
            "reg_initial": 0 < self.reg_initial <= self.reg_max,
            "reg_growth": self.reg_growth > 1,
            "eager_above_tol": self.eager_above_tol >= 0,
            "chord_within": self.chord_within >= 0,
            "chord_contraction": 0 < self.chord_contraction < 1,
        }
        bad = [k for k, ok in checks.items() if not ok]
        if bad:
            raise ValueError(f"invalid NewtonConfig: {', '.join(f'{k}={getattr(self, k)!r}' for k in bad)}")


@dataclass
class NewtonResult:
    """Outcome of a converged :func:`minimize`.

    Args:
        x: (N,) float64 minimizer (fixed dofs equal to x0)
        energy: objective value at x
        grad_norm: ||g_f(x)||_inf on the free dofs
        iterations: Newton iterations taken (linear solves)
        converged: always True for a returned result (non-convergence raises)
        reason: which criterion stopped the iteration ("gradient", "step", "roundoff")
        history: one dict per iteration: energy, grad_norm, alpha, backtracks, shift
        exact_failures: exact Hessians offered whose factorization failed (not positive definite)
        chord_steps: iterations that reused the previous iteration's factorization (see
            ``NewtonConfig.chord_within``; counted in ``iterations`` too)
    """

    x: np.ndarray
    energy: float
    grad_norm: float
    iterations: int
    converged: bool
    reason: str = ""
    history: list = field(default_factory=list)
    exact_failures: int = 0
    chord_steps: int = 0


class _FreeBlock:
    """Extracts the free-dof submatrix of a CSR matrix, caching the index map per pattern."""

    def __init__(self, free_idx: np.ndarray, n: int):
        self.free_idx = free_idx
        self.n = n
        self._key = None
        self._sel = None
        self._indices = None
        self._indptr = None

    def __call__(self, H: sp.spmatrix) -> sp.csr_matrix:
        if len(self.free_idx) == self.n:
            return sp.csr_matrix(H)
        H = sp.csr_matrix(H)
        if self._key is None or not (
            self._key[0].shape == H.indptr.shape
            and self._key[1].shape == H.indices.shape
            and np.array_equal(self._key[0], H.indptr)
            and np.array_equal(self._key[1], H.indices)
        ):
            self._build(H)
        m = len(self.free_idx)
        return sp.csr_matrix((H.data[self._sel], self._indices, self._indptr), shape=(m, m))

    def _build(self, H: sp.csr_matrix) -> None:
        self._sel, self._indptr, self._indices = free_block_map(H, self.free_idx)
        self._key = (H.indptr.copy(), H.indices.copy())


_FREE_BLOCKS: dict = {}  # (n, free dofs) -> _FreeBlock: repeated solves (e.g. per insertion step) reuse the map
_FREE_BLOCKS_MAX = 8


def _free_block(free_idx: np.ndarray, n: int) -> _FreeBlock:
    key = (n, free_idx.size, hash(free_idx.tobytes()))
    fb = _FREE_BLOCKS.get(key)
    if fb is None or not np.array_equal(fb.free_idx, free_idx):
        if len(_FREE_BLOCKS) >= _FREE_BLOCKS_MAX:
            _FREE_BLOCKS.pop(next(iter(_FREE_BLOCKS)))
        fb = _FREE_BLOCKS[key] = _FreeBlock(free_idx.copy(), n)
    return fb


def _newton_direction(solver: SPDSolver, sub, H, rhs: np.ndarray, opts: NewtonConfig, try_exact: bool = True):
    """Newton direction on the free dofs. ``H`` is a PSD sparse matrix, or a pair
    ``(H_exact, H_psd)``: the exact Hessian is tried first (a successful Cholesky factorization
    proves it positive definite, so the step is an exact Newton step: quadratic convergence);
    when it is indefinite (or ``try_exact`` is False) the PSD-projected one is used. Returns
    (dx, shift, "exact"|"psd", whether an exact factorization failed, the matrix factorized: None
    when it needed a diagonal shift)."""
    failed = False
    if isinstance(H, tuple):
        H_exact, H_psd = H
        if try_exact:
            try:
                H_exact = H_exact() if callable(H_exact) else H_exact
                return _solve_block(solver, sub, H_exact, rhs), 0.0, "exact", False, H_exact
            except NotPositiveDefinite:
                failed = True
        H = H_psd() if callable(H_psd) else H_psd
    try:
        return _solve_block(solver, sub, H, rhs), 0.0, "psd", failed, H
    except NotPositiveDefinite:
        dx, shift = _solve_shifted(solver, sub(H), rhs, opts)
    return dx, shift, "psd", failed, None


def _solve_block(solver: SPDSolver, sub: "_FreeBlock", H, rhs: np.ndarray) -> np.ndarray:
    """Solve the free-dof block of H (:meth:`SPDSolver.solve_free`: no submatrix built; H as CSR
    when every dof is free)."""
    if len(sub.free_idx) < sub.n:
        return solver.solve_free(H, sub.free_idx, rhs)
    return solver.solve(sub(H), rhs)


def _solve_shifted(solver: SPDSolver, H: sp.csr_matrix, rhs: np.ndarray, opts: NewtonConfig):
    """Solve (H + shift I) dx = rhs for H found not positive definite, with the smallest shift of
    a growing sequence that factorizes. Returns (dx, shift)."""
    diag = np.abs(H.diagonal())
    base = float(diag.mean()) if diag.size and diag.mean() > 0 else 1.0
    shift = opts.reg_initial
    while shift <= opts.reg_max:
        try:
            return solver.solve(H + sp.identity(H.shape[0], format="csr") * (shift * base), rhs), shift * base
        except NotPositiveDefinite:
            shift *= opts.reg_growth
    raise ConvergenceError(
        f"Newton: Hessian could not be factorized even with a diagonal shift of {opts.reg_max:g} x mean|diag|"
    )


def minimize(
    fun: Objective,
    x0: np.ndarray,
    *,
    free: np.ndarray | None = None,
    options: NewtonConfig = NewtonConfig(),
    max_step: Callable[[np.ndarray, np.ndarray], float] | None = None,
    admissible: Callable[[np.ndarray], bool] | None = None,
    solver: SPDSolver | None = None,
) -> NewtonResult:
    """Minimize ``fun`` from ``x0`` by projected Newton with backtracking line search.

    Args:
        fun: callable ``fun(x, need_hessian) -> (f, g, H)``
            ``x`` (N,) float64; ``f`` float (``+inf`` marks an infeasible point); ``g`` (N,) gradient;
            ``H`` scipy.sparse (N, N) positive semi-definite (PSD-projected) when ``need_hessian``,
            else may be None. ``H`` may also be a pair ``(H_exact, H_psd)`` of the exact and the
            PSD-projected Hessian: the exact one is used whenever its Cholesky factorization succeeds
            (positive definite: exact Newton step, quadratic convergence near a stable minimizer where
            per-element projection would only give linear convergence), the projected one otherwise.
        x0: (N,) array, start point; must be admissible with a finite ``f``.
        free: (N,) bool mask of unknown dofs; the others stay at ``x0``'s values. None: all free.
        options: :class:`NewtonConfig`.
        max_step: ``max_step(x, dx) -> alpha_max`` in (0, 1], the largest feasible step fraction
            along the full-length direction ``dx`` (zero on fixed dofs).
        admissible: ``admissible(x) -> bool``; trial points failing it are rejected.
        solver: an :class:`SPDSolver` to reuse (keeps the symbolic analysis across calls).

    Returns:
        NewtonResult with ``converged=True``. Raises ConvergenceError otherwise.
    """
    x = np.array(x0, dtype=np.float64).ravel()
    n = x.size
    if free is None:
        free_idx = np.arange(n)
    else:
        free = np.asarray(free, dtype=bool).ravel()
        if free.shape != (n,):
            raise ValueError(f"free mask has shape {free.shape}, expected ({n},)")
        free_idx = np.flatnonzero(free)
    solver = solver if solver is not None else SPDSolver()
    opts = options
    sub = _free_block(free_idx, n)
    tiny = np.finfo(np.float64).tiny

    if admissible is not None and not admissible(x):
        raise ConvergenceError("Newton: the start point is not admissible")
    try_exact = opts.exact_first
    exact_failures = 0
    f, g, H = fun(x, True)
    if not np.isfinite(f):
        raise ConvergenceError(f"Newton: the objective is not finite at the start point (f={f})")
    gnorm = _inf_norm(g[free_idx])
    gscale = opts.grad_scale if opts.grad_scale is not None else gnorm
    xscale = opts.x_scale if opts.x_scale is not None else max(_inf_norm(x[free_idx]), 1.0)
    history: list[dict] = []

    chords = 0
    factored = None  # the matrix of this solve's last factorization (what a chord step reuses)
    chord = False  # the next step is a chord step
    g_before = np.inf  # gradient norm before the last step

    def done(reason: str, it: int) -> NewtonResult:
        return NewtonResult(x=x, energy=float(f), grad_norm=gnorm, iterations=it, converged=True,
                            reason=reason, history=history, exact_failures=exact_failures, chord_steps=chords)

    if free_idx.size == 0 or gnorm <= opts.grad_tol * gscale:
        return done("gradient", 0)

    for it in range(1, opts.max_iter + 1):
        dx_f = None
        if chord:
            try:  # the same values: the solver reuses its factorization (no numeric factorization)
                dx_f, shift, used, failed = _solve_block(solver, sub, factored, -g[free_idx]), 0.0, "chord", False
                chords += 1
            except NotPositiveDefinite:
                factored = None
                f, g, H = fun(x, True)
        if dx_f is None:
            dx_f, shift, used, failed, factored = _newton_direction(solver, sub, H, -g[free_idx], opts, try_exact)
        exact_failures += int(failed)
        if failed and not opts.retry_exact:
            try_exact = False
        dx = np.zeros(n)
        dx[free_idx] = dx_f
        slope = float(g[free_idx] @ dx_f)
        if not slope < 0.0:  # regularized SPD solve always gives descent unless g ~ 0
            if -slope <= opts.roundoff * max(abs(f), tiny):
                return done("roundoff", it - 1)
            raise ConvergenceError(f"Newton: search direction is not a descent direction at iteration {it} "
                                   f"(g.dx={slope:.3e}, ||g||_inf={gnorm:.3e})")
        if _inf_norm(dx_f) <= opts.step_tol * xscale:
            return done("step", it - 1)

        alpha = 1.0
        if max_step is not None:
            alpha = float(min(1.0, max_step(x, dx)))
            if not alpha > 0.0:
                raise ConvergenceError(f"Newton: max_step returned {alpha} at iteration {it}")
        # Near the minimizer the predicted decrease -g.dx can fall below the resolution of f; then
        # comparing energies is meaningless (round-off decides), and the trial is accepted when it
        # reduces the gradient norm instead.
        flat = -slope <= opts.roundoff * max(abs(f), tiny)
        accepted = False
        Ht = None
        eager_now = opts.eager_hessian and gnorm > opts.eager_above_tol * opts.grad_tol * gscale and not chord
        for bt in range(opts.max_backtracks + 1):
            xt = x + alpha * dx
            if admissible is None or admissible(xt):
                eager = eager_now and bt == 0
                ft, gt, Ht = fun(xt, eager)
                if not eager:
                    Ht = None
                if np.isfinite(ft):
                    if flat:
                        accepted = _inf_norm(np.asarray(gt)[free_idx]) < gnorm
                    else:
                        accepted = ft <= f + opts.armijo * alpha * slope
                        if not accepted and bt == 0 and abs(ft - f) <= opts.roundoff_terms * max(abs(f), tiny):
                            # f cannot resolve the full step's change: the gradient norm decides (a
                            # shorter trial would pass or fail Armijo on f's rounding alone)
                            accepted = _inf_norm(np.asarray(gt)[free_idx]) < gnorm
                    if accepted:
                        break
            alpha *= opts.backtrack
        if not accepted:
            if flat:
                # neither f nor ||g|| can be improved along the Newton direction: round-off floor
                return done("roundoff", it - 1)
            raise ConvergenceError(
                f"Newton: line search failed at iteration {it} after {opts.max_backtracks} backtracks "
                f"(||g_free||_inf={gnorm:.3e}, target {opts.grad_tol * gscale:.3e}, g.dx={slope:.3e})"
            )
        x = xt
        f, g, H = ft, np.asarray(gt), Ht  # H None: the accepted trial was evaluated without it
        g_before, gnorm = gnorm, _inf_norm(g[free_idx])
        history.append(dict(energy=float(f), grad_norm=gnorm, alpha=alpha, backtracks=bt, shift=shift, hessian=used))
        if gnorm <= opts.grad_tol * gscale:
            return done("gradient", it)
        chord = (H is None and factored is not None and gnorm <= opts.chord_within * opts.grad_tol * gscale
                 and (not chord or gnorm <= opts.chord_contraction * g_before))
        if H is None and not chord:
            f, g, H = fun(x, True)

    raise ConvergenceError(
        f"Newton did not converge in {opts.max_iter} iterations: ||g_free||_inf={gnorm:.3e} > "
        f"target {opts.grad_tol * gscale:.3e}, f={f:.6e}"
    )


def _inf_norm(v: np.ndarray) -> float:
    return float(np.max(np.abs(v))) if v.size else 0.0


#: The earlier name (``...Config`` is the package's one suffix for configuration).
NewtonOptions = NewtonConfig
