"""The record of a converged insertion step (:class:`StepResult`): energy, forces on O, grip,
stresses and the checks that the state is admissible (:func:`record_step`).

Forces: the reaction at the fixed dofs is r = dE_total/dx there (the force the support applies to
A); by equilibrium of A it equals the force A exerts on O, so the insertion force is F = sum r . u
(u: unit direction of O's translation), negative when A resists the insertion. The path force is
the generalized force on O along the path, P = sum_j f_j(on O) . dy_j/ds (= -d(E + B)/ds without
friction). Contact forces on A are f_a = -dB/dx_a; the grip force is
|| (1/2 sum |f_x|, 1/2 sum |f_y|, 1/2 sum |f_z|) || over the normal (barrier) forces.

With friction (:mod:`simfab.coupling.friction`) the friction forces f_j = dD/dy_j on O join the
reaction and the path force (``path_force_friction`` is their part), and the step's dissipated work
sum_j f_j . dy_j is recorded: over a step the work done on O equals the change of stored energy plus
what friction dissipated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simfab.contact.barrier import point_barrier
from simfab.coupling import friction
from simfab.coupling.layout import point_dhat
from simfab.coupling.model import CouplingModel
from simfab.coupling.refine import facet_check
from simfab.coupling.state import StepState
from simfab.errors import ConvergenceError
from simfab.fem.elastic import det_and_von_mises, energy_gradient


@dataclass(kw_only=True)
class StepResult:
    """One insertion step. Units: s, penetration [m]; energy [J]; forces [N]; stress [Pa].

    Args:
        s: path length of O's reference point [m].
        pos, quat: O's pose (position [m], unit quaternion wxyz).
        x: (n, dim) deformed positions of A's nodes [m].
        energy: elastic energy of A [J].
        force: insertion force: support reactions along O's translation (resisting < 0) [N].
        path_force: generalized force along the path, sum_j f_j(on O) . dy_j/ds = -d(E + B)/ds [N].
        barrier_energy: kappa sum_j b(d_j) at this state [J] (not part of the elastic energy).
        grip: grip force: total normal contact force squeezing O [N], >= 0.
        max_von_mises: the largest element von Mises stress [Pa].
        von_mises: (m,) per element [Pa].
        penetration: deepest penetration of A into O [m].
        min_det_F: the smallest deformation-gradient determinant [-].
        iterations: Newton iterations of the step.
        contact_points: active contact points.
        kappa: barrier stiffness used for this step [N/m].
        phase: "insert" (O moving forward along the path) or "remove" (moving back).
        normal_force: total normal contact force sum_j lambda_j [N].
        path_force_friction: friction's part of path_force [N].
        dissipated: work dissipated by friction over the step leading to this record [J].
        slipping: fraction of the normal force at points that slipped more than eps [-].
        lag_solves: solves of the step with refreshed friction lags (lagging iterations).
        lag_change: relative change of the normal forces at the step's last lagging iteration [-].
        reaction: (dim,) force of the support on A = force of A on O [N].
        locked: fraction of the normal force at self-locked contact points [-] (friction.FrictionRecord).
    """

    s: float
    pos: np.ndarray
    quat: np.ndarray
    x: np.ndarray
    energy: float
    force: float
    path_force: float
    barrier_energy: float
    grip: float
    max_von_mises: float
    von_mises: np.ndarray
    penetration: float
    min_det_F: float
    iterations: int
    contact_points: int
    kappa: float
    phase: str = "insert"
    normal_force: float = 0.0
    path_force_friction: float = 0.0
    dissipated: float = 0.0
    slipping: float = 0.0
    lag_solves: int = 0
    lag_change: float = 0.0
    reaction: np.ndarray | None = None
    locked: float = 0.0


def path_velocity(cm: CouplingModel, s: float, y: np.ndarray) -> np.ndarray:
    """(k, dim) velocity per unit path length of O's material points currently at y (central
    differences of O's pose, one-sided at the ends of the path)."""
    L = float(cm.path.length)
    h = 1e-6 * max(L, 1e-12)
    s0 = max(0.0, s - h)
    s1 = s + h if cm.end_direction is not None else min(L, s + h)  # straight on past the end
    dim = y.shape[1]
    if not cm.path.turns_between(s0, min(s1, L)):  # O translates between s0 and s1: every point moves alike
        return np.repeat(((cm.position(s1) - cm.position(s0)) / (s1 - s0))[None, :dim], len(y), axis=0)
    (R0, p0), (R1, p1) = cm.pose(s0), cm.pose(s1)
    # y -> R_b R_s^T (y - p_s) + p_b for b = 0, 1 (cm.carry), differenced
    Rs, ps = cm.pose(s)
    y3 = np.zeros((len(y), 3))
    y3[:, :dim] = y
    return (((y3 - ps) @ (Rs @ (R1 - R0).T) + (p1 - p0)) / (s1 - s0))[:, :dim]


def record_step(cm: CouplingModel, state: StepState, iterations: int) -> StepResult:
    """The record of the converged current state (see the module docstring for the forces).
    Raises ConvergenceError when an element is inverted or the penetration exceeds the tolerance."""
    x = state.x
    n, dim = cm.fem.n_vertices, cm.dim
    R, p = cm.pose(state.s)
    pts = state.points
    ev = state.current_evaluation()
    if ev is not None and ev.kappa == state.kappa_step and ev.barrier_gradient is not None:
        # Newton's last evaluation at x: exact distances within the lazy band (which contains the
        # barrier's support), certified lower bounds beyond it (zero barrier, outside O), and the
        # barrier of the points within their d_hat
        E, gE, psi_pts = ev.elastic_energy, ev.elastic_gradient, -ev.distances
        act, B, gy = ev.barrier_points, ev.barrier_energy, ev.barrier_gradient
    else:
        E, gE = energy_gradient(cm.fem, x)
        field = cm.field.evaluate(pts.positions(x), (R, p), hessian=False)
        psi_pts = field.psi
        act = None  # (every point)
        B, gy, _ = point_barrier(-field.psi, -field.grad, None, point_dhat(cm, pts), state.kappa_step)
    gc = pts.scatter(gy, n, rows=act)
    grip = float(np.linalg.norm(0.5 * np.abs(-gc).sum(axis=0)))  # -gc: normal contact force on A's vertices
    velocity = path_velocity(cm, state.s, pts.positions(x))
    path_force = float(np.einsum("kd,kd->", gy, velocity if act is None else velocity[act]))
    g = gE + gc
    fr = None
    if state.friction is not None:
        fr = friction.record(state.friction, x, velocity)
        g = g + pts.scatter(fr.point_forces, n, rows=state.friction.rows)
        path_force += fr.path_force
    fixed = ~cm.free.reshape(n, dim)
    reaction = np.where(fixed, g, 0.0).sum(axis=0)  # force of the support on A = force of A on O
    force = float(reaction @ cm.direction(state.s))
    dets, vm = det_and_von_mises(cm.fem, x)
    min_det = float(dets.min())
    if not min_det > 0:
        raise ConvergenceError(f"an element is inverted at s={state.s:.6g} m (min det F = {min_det:.3e})")
    check = facet_check(cm, x, state.s, state)
    pen = float(max(0.0, psi_pts.max(initial=-np.inf), check.psi_max.max(initial=-np.inf)))
    if pen > cm.tol:
        raise ConvergenceError(f"penetration {pen:.3e} m exceeds the tolerance {cm.tol:.3e} m at s={state.s:.6g} m")
    pos, quat = (np.asarray(a).copy() for a in cm.pos_quat(state.s))
    normal = float(np.sqrt(np.add.reduce(gy * gy, axis=1)).sum())  # (np.linalg.norm(gy, axis=1)'s sums)
    return StepResult(
        s=state.s, pos=pos, quat=quat, x=x.copy(), energy=float(E), force=force, path_force=path_force,
        barrier_energy=float(B), grip=grip, max_von_mises=float(vm.max()), von_mises=vm, penetration=pen,
        min_det_F=min_det, iterations=int(iterations), contact_points=len(pts), kappa=float(state.kappa_step),
        phase="remove" if state.direction < 0 else "insert", normal_force=normal,
        path_force_friction=fr.path_force if fr else 0.0, dissipated=fr.dissipated if fr else 0.0,
        slipping=fr.slipping if fr else 0.0, lag_solves=state.lag_solves, lag_change=state.lag_change,
        reaction=reaction, locked=fr.locked if fr else 0.0,
    )
