"""A trust-region SQP for problems whose constraints cost one expensive evaluation per design and
whose objective model comes with it (the gradient design, :func:`simfab.design.gradient.optimize_gradient`).

Problem, over z in [0, 1]^n (the design scaled by its bounds):

    min f(z)    s.t.   c(z) >= 0   (m expensive constraints: one evaluation gives c, A = dc/dz, f, g, B)
                       q(z) >= 0   (cheap constraints in closed form: the element-quality bound)

Each iteration costs exactly one evaluation. A step dz in the trust region |dz|_inf <= Delta, the
box and q(z_k + dz) >= 0 is found in two subproblems (SciPy's SLSQP):

1. **Feasibility** (only when a linearized constraint is violated at dz = 0): the smallest l1
   violation v(dz) = sum_i max(0, -(c_i + A_i dz)) reachable, r_i its per-row residual.
2. **Optimality**: min g^T dz + dz^T (B + S) dz / 2 s.t. c + A dz >= -r, S an SR1 secant of the
   constraints' curvature.

The step is judged by the l1 merit phi(z) = f(z) + mu v(z), v = sum_i max(0, -c_i - ctol_i):
rho = (phi(z_k) - phi(z_k + dz)) / pred; taken when rho >= ETA; the radius shrinks to
SHRINK |dz|_inf when rho < 1/4 or the evaluation fails, doubles when rho > 3/4 at the region's edge.

Stops when the design is feasible and the model predicts no reduction of f above
``rtol`` |f| + ``atol``, after ``patience`` rejected trials, at once with ``stop_when_feasible``;
when infeasible and no step reduces the violation; below ``min_radius``; or after ``max_evaluations``.
Full notes (the merit's pred, mu, the SR1 secant): docs/methods.md, "simfab.design.sqp".
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.optimize import minimize

#: Share of the linearized violation's reduction the predicted merit reduction must keep (mu's update).
RHO_M = 0.1
#: A step is taken when its actual merit reduction is at least this share of the predicted one.
ETA = 0.05
#: Round-off allowed on the cheap constraints at a subproblem's solution (the caller aims them inside
#: its true bound by more than this).
CHEAP_TOL = 1e-10
#: On a poor or failed step the radius becomes this share of the step's length (inf-norm).
SHRINK = 0.3


@dataclass(frozen=True, kw_only=True, eq=False)
class Sample:
    """One expensive evaluation at z.

    Args:
        ok: False when the design could not be evaluated (the other fields are then unused).
        f: the objective [units of f].
        g: (n,) its gradient.
        B: (n, n) its model Hessian (symmetric positive semi-definite).
        c: (m,) the constraints (>= 0 wanted).
        A: (m, n) their Jacobian.
    """

    ok: bool
    f: float = math.nan
    g: np.ndarray | None = None
    B: np.ndarray | None = None
    c: np.ndarray | None = None
    A: np.ndarray | None = None

    def violation(self, tol: float | np.ndarray = 0.0) -> float:
        """The l1 constraint violation beyond a tolerance.

        Args:
            tol: per-constraint tolerance (scalar or (m,)), in the constraints' units.

        Returns:
            sum_i max(0, -c_i - tol_i) (inf when the design could not be evaluated).
        """
        return float(np.sum(np.maximum(0.0, -self.c - tol))) if self.ok else math.inf


@dataclass(frozen=True, kw_only=True)
class CheapConstraints:
    """Constraints in closed form, imposed exactly in every subproblem: ``fun(z)`` (k,) >= 0 wanted,
    ``jac(z)`` (k, n)."""

    fun: Callable[[np.ndarray], np.ndarray]
    jac: Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True, kw_only=True)
class SQPConfig:
    """radius : initial trust-region radius (inf-norm, in z's units: a fraction of each variable's
    range); max_radius, min_radius : its bounds (below min_radius the method stops);
    max_evaluations : expensive evaluations at most, the start's included;
    rtol, atol : stop when feasible and the predicted reduction is below rtol |f| + atol (f's units);
    ctol : a design whose every violation max(0, -c_i) is at most ctol (scalar or (m,), c's units) counts as
    feasible for that test;
    penalty : the l1 merit's initial mu (f's units per unit of violation), raised as needed;
    patience : stop when the current design is feasible and this many trials in a row were rejected (the
    model mispredicts the simulation at every radius tried: a kink of a constraint at the design);
    stop_when_feasible : stop at the first design that is feasible (within ``ctol``), the start included: for
    constraints known only up to an error larger than what further steps would gain (a correction round's
    factors, measured at its start, move with the design), which a check outside the method decides."""

    radius: float = 0.05
    max_radius: float = 0.5
    min_radius: float = 1e-3
    max_evaluations: int = 20
    rtol: float = 1e-2
    atol: float = 1e-10
    ctol: float | np.ndarray = 0.0
    penalty: float = 1.0
    patience: int = 3
    stop_when_feasible: bool = False

    def __post_init__(self):
        if not (0 < self.min_radius <= self.radius <= self.max_radius):
            raise ValueError("need 0 < min_radius <= radius <= max_radius")
        if self.max_evaluations < 1:
            raise ValueError("max_evaluations must be at least 1")


@dataclass(frozen=True, kw_only=True, eq=False)
class SQPStep:
    """One iteration: the trial ``z`` and its ``sample``, ``accepted``, the ratio ``rho`` (-inf for a
    failed evaluation), ``predicted`` and ``actual`` merit reductions, the ``radius`` it was taken in,
    ``mu`` the merit's penalty."""

    z: np.ndarray
    sample: Sample
    accepted: bool
    rho: float
    predicted: float
    actual: float
    radius: float
    mu: float


@dataclass(kw_only=True, eq=False)
class SQPResult:
    """Outcome of the trust-region SQP.

    Args:
        z: the last accepted design, in [0, 1]^n (the design scaled by its bounds).
        sample: its :class:`Sample` (figures and gradients).
        steps: one :class:`SQPStep` per step.
        evaluations: designs evaluated (the start's included).
        converged: stopped by the tolerance (a feasible design where no step predicts progress).
        message: why it stopped.
    """

    z: np.ndarray
    sample: Sample
    steps: list = field(default_factory=list)
    evaluations: int = 0
    converged: bool = False
    message: str = ""


def _model(s: Sample, dz: np.ndarray, S: np.ndarray | None = None) -> float:
    """m(dz) = g^T dz + dz^T (B + S) dz / 2."""
    Bdz = s.B @ dz if S is None else s.B @ dz + S @ dz
    return float(s.g @ dz + 0.5 * dz @ Bdz)


def sr1_update(S: np.ndarray, step: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Symmetric rank-one update of S so that S step = y (skipped when |u^T step| < 1e-8 |u| |step|,
    u = y - S step): the constraints' curvature, S ~ -sum_i lambda_i d2c_i/dz2, may be indefinite,
    which SR1 allows and BFGS does not."""
    u = y - S @ step
    den = float(u @ step)
    if abs(den) < 1e-8 * float(np.linalg.norm(u) * np.linalg.norm(step)) or not np.any(u):
        return S
    return S + np.outer(u, u) / den


def _linear_violation(s: Sample, dz: np.ndarray, tol: float | np.ndarray = 0.0) -> float:
    return float(np.sum(np.maximum(0.0, -(s.c + s.A @ dz) - tol)))


def _cheap(cheap: CheapConstraints | None, z: np.ndarray, radius: float, n_extra: int = 0) -> list:
    """SLSQP constraint dicts of the cheap constraints at z + radius u (variables u, then n_extra slacks)."""
    if cheap is None:
        return []
    n = len(z)

    def fun(x):
        return cheap.fun(z + radius * x[:n])

    def jac(x):
        J = cheap.jac(z + radius * x[:n]) * radius
        return np.hstack([J, np.zeros((J.shape[0], n_extra))]) if n_extra else J

    return [{"type": "ineq", "fun": fun, "jac": jac}]


def _unit_region(z: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of u = dz / radius: the trust region (|u| <= 1) within the box 0 <= z + dz <= 1."""
    return np.maximum(-1.0, -z / radius), np.minimum(1.0, (1.0 - z) / radius)


def feasibility_step(s: Sample, z: np.ndarray, radius: float, cheap: CheapConstraints | None = None) -> np.ndarray:
    """dz minimizing the linearized l1 violation sum_i max(0, -(c_i + A_i dz)) inside the region
    (slacks t >= 0, c + A dz + t >= 0, min sum t), the cheap constraints held; the start dz = 0 is
    returned when nothing better is found. Solved in u = dz / radius and t / max(t(0)) (SLSQP
    stalls on variables many orders below one)."""
    n, m = len(z), len(s.c)
    t0 = np.maximum(0.0, -s.c)
    ts = max(float(t0.max()), 1e-300)
    lo, hi = _unit_region(z, radius)
    Au = s.A * radius / ts
    cons = [{"type": "ineq", "fun": lambda x: s.c / ts + Au @ x[:n] + x[n:],
             "jac": lambda x: np.hstack([Au, np.eye(m)])}] + _cheap(cheap, z, radius, m)
    res = minimize(lambda x: float(x[n:].sum()), np.r_[np.zeros(n), t0 / ts],
                   jac=lambda x: np.r_[np.zeros(n), np.ones(m)], method="SLSQP",
                   bounds=list(zip(lo, hi)) + [(0.0, None)] * m, constraints=cons,
                   options={"maxiter": 200, "ftol": 1e-12})
    dz = radius * np.clip(res.x[:n], lo, hi)
    if cheap is not None and np.any(cheap.fun(z + dz) < -CHEAP_TOL):
        return np.zeros(n)
    return dz if _linear_violation(s, dz) < _linear_violation(s, np.zeros(n)) else np.zeros(n)


def optimality_step(s: Sample, z: np.ndarray, radius: float, dz0: np.ndarray, cheap: CheapConstraints | None = None,
                    S: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """(dz, lambda): dz minimizing m(dz) (Hessian B + S) inside the region with the linearized constraints
    no more violated than at ``dz0`` (c + A dz >= -r, r = max(0, -(c + A dz0))), the cheap constraints
    held; from dz0 (which is feasible for it), and dz0 itself (lambda None) when the solver ends elsewhere
    infeasible or higher. lambda (m,) >= 0: the subproblem's multipliers of the linearized constraints.
    Solved in u = dz / radius with m scaled to ~1 over the region."""
    m = len(s.c)
    B = s.B if S is None else s.B + S
    r = np.maximum(0.0, -(s.c + s.A @ dz0))
    tol = 1e-9 * (1.0 + np.abs(s.c))
    lo, hi = _unit_region(z, radius)
    gu, Bu = s.g * radius, B * radius**2
    scale = max(float(np.abs(gu).sum()) + 0.5 * float(np.abs(Bu).sum()), 1e-300)
    cscale = np.maximum(np.abs(s.A).sum(axis=1) * radius, 1e-300)  # each row ~1 over the region
    Au = s.A * radius / cscale[:, None]
    cons = [{"type": "ineq", "fun": lambda x: (s.c + r) / cscale + Au @ x, "jac": lambda x: Au}]
    cons += _cheap(cheap, z, radius)
    res = minimize(lambda x: float(gu @ x + 0.5 * x @ (Bu @ x)) / scale, dz0 / radius,
                   jac=lambda x: (gu + Bu @ x) / scale, method="SLSQP", bounds=list(zip(lo, hi)), constraints=cons,
                   options={"maxiter": 200, "ftol": 1e-12})
    dz = radius * np.clip(res.x, lo, hi)
    ok = np.all(s.c + s.A @ dz + r >= -tol) and (cheap is None or np.all(cheap.fun(z + dz) >= -CHEAP_TOL))
    if not (ok and _model(s, dz, S) <= _model(s, dz0, S)):
        return dz0, None
    lam = getattr(res, "multipliers", None)
    lam = None if lam is None or len(lam) < m else np.maximum(np.asarray(lam[:m], float), 0.0) * scale / cscale
    return dz, lam


def trust_region_sqp(evaluate: Callable[[np.ndarray], Sample], z0: np.ndarray, *,
                     options: SQPConfig = SQPConfig(), cheap: CheapConstraints | None = None,
                     callback: Callable[[SQPStep], None] | None = None) -> SQPResult:
    """Minimize f subject to c >= 0 and the cheap constraints over [0, 1]^n from z0 (see the module
    docstring); ``evaluate(z)`` -> :class:`Sample` is called once per iteration (z0 first), never twice
    for one design. z0 must satisfy the cheap constraints and be evaluable (else ValueError).
    ``callback(step)`` after every iteration."""
    z = np.clip(np.asarray(z0, float), 0.0, 1.0)
    if cheap is not None and np.any(cheap.fun(z) < -CHEAP_TOL):
        raise ValueError("the start violates the cheap constraints")
    s = evaluate(z)
    if not s.ok:
        raise ValueError("the start cannot be evaluated")
    out = SQPResult(z=z, sample=s, evaluations=1)
    radius, mu = options.radius, options.penalty
    S = np.zeros((len(z), len(z)))  # the constraints' curvature in the Lagrangian's Hessian (SR1)
    lam = np.zeros(len(s.c))
    while True:
        v0 = s.violation(options.ctol)  # the merit's: violations within ctol are free
        within = v0 == 0.0
        if within and options.stop_when_feasible:
            out.converged, out.message = True, "a feasible design reached (stop_when_feasible)"
            break
        dzf = feasibility_step(s, z, radius, cheap) if s.violation() > 0 else np.zeros(len(z))
        dz, lam_qp = optimality_step(s, z, radius, dzf, cheap, S)
        if lam_qp is not None:
            lam = lam_qp
        dv = v0 - _linear_violation(s, dz, options.ctol)
        q = _model(s, dz)  # the objective's own model (exact for a quadratic f), without the constraints' curvature
        if dv > 1e-12 * max(v0, 1.0) and q > 0:
            mu = max(mu, q / ((1.0 - RHO_M) * dv))
        pred = -q + mu * dv
        step = float(np.abs(dz).max()) if len(dz) else 0.0
        if within and -q <= options.rtol * abs(s.f) + options.atol:
            out.converged, out.message = True, "converged: no step predicts a reduction above the tolerance"
            break
        if pred <= options.atol or step == 0.0:
            out.message = ("no step reduces the linearized violation inside the region" if not within
                           else "no step predicts a reduction")
            break
        if out.evaluations >= options.max_evaluations:
            out.message = f"evaluation limit ({options.max_evaluations}) reached"
            break
        zt = np.clip(z + dz, 0.0, 1.0)
        st = evaluate(zt)
        out.evaluations += 1
        if st.ok:
            actual = (s.f + mu * v0) - (st.f + mu * st.violation(options.ctol))
            rho = actual / pred
            # secant of the constraint part of grad L = g - A^T lambda (the objective's own Hessian is in B)
            S = sr1_update(S, zt - z, -(st.A - s.A).T @ lam)
        else:
            actual, rho = -math.inf, -math.inf
        accepted = rho >= ETA
        rec = SQPStep(z=zt, sample=st, accepted=accepted, rho=rho, predicted=pred, actual=actual, radius=radius,
                      mu=mu)
        out.steps.append(rec)
        if rho < 0.25:
            radius = SHRINK * step
        elif rho > 0.75 and step >= 0.8 * radius:
            radius = min(2.0 * radius, options.max_radius)
        if accepted:
            z, s = zt, st
            out.z, out.sample = z, s
        if callback is not None:
            callback(rec)
        if radius < options.min_radius:
            out.message = f"trust region below {options.min_radius:g}"
            break
        tail = out.steps[-options.patience:]
        if within and len(tail) == options.patience and not any(t.accepted for t in tail):
            out.message = f"{options.patience} trials in a row rejected at a feasible design"
            break
    return out
