"""Rigid motions of A that the contact leaves unresisted at the current state (the math is in
:mod:`simfab.coupling.rigid`): the basis the next step pins, and the weakest motion for the notes."""

from __future__ import annotations

import numpy as np

from simfab.contact.barrier import barrier_hessian
from simfab.coupling import rigid
from simfab.coupling.model import CouplingModel
from simfab.coupling.objective import _point_dhat
from simfab.coupling.state import _State, _state_final

def _unresisted_basis(cm: CouplingModel, state: _State, free_motions) -> np.ndarray:
    """(k, r) the free rigid motions that the contact at the current state leaves unresisted
    (:func:`simfab.coupling.rigid.unresisted`; all of them without contact)."""
    fin = _state_final(state)
    Q, c = free_motions
    if Q.shape[1] == 0:
        return Q
    if fin is None:
        return state.pin_basis if state.pin_basis is not None else Q
    d, gd = fin[4], fin[5]
    dh = _point_dhat(cm, state.points)
    act = (d < dh) & (np.einsum("kd,kd->k", gd, gd) > 0)
    if not act.any():
        return Q
    y = state.points.positions(state.x)[act]
    nrm = gd[act] / np.linalg.norm(gd[act], axis=1, keepdims=True)
    return rigid.unresisted(Q, c, y, nrm, barrier_hessian(d[act], dh[act]))


def _weakest_rigid_motion(cm: CouplingModel, state: _State, free_motions):
    """(ratio, motion, s, radius) of the rigid motion of A that the contact at the current state
    resists least (see :func:`simfab.coupling.rigid.weakest_motion`), or None without contact or
    free motion."""
    fin = _state_final(state)
    Q, c = free_motions
    if fin is None or Q.shape[1] == 0:
        return None
    d, gd = fin[4], fin[5]
    dh = _point_dhat(cm, state.points)
    act = (d < dh) & (np.einsum("kd,kd->k", gd, gd) > 0)
    if not act.any():
        return None
    y = state.points.positions(state.x)[act]
    nrm = gd[act] / np.linalg.norm(gd[act], axis=1, keepdims=True)
    out = rigid.weakest_motion(Q, c, y, nrm, barrier_hessian(d[act], dh[act]))
    if out is None:
        return None
    return out[0], out[1], state.s, float(np.sqrt(np.mean(np.sum((y - c) ** 2, axis=1))))
