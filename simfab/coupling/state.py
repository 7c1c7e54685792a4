"""Typed data of the insertion loop: what one converged step's evaluation holds
(:class:`Evaluation`), the run's state between steps (:class:`StepState`: with friction also the
lagged contact a step was solved with, :class:`simfab.coupling.friction.FrictionLag`: its normal
forces, normals and tangent bases) and the per-run context (:class:`StepContext`); and
:func:`accept`, which makes a converged solution the current state.

Model/State split: the :class:`simfab.coupling.model.CouplingModel` is immutable for a run; a
:class:`StepState` is what a step reads and writes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from simfab.coupling.guide import CoarseGuide
from simfab.coupling.points import ContactPoints
from simfab.coupling.timing import Timer
from simfab.solve.linear import LagConfig, SPDSolver
from simfab.solve.pmg import MultigridConfig, insertion_solver


@dataclass(frozen=True, kw_only=True, eq=False)
class Evaluation:
    """Newton's last evaluation of a step objective at its converged positions.

    x : (n, dim) positions [m] it was evaluated at (the very array the state holds);
    kappa : barrier stiffness [N/m]; points : the constraint points it was evaluated over;
    elastic_energy [J] and elastic_gradient (n, dim) [N]: E_d and dE_d/dx (without barrier or pin);
    distances (k,) [m]: d_j = -psi(y_j), exact within the objective's lazy band (which contains the
    barrier's support), certified lower bounds beyond it; distance_gradients (k, dim): grad d_j
    (zero where only a bound is known); hessian: the objective's PSD Hessian at x (CSR, or a
    callable that assembles it on first use), None when it was not evaluated at x; barrier_points
    (a,): the points within their d_hat, barrier_energy [J] kappa sum_j b(d_j) and barrier_gradient
    (a, dim) [N] its gradient with respect to those points' positions (None: not evaluated)."""

    x: np.ndarray
    kappa: float
    points: ContactPoints
    elastic_energy: float
    elastic_gradient: np.ndarray
    distances: np.ndarray
    distance_gradients: np.ndarray
    hessian: object = None
    barrier_points: np.ndarray | None = None
    barrier_energy: float | None = None
    barrier_gradient: np.ndarray | None = None


@dataclass(frozen=True)
class PastStep:
    """A converged earlier step: positions x (n, dim) [m] at path length s [m]; with friction the
    normal forces (k,) [N] at its constraint points ``points``."""

    x: np.ndarray
    s: float
    points: ContactPoints | None = None
    normal_force: np.ndarray | None = None


@dataclass(kw_only=True)
class StepState:
    """The insertion run's state between steps.

    x (n, dim) [m] at path length s [m]; points: the constraint points (boundary vertices plus the refinement
    points of the ``refined`` facets at density ``order``: 2D points per edge, 3D face lattice order, doubled on
    demand); kappa: the barrier stiffness for the following steps [N/m] (adapted); kappa_step: the stiffness x
    was solved with (forces at x use it); evaluation: Newton's last evaluation at x (None when it is not at x);
    tangent: the PSD Hessian at x for the predictor (CSR, or a callable assembling it on demand); prev, prev2:
    the one and two steps before (extrapolating warm starts); pin_basis (k, r): the rigid motions the next step
    pins; grad_peak: largest |grad psi| seen at converged constraint and check points; check / check_cache: memo
    of the last facet check and of earlier check points' values (see :mod:`simfab.coupling.refine`); direction:
    +1 while O moves forward along the path (insertion), -1 backward (removal); friction: the friction lag x was
    solved with (:class:`simfab.coupling.friction.FrictionLag`, None without friction), lag_solves: the solves
    its step took (lagging iterations), lag_change: the relative change of the normal forces at its last lagging
    iteration, normal_force (k,) [N]: the normal forces at x (with friction) over the constraint points
    ``normal_force_points`` (the current ones until a refinement replaces them); start: the source of the warm
    start the step to x was solved from (:class:`simfab.coupling.predictor.WarmStart`; "" when it had none:
    A at rest, the first step)."""

    x: np.ndarray
    s: float
    points: ContactPoints
    refined: set
    order: int
    kappa: float = 0.0
    kappa_step: float = 0.0
    evaluation: Evaluation | None = None
    tangent: object = None
    prev: PastStep | None = None
    prev2: PastStep | None = None
    pin_basis: np.ndarray | None = None
    grad_peak: float = 0.0
    check: object = None
    check_cache: dict = field(default_factory=dict)
    direction: int = 1
    friction: object = None
    lag_solves: int = 0
    lag_change: float = 0.0
    normal_force: np.ndarray | None = None
    normal_force_points: ContactPoints | None = None
    start: str = ""

    def current_evaluation(self) -> Evaluation | None:
        """Newton's last evaluation when it belongs to the current state (at ``x``, over the current
        points: a refinement since changes the points), else None."""
        ev = self.evaluation
        if ev is None or ev.x is not self.x or len(ev.distances) != len(self.points):
            return None
        return ev


#: Lagged factorizations from this many unknowns on a quadratic (P2) model: at every size, since its
#: iterative solves stop at Newton's force target (:func:`simfab.coupling.rigid.forcing`); measured
#: in docs/benchmarks.md, section 3e. A linear model lags from :class:`LagConfig`'s own threshold.
P2_LAG_MIN_UNKNOWNS = 0


def step_solver(model) -> SPDSolver:
    """The insertion's sparse solver on ``model``: lagged factorizations (:class:`LagConfig`; on a
    quadratic model from :data:`P2_LAG_MIN_UNKNOWNS`) and, on a quadratic model, p-multigrid conjugate
    gradients at large sizes (:class:`MultigridConfig`)."""
    lag = LagConfig(min_unknowns=P2_LAG_MIN_UNKNOWNS) if model.element_order == 2 else LagConfig()
    return insertion_solver(model, lag=lag, multigrid=MultigridConfig())


@dataclass(kw_only=True)
class StepContext:
    """Per-run services of the insertion loop: ``timer`` (seconds per stage: assembly, factorization,
    solves, contact_field, barrier, line_search, predictor; see :mod:`simfab.coupling.timing`),
    ``phases`` (seconds per loop phase: warm_start, newton, facet_check, record, rigid_check) and
    the sparse ``solver`` whose symbolic factorization every solve reuses; ``exact_failed``: the
    last Newton solve found the exact Hessian indefinite (see :func:`simfab.coupling.objective.solve`);
    ``guide``: a coarser run of the same insertion offering warm-start candidates
    (:class:`simfab.coupling.guide.CoarseGuide`), or None; ``guided``: the steps whose warm start
    was one of its candidates."""

    timer: Timer = field(default_factory=Timer)
    phases: Timer = field(default_factory=Timer)
    solver: SPDSolver = field(default_factory=lambda: SPDSolver(lag=LagConfig()))
    exact_failed: bool = False
    guide: CoarseGuide | None = None
    guided: int = 0


def accept(state: StepState, x: np.ndarray, s: float, kappa: float, evaluation: Evaluation | None,
           start: str = "") -> None:
    """Make the converged x at path length s (solved with barrier stiffness ``kappa`` from a warm start
    of source ``start``) the current state, with Newton's last evaluation there."""
    state.x, state.s, state.kappa_step, state.start = x, s, kappa, start
    state.evaluation = evaluation
    # the objective's last evaluation may be a rejected line-search trial (Newton stopping at the
    # round-off floor): its Hessian belongs to x only when the evaluation does
    state.tangent = evaluation.hessian if evaluation is not None else None
