"""Rigid motions of A that the contact leaves unresisted at the current state (the math is in
:mod:`simfab.coupling.rigid`): the basis the next step pins, and the weakest motion for the notes."""

from __future__ import annotations

import numpy as np

from simfab.contact.barrier import barrier_hessian
from simfab.coupling import rigid
from simfab.coupling.model import CouplingModel
from simfab.coupling.objective import _point_dhat
from simfab.coupling.state import _State, _state_final

def _rigid_contact(cm: CouplingModel, state: _State, free_motions):
    """(basis, weakest) at the current state, from one generalized eigenproblem
    (:func:`simfab.coupling.rigid.contact_modes`): basis (k, r') the free rigid motions that the
    contact leaves unresisted (what the next step pins; all of them without contact), weakest
    (ratio, motion, s, radius) the motion it resists least (for the notes; None without contact or
    free motion)."""
    fin = _state_final(state)
    Q, c = free_motions
    if Q.shape[1] == 0:
        return Q, None
    if fin is None:
        return (state.pin_basis if state.pin_basis is not None else Q), None
    d, gd = fin[4], fin[5]
    dh = _point_dhat(cm, state.points)
    act = (d < dh) & (np.einsum("kd,kd->k", gd, gd) > 0)
    if not act.any():
        return Q, None
    y = state.points.positions(state.x)[act]
    nrm = gd[act] / np.linalg.norm(gd[act], axis=1, keepdims=True)
    modes = rigid.contact_modes(Q, c, y, nrm, barrier_hessian(d[act], dh[act]))
    if modes is None:
        return Q, None
    lam, motions = modes
    radius = float(np.sqrt(np.mean(np.sum((y - c) ** 2, axis=1))))
    return motions[:, lam < rigid.UNRESISTED_REL], (float(max(lam[0], 0.0)), motions[:, 0], state.s, radius)
