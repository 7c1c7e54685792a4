"""The state of an insertion run between steps (:class:`_State`) and the acceptance of a converged step."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from simfab.coupling.points import ContactPoints

# ----------------------------------------------------------------------------- simulation
@dataclass(kw_only=True)
class _State:
    x: np.ndarray  # (n, dim)
    s: float
    points: ContactPoints
    refined: set
    order: int  # refinement density (2D: points per edge, 3D: face lattice order), doubled on demand
    check: tuple | None = None  # memo of the last facet check (x, s, order, result)
    check_cache: dict = field(default_factory=dict)  # earlier check points' values (_check_cache)
    kappa: float = 0.0  # current barrier stiffness [N/m] (adapted, see _adapt_kappa)
    H: object = None  # last PSD Hessian (for the predictor; a _LazyHessian until first needed)
    final: tuple | None = None  # Newton's last evaluation at x (see _final_eval), for _record
    kappa_step: float = 0.0  # barrier stiffness the current x was solved with [N/m] (kappa may
    # grow for the following steps; forces at x must use the stiffness of its own equilibrium)
    prev: tuple | None = None  # (x, s) of the step before (for the extrapolating predictor)
    prev2: tuple | None = None  # (x, s) two steps before
    grad_peak: float = 0.0  # largest |grad psi| seen at converged constraint and check points [-]
    pin_basis: np.ndarray | None = None  # (k, r) rigid motions (rigid.motion_basis coordinates) the


def _accept(state: _State, x: np.ndarray, s: float, obj: _StepObjective, final) -> None:
    """Make the converged x at path length s the current state, with the Hessian, final
    evaluation (``_final_eval(obj, x)``) and barrier stiffness of the objective it was solved with."""
    state.x, state.s = x, s
    state.final = final
    # the objective's last evaluation may be a rejected line-search trial (Newton stopping at the
    # round-off floor): its Hessian belongs to x only when the evaluation does
    state.H = obj.last_H if state.final is not None else None
    state.kappa_step = obj.kappa


def _state_final(state: _State):
    """Newton's last evaluation (see :func:`_final_eval`) when it belongs to the current state:
    at state.x and over the current constraint points (a refinement since changes the points);
    else None."""
    fin = state.final
    if fin is None or fin[0] is not state.x or len(fin[4]) != len(state.points):
        return None
    return fin
