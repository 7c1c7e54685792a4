"""Coulomb friction between O and A in the insertion step: the lagged data of the friction potential
(:mod:`simfab.contact.friction`) over a step, and its forces and dissipation at a solution.

Over a step from path length s_a to s_b O moves rigidly, y -> M (y - p_a) + p_b. A constraint point
that starts the step at y_j^a would, sticking to O, end it at the anchor c_j = M (y_j^a - p_a) + p_b;
its relative displacement is dy_j = y_j(x) - c_j, whose tangential part slips. The normal force
lambda_j = -kappa b'(d_j) [N] and O's outward normal n_j (hence the tangent basis T_j) are lagged:
taken first from the step's start (normals carried by O's rotation M), then from the step's own
solution, and the step is solved again until the normal forces change by less than ``lag_tol`` of
the largest (IPC's lagged friction). Points beyond their barrier range (lambda = 0) carry no
friction. The mollifier width is eps_j = ``friction_eps_rel`` times the local boundary edge length.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from simfab.contact.barrier import barrier_gradient
from simfab.contact.friction import FrictionEval, FrictionPoints, tangent_bases
from simfab.coupling.layout import point_dhat
from simfab.coupling.model import CouplingModel
from simfab.coupling.points import ContactPoints, row_norms

#: A stuck contact counts as self-locked only where O's motion has a tangential part of at least this
#: fraction of it (O pressing straight into a face sticks without locking anything).
LOCK_TANGENTIAL_REL = 0.1


@dataclass(frozen=True, eq=False)
class FrictionLag:
    """The lagged friction data of a step over the constraint points ``points``.

    anchors (k, dim) [m]: each point's anchor c_j (see the module docstring), for every point;
    travel (k, dim) [m]: O's displacement over the step at each point's start position (c_j - y_j^a);
    normal_force (k,) [N]: lagged lambda_j (0 beyond the barrier's range); rows (a,): the points with
    lambda_j > 0; normals (a, dim), tangents (a, dim, dim - 1), mu_lambda (a,) [N], eps (a,) [m] over
    those rows; device: where :meth:`evaluate` runs."""

    points: ContactPoints
    anchors: np.ndarray
    travel: np.ndarray
    normal_force: np.ndarray
    rows: np.ndarray
    normals: np.ndarray
    tangents: np.ndarray
    mu_lambda: np.ndarray
    eps: np.ndarray
    device: str = "cpu"

    @cached_property
    def potential(self) -> FrictionPoints:
        """The rows' friction data on the device (built on the first evaluation: many lags are only
        compared, never evaluated)."""
        return FrictionPoints(self.tangents, self.mu_lambda, self.eps, device=self.device)

    def evaluate(self, x: np.ndarray, *, hessian: bool) -> FrictionEval:
        """The friction potential at positions x (n, dim) over ``rows``."""
        dy = self.points.positions(x)[self.rows] - self.anchors[self.rows]
        return self.potential.evaluate(dy, hessian=hessian)

    def change(self, other: "FrictionLag") -> float:
        """max_j |lambda_j - lambda'_j| over the largest normal force of either lag [-]."""
        scale = max(float(self.normal_force.max(initial=0.0)), float(other.normal_force.max(initial=0.0)))
        if scale <= 0:
            return 0.0
        return float(np.abs(self.normal_force - other.normal_force).max()) / scale


def normal_forces(cm: CouplingModel, points: ContactPoints, distances: np.ndarray, kappa: float) -> np.ndarray:
    """(k,) the barrier's normal force lambda_j = -kappa b'(d_j) [N] at distances (k,) [m] (0 beyond d_hat)."""
    dh = point_dhat(cm, points)
    rows = np.flatnonzero((distances < dh) & (distances > 0))
    lam = np.zeros(len(points))
    lam[rows] = -kappa * barrier_gradient(distances[rows], dh[rows])
    return lam


def lag(cm: CouplingModel, points: ContactPoints, anchors: np.ndarray, travel: np.ndarray, distances: np.ndarray,
        distance_gradients: np.ndarray, kappa: float, rotation: np.ndarray | None = None,
        normal_force: np.ndarray | None = None) -> FrictionLag:
    """The friction lag from distances (k,) [m] and their gradients (k, dim) at some state, with
    barrier stiffness ``kappa`` [N/m]; ``rotation`` (3, 3) carries the normals to the step's end
    pose (from the step's start), None when they are at it already; ``normal_force`` (k,) [N]
    replaces the normal forces of the distances (a prediction), on the points whose normal is known."""
    dh = point_dhat(cm, points)
    gn = row_norms(distance_gradients)
    lam = normal_forces(cm, points, distances, kappa) if normal_force is None else np.where(gn > 0, normal_force, 0.0)
    rows = np.flatnonzero((lam > 0) & (gn > 0))
    n = distance_gradients[rows] / gn[rows, None]
    if rotation is not None:
        dim = n.shape[1]
        n = n @ rotation[:dim, :dim].T
    mu = cm.contact.friction
    eps = cm.contact.friction_eps_rel * dh[rows] / cm.options.dhat_rel
    tangents = tangent_bases(n)
    return FrictionLag(points=points, anchors=anchors, travel=travel, normal_force=lam, rows=rows, normals=n,
                       tangents=tangents, mu_lambda=mu * lam[rows], eps=eps, device=cm.fem.device)


@dataclass(frozen=True)
class FrictionRecord:
    """Friction at a converged step: point_forces (a, dim) [N] the friction force on O at the lag's
    rows (dD/dy_j); path_force [N]: their generalized force along the path; dissipated [J]: the work
    friction dissipated over the step, sum_j dD/dy_j . dy_j >= 0; slipping [-]: the fraction of the
    normal force carried by points that slipped more than eps; max_slip [m]; locked [-]: the fraction
    of the normal force at points that stuck (slip < eps) while O's motion there lay inside the
    friction cone, mu |v_n| >= |v_t|, with a tangential part |v_t| >= LOCK_TANGENTIAL_REL |v|: the
    contact self-locks (a wedge pushed inside its friction cone cannot slide, the part is dragged)."""

    point_forces: np.ndarray
    path_force: float
    dissipated: float
    slipping: float
    max_slip: float
    locked: float


def record(lagged: FrictionLag, x: np.ndarray, velocity: np.ndarray) -> FrictionRecord:
    """The friction of a converged state x (n, dim); ``velocity`` (k, dim): O's material velocity per
    unit path length at every constraint point."""
    fe = lagged.evaluate(x, hessian=False)
    rows = lagged.rows
    dy = lagged.points.positions(x)[rows] - lagged.anchors[rows]
    lam = lagged.normal_force[rows]
    slip = fe.slip >= lagged.eps
    total = float(lam.sum())
    v = lagged.travel[rows]
    vn = np.einsum("kd,kd->k", v, lagged.normals)
    vt = row_norms(v - vn[:, None] * lagged.normals)
    mu = lagged.mu_lambda / np.maximum(lam, 1e-300)
    locked = ~slip & (mu * np.abs(vn) >= vt) & (vt >= LOCK_TANGENTIAL_REL * row_norms(v)) & (vt > 0)
    return FrictionRecord(point_forces=fe.gradient,
                          path_force=float(np.einsum("kd,kd->", fe.gradient, velocity[rows])),
                          dissipated=float(np.einsum("kd,kd->", fe.gradient, dy)),
                          slipping=float(lam[slip].sum() / total) if total > 0 else 0.0,
                          max_slip=float(fe.slip.max(initial=0.0)),
                          locked=float(lam[locked].sum() / total) if total > 0 else 0.0)
