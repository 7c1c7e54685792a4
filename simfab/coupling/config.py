"""Configuration of the insertion simulation (keyword-only dataclasses) and the area's tolerances.

Lengths are relative to A's mean edge length ``h_A`` where noted (``*_rel``), so one set of
defaults works at any scale and resolution. Each config class is one table of a coupling scene's
TOML, loaded by :func:`simfab.io.tables.load_table` (unknown keys, types, and the ranges its
``__post_init__`` checks, each error naming the file and table or the flag that gave the value).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simfab.io.tables import FieldError

# ---------------------------------------------------------------------------- tolerances (one place)
#: Max penetration allowed at the end of every step, relative to h_A (checked, else ConvergenceError).
PENETRATION_TOL_REL = 1e-3
#: Barrier activation distance d_hat relative to the local boundary edge length (layout.point_dhat).
DHAT_REL = 1e-2
#: Lipschitz bound of the IMLS field used by the conservative step cap (|grad psi| ~ 1 near O).
PSI_LIPSCHITZ = 2.0
#: Fraction of the distance to O a point within the barrier's range (d < d_hat) may travel in one
#: Newton step (conservative advancement; Newton's model holds its barrier).
STEP_FRACTION = 0.9
#: A point outside the barrier's range may travel until it is CAP_LAND_DHATS * d_hat away: it lands
#: inside the range, so the next Newton step sees it (at 10 % of a gap of more than 10 d_hat it would
#: still be outside and cap that step again), and no deeper, since the step that carried it did not see
#: its barrier: from 10 % of a gap of 1-5 d_hat it landed at 0.1-0.5 d_hat, where each Newton iteration
#: of the log barrier at most doubles the gap of a point whose equilibrium lies at ~0.75 d_hat.
CAP_LAND_DHATS = 0.5
#: Barrier stiffness adaptation: double kappa after a step that ends with a point closer than
#: KAPPA_GROW_BELOW * d_hat to O, up to KAPPA_MAX_GROWTH times its initial value.
KAPPA_GROW_BELOW = 1e-3
KAPPA_MAX_GROWTH = 1e3
#: Step cap curvature bound K = max(CURVATURE_SAFETY * max |hess d| near O, CURVATURE_FLOOR / sigma).
CURVATURE_SAFETY = 2.0
CURVATURE_FLOOR = 0.1
#: Lazy contact evaluation: points certified (by the Lipschitz bound) farther than
#: LAZY_BAND_DHATS * d_hat from O are not re-evaluated (the barrier acts within d_hat only).
LAZY_BAND_DHATS = 4.0
#: Newton: stop when the step is below this fraction of h_A ...
NEWTON_STEP_TOL_REL = 1e-7
#: ... or the free-dof force residual is below this fraction of E * h_A^2 (3D) / E * h_A * t (2D)
#: (Newton converges quadratically near this tolerance, so the profile figures are settled to far
#: more digits than the force residual suggests).
NEWTON_GRAD_TOL_REL = 1e-6
#: A frictional step's lagging iterations solve to a force residual of LAG_RESIDUAL_REL * lag_tol times
#: the largest lagged normal force (or Newton's tolerance, if larger) until the normal forces settle,
#: then once to Newton's tolerance: such a residual moves the normal forces by a tenth of the lagging
#: tolerance at most, and Newton's last iterations are not spent on a lag that changes anyway.
LAG_RESIDUAL_REL = 0.1
#: ... or below this fraction of the residual at the step's warm start.
NEWTON_GRAD_TOL_START = 1e-5
NEWTON_MAX_ITER = 100
#: On linear elements Newton evaluates the Hessian at its first line-search trial (most are accepted
#: at once) unless the residual is already within this factor of the target (the trial is then most
#: likely the converged point, which needs no Hessian). On quadratic ones never: a rejected trial's
#: Hessian is wasted and the accepted one's costs more than the gradient it replaces (the P2 Hessian
#: launch ~2-3 gradient launches, the contact blocks and the pin on top): eager on cclamp2d's P2 run,
#: 220 -> 240 ms (medians of 30 alternating runs). A linear element's Hessian costs about one
#: objective evaluation.
NEWTON_EAGER_ABOVE_TOL = 10.0
#: A Newton iterate within this factor of the force target takes a chord step (the solve's last
#: factorization reused: no Hessian, no factorization) before a fresh Newton step
#: (``NewtonConfig.chord_within``; the measurements: docs/decisions.md).
NEWTON_CHORD_WITHIN = 10.0
#: Predictor: penalty weight (relative to max |diag H|) pushing reachable points with O.
PREDICTOR_PENALTY = 1e4
#: Predictor: retries carrying newly infeasible points fully with O before bisecting the step.
PREDICTOR_RETRIES = 3
#: Predictor: a push by the gaps that leaves an element below this fraction of its volume (det F) has
#: met a deep overlap with a few points: a point load's dent, which the push of the whole contact region
#: spreads (it is then solved too, the lower objective kept). Measured: such dents 0.40, every other push
#: of the family in docs/decisions.md 0.975 or more.
PREDICTOR_DENT_J = 0.8
#: Refinement density limits when it is doubled because refined facets still penetrate O by more
#: than the tolerance between their points (2D: points per edge, 3D: face lattice order).
MAX_EDGE_SAMPLES = 160
MAX_FACE_LATTICE = 16
#: Step bisection depth when a step cannot be taken in one go (2^-6 of h_in at most).
MAX_BISECTIONS = 6
#: After a refinement the step is solved again from its converged positions with the new points
#: that lie inside O lifted out to LIFT_TO * d_hat (their facets' vertices move); from the previous
#: step's state when that is infeasible or fails. 0.8 is near where contact points settle (see
#: WARM_START_FLOOR), so a lifted point starts close to its equilibrium gap.
LIFT_TO = 0.8
#: Warm-start points closer to O than WARM_START_FLOOR * d_hat (and not that close at the last
#: step) are lifted to LIFT_TO * d_hat: from a small gap the log barrier's Newton steps only about
#: double it (one iteration per doubling), while with the barrier stiffness kappa of the bundled
#: scenes contact points settle at 0.8-0.95 d_hat. The measured choice of (floor, lift) is in
#: docs/decisions.md.
WARM_START_FLOOR = 0.7
#: Refinement rounds per step (each adds the facets found crossing O) before ConvergenceError.
MAX_REFINEMENT_ROUNDS = 64
#: Diagonal term (relative to A's mean stiffness) that keeps the Hessian factorizable when the
#: supports leave rigid motions free (Hessian only; the pin, rigid.Pin, fixes those motions).
FACTOR_REG = 1e-10
#: A step whose pinned rigid motion the contact turns out to resist is solved again without the pin
#: only when the pin held it with more than this many Newton force tolerances (else the pinned
#: motion was in balance and the solution stands).
PIN_FORCE_TOL = 10.0
#: Profile analysis: energies within this fraction of E_max are equal (plateaus, noise).
ENERGY_REL_TOL = 1e-6
#: A steady state with E_ss <= LOOSE_REL * E_max is "loose" (zero grip).
LOOSE_REL = 1e-3


@dataclass(frozen=True, kw_only=True)
class ContactConfig:
    """Contact between the object O and the part A (scene TOML table ``[contact]``).

    Args:
        friction: Coulomb coefficient mu >= 0 between O and A [-]; 0 (the default) is frictionless.
            Printed PLA on PLA or on metal: roughly 0.2-0.5.
        friction_eps_rel: the stick-slip transition eps of the friction mollifier
            (:mod:`simfab.contact.friction`) relative to the local boundary edge length at each contact
            point [-]: below eps of tangential slip over a step a point sticks (a spring of stiffness
            2 mu lambda / eps), beyond it it slides with the force mu lambda (the measured choice of the
            default: docs/decisions.md).
        lag_tol: the normal forces and tangent bases are lagged (from the step's start, then from its
            solution); a step is solved again with the refreshed ones until its normal forces change by
            less than this fraction of the largest normal force [-]. The friction forces are consistent
            with the normal forces to this tolerance (the measured choice of the default: docs/decisions.md).
        max_lag_iterations: solves per step at most (the first included); a step whose normal forces
            still change by more than ``lag_tol`` after them is reported in the run's warnings.
    """

    friction: float = 0.0
    friction_eps_rel: float = 3e-3
    lag_tol: float = 3e-2
    max_lag_iterations: int = 6

    def __post_init__(self):
        def bad(name, why):
            v = getattr(self, name)
            raise FieldError(f"{name}={v!r} {why}", key=name, where="[contact]", flag_message=f"{why}, got {v!r}")

        for name in ("friction", "friction_eps_rel", "lag_tol"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                bad(name, "must be a number")
        if not 0 <= self.friction <= 2:
            bad("friction", "must be a Coulomb coefficient in [0, 2]")
        if not 0 < self.friction_eps_rel <= 0.1:
            bad("friction_eps_rel", "must lie in (0, 0.1]")
        if not 0 < self.lag_tol < 1:
            bad("lag_tol", "must lie in (0, 1)")
        if isinstance(self.max_lag_iterations, bool) or not isinstance(self.max_lag_iterations, int) \
                or not 1 <= self.max_lag_iterations <= 50:
            bad("max_lag_iterations", "must be an integer in [1, 50]")



@dataclass(frozen=True, kw_only=True)
class InsertionConfig:
    """Insertion-simulation parameters (scene TOML table ``[simulation]``).

    Args:
        h_in: insertion step along the path [m] (path length: translation plus rotation angle times
            the object's radius); None: ``L_max / steps``.
        steps: number of steps when ``h_in`` is None.
        L_max: insertion length [m]; None: until O's centre passes A's farthest point along the
            insertion direction, or the whole keyframe path if it ends before that.
        fix_all_axes: fix the fixed region in all axes (default: only along the insertion axis).
        fixed_axes: the axes the fixed region is held along, e.g. "xz" (must include the insertion
            axis); None: the insertion axis only (or all with ``fix_all_axes``). Hold an axis for the
            part's physics (how it is mounted), not for the solver: rigid motions that neither the
            supports nor the contact resist are pinned by the solver (simfab.coupling.rigid).
        refine: add interpolated constraint points on boundary edges/faces that cross into O.
        samples_per_edge: 2D refinement points per boundary edge (paper: 10).
        face_lattice: 3D refinement: barycentric lattice order per boundary face (order m gives
            (m+1)(m+2)/2 - 3 points; 4 -> 12).
        dhat_rel: barrier activation distance / the local boundary edge length at each constraint point
            (CouplingModel.dhat is the same fraction of the mean edge length h_A, for reference).
        kappa_rel: initial barrier stiffness kappa = kappa_rel * E * h_A (3D) or E * thickness (2D)
            [N/m] (the stiffness per node of A's elements); adapted during the run (see simulate).
        penetration_tol_rel: max penetration / h_A accepted at the end of a step.
        element_order: 1 (linear triangles / tets, the scene's mesh as it is) or 2 (quadratic: the
            mesh lifted to 6-node triangles / 10-node tets by :func:`simfab.fem.p2.to_p2`, which do
            not lock in bending; contact then acts at every boundary node, corners and edge
            midpoints, and on the linear sub-facets of the quadratic boundary, whose edges, half the
            element's, set the local d_hat). h_A stays the corner mesh's mean edge length. The
            rest-shape optimizer needs 1.
    """

    h_in: float | None = None
    steps: int | None = None
    L_max: float | None = None
    fix_all_axes: bool = False
    fixed_axes: str | None = None
    refine: bool = True
    samples_per_edge: int = 10
    face_lattice: int = 4
    dhat_rel: float = DHAT_REL
    kappa_rel: float = 1.0
    penetration_tol_rel: float = PENETRATION_TOL_REL
    element_order: int = 1

    def __post_init__(self):
        def bad(name, why):
            v = getattr(self, name)
            raise FieldError(f"{name}={v!r} {why}", key=name, where="[simulation]", flag_message=f"{why}, got {v!r}")

        if self.h_in is not None and not (isinstance(self.h_in, (int, float)) and self.h_in > 0):
            bad("h_in", "must be a positive length [m]")
        if self.steps is not None and not (isinstance(self.steps, int) and self.steps >= 1):
            bad("steps", "must be an integer >= 1")
        if self.L_max is not None and not (isinstance(self.L_max, (int, float)) and self.L_max > 0):
            bad("L_max", "must be a positive length [m]")
        if self.fixed_axes is not None:
            ax = self.fixed_axes
            if not (isinstance(ax, str) and ax and set(ax) <= set("xyz") and len(set(ax)) == len(ax)):
                bad("fixed_axes", 'must be distinct axis letters from "xyz", e.g. "xz"')
            if self.fix_all_axes:
                bad("fixed_axes", "cannot be combined with fix_all_axes = true")
        if not (isinstance(self.samples_per_edge, int) and 1 <= self.samples_per_edge <= 100):
            bad("samples_per_edge", "must be an integer in [1, 100]")
        if not (isinstance(self.face_lattice, int) and 2 <= self.face_lattice <= 16):
            bad("face_lattice", "must be an integer in [2, 16]")
        if not (isinstance(self.element_order, int) and not isinstance(self.element_order, bool)
                and self.element_order in (1, 2)):
            bad("element_order", "must be 1 (linear elements) or 2 (quadratic)")
        for name in ("dhat_rel", "kappa_rel", "penetration_tol_rel"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and v > 0):
                bad(name, "must be a positive number")



@dataclass(frozen=True, kw_only=True)
class ObjectConfig:
    """The rigid object O (scene TOML table ``[object]``).

    Args:
        body: name of O's mocap body in the MJCF.
        samples: surface samples of O for its IMLS field (>= 8); None: 50 in 2D, 2000 in 3D. An
            object made only of primitive geoms uses their exact signed distance unless ``sigma`` is
            given (samples then only sets its display samples).
        sigma: IMLS support radius [m]; None: from the sample spacing (and the exact field for primitives).
        seed: seed of O's 3D surface sampling (an integer >= 0).
        rot_length_scale: rho [m/rad], the length a rotation of O along its path counts per radian;
            None: O's bounding radius (simfab.io.mjcf.Trajectory).
    """

    body: str = "object"
    samples: int | None = None
    sigma: float | None = None
    seed: int = 0
    rot_length_scale: float | None = None

    def __post_init__(self):
        def bad(name, why):
            v = getattr(self, name)
            raise FieldError(f"{name}={v!r} {why}", key=name, where="[object]", flag_message=f"{why}, got {v!r}")

        if not (isinstance(self.body, str) and self.body):
            bad("body", "must be the name of O's mocap body")
        if self.samples is not None and (isinstance(self.samples, bool) or not isinstance(self.samples, int)
                                         or self.samples < 8):
            bad("samples", "must be an integer >= 8 (too few for the object's IMLS field)")
        for name in ("sigma", "rot_length_scale"):
            v = getattr(self, name)
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v < float("inf")):
                bad(name, "must be a positive length [m]")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or not 0 <= self.seed < 2**32:
            bad("seed", "must be an integer in [0, 2**32)")



#: The earlier names of the config classes (``...Config`` is the package's one suffix for configuration).
