"""Rigid motions of A that the contact leaves unresisted at the current state (the math is in
:mod:`simfab.coupling.rigid`): the basis the next step pins, and the weakest motion for the notes."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simfab.contact.barrier import barrier_hessian
from simfab.coupling import rigid
from simfab.coupling.layout import point_dhat
from simfab.coupling.model import CouplingModel
from simfab.coupling.state import StepState


@dataclass(frozen=True, eq=False)
class WeakMotion:
    """The rigid motion of A the contact resists least at path length s [m]: ratio [-] its contact
    stiffness over the stiffness it would have if every contact normal were aligned with it, motion
    (r,) its coordinates in :func:`simfab.coupling.rigid.motion_basis`, radius [m] the RMS distance
    of the contact points from A's rest centroid (for describing a rotation)."""

    ratio: float
    motion: np.ndarray
    s: float
    radius: float


@dataclass(frozen=True, eq=False)
class RigidContact:
    """basis (k, r'): the free rigid motions the contact leaves unresisted (what the next step pins;
    all of them without contact); weakest: the motion it resists least (None without contact or
    free motion)."""

    basis: np.ndarray
    weakest: WeakMotion | None


def rigid_contact(cm: CouplingModel, state: StepState, free_motions) -> RigidContact:
    """The unresisted motions at the current state, from one generalized eigenproblem
    (:func:`simfab.coupling.rigid.contact_modes`) over the points in the barrier's range, each
    resisting along O's normal with the barrier's stiffness kappa b''(d); with friction also along
    its tangents with the sticking stiffness 2 mu lambda / eps (friction resists a clip sliding along
    a cylinder, or a claw turning on a sphere: those motions are then not pinned).
    ``free_motions``: :func:`simfab.coupling.rigid.motion_basis` of ``cm``."""
    ev = state.current_evaluation()
    Q, c = free_motions
    if Q.shape[1] == 0:
        return RigidContact(Q, None)
    if ev is None:
        return RigidContact(state.pin_basis if state.pin_basis is not None else Q, None)
    d, gd = ev.distances, ev.distance_gradients
    dh = point_dhat(cm, state.points)
    act = (d < dh) & (np.einsum("kd,kd->k", gd, gd) > 0)
    if not act.any():
        return RigidContact(Q, None)
    y = state.points.positions(state.x)[act]
    nrm = gd[act] / np.linalg.norm(gd[act], axis=1, keepdims=True)
    w = ev.kappa * barrier_hessian(d[act], dh[act])
    lag = state.friction  # the lagged contact the state was solved with (with friction)
    if lag is not None and lag.points is state.points and len(lag.rows):
        # sticking friction along each tangent of the points in contact: stiffness 2 mu lambda / eps
        stick = 2.0 * lag.mu_lambda / lag.eps
        T = lag.tangents
        y = np.vstack([y, *[state.points.positions(state.x)[lag.rows]] * T.shape[2]])
        nrm = np.vstack([nrm, *[T[:, :, i] for i in range(T.shape[2])]])
        w = np.concatenate([w, *[stick] * T.shape[2]])
    modes = rigid.contact_modes(Q, c, y, nrm, w)
    if modes is None:
        return RigidContact(Q, None)
    lam, motions = modes
    radius = float(np.sqrt(np.mean(np.sum((y - c) ** 2, axis=1))))
    return RigidContact(motions[:, lam < rigid.UNRESISTED_REL],
                        WeakMotion(float(max(lam[0], 0.0)), motions[:, 0], state.s, radius))
