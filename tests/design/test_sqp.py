"""The trust-region SQP (simfab.design.sqp) on closed-form problems: a quadratic objective whose model
is exact, an expensive nonlinear constraint known only through its value and gradient at each
evaluated design, and a cheap constraint imposed in the subproblems. Optimum by the KKT conditions;
every evaluation counted."""

import math

import numpy as np
import pytest

from simfab.design.sqp import CheapConstraints, Sample, SQPConfig, trust_region_sqp

# min |z - a|^2 over [0, 1]^2 subject to c(z) = R^2 - |z|^2 >= 0: the optimum is the disc's point
# nearest a, z* = R a / |a| (a outside the disc), where grad f = -lambda grad c with lambda > 0.
A_POINT = np.array([1.0, 1.0])
R = 0.8
Z_STAR = R * A_POINT / np.linalg.norm(A_POINT)


class Counted:
    """The expensive evaluation: the objective with its exact Hessian, the disc constraint linearized."""

    def __init__(self, fail=None):
        self.calls, self.fail, self.seen = 0, fail, []

    def __call__(self, z):
        self.calls += 1
        self.seen.append(tuple(z))
        if self.fail is not None and self.fail(z):
            return Sample(ok=False)
        return Sample(ok=True, f=float(np.sum((z - A_POINT) ** 2)), g=2.0 * (z - A_POINT), B=2.0 * np.eye(2),
                      c=np.array([R**2 - z @ z]), A=-2.0 * z[None, :])


@pytest.mark.parametrize("z0", [(0.1, 0.2), (0.9, 0.95)])  # feasible and infeasible starts
def test_reaches_the_kkt_point_of_a_disc_constraint(z0):
    ev = Counted()
    res = trust_region_sqp(ev, np.array(z0), options=SQPConfig(radius=0.05, max_evaluations=30, ctol=1e-6))
    assert res.converged, res.message
    assert np.allclose(res.z, Z_STAR, atol=2e-3)
    assert res.sample.violation() <= 1e-4
    # one evaluation per iteration, the start's included, and never the same design twice
    assert ev.calls == res.evaluations == len(res.steps) + 1
    assert len(set(ev.seen)) == ev.calls
    assert ev.calls <= 10


def test_stop_when_feasible_ends_at_the_first_feasible_design():
    # from the infeasible start (0.95, 0.1) the iterates enter the disc far from z* and then slide along its
    # edge; asked to stop when feasible, the method ends at the first accepted design inside the disc (within
    # ctol), with fewer evaluations than the full descent
    full = trust_region_sqp(Counted(), np.array([0.95, 0.1]), options=SQPConfig(radius=0.05, max_evaluations=30,
                                                                               ctol=1e-6))
    assert full.converged and np.allclose(full.z, Z_STAR, atol=2e-3)
    ev = Counted()
    res = trust_region_sqp(ev, np.array([0.95, 0.1]),
                           options=SQPConfig(radius=0.05, max_evaluations=30, ctol=1e-6, stop_when_feasible=True))
    assert res.converged and "feasible" in res.message
    assert res.sample.violation(1e-6) == 0.0
    accepted = [st for st in res.steps if st.accepted]
    assert accepted and accepted[-1].sample is res.sample
    assert all(st.sample.violation(1e-6) > 0.0 for st in accepted[:-1])  # none feasible before the last
    assert ev.calls == res.evaluations < full.evaluations
    assert res.sample.f > full.sample.f + 0.1  # (0.72, 0.15): not yet the optimum
    # a feasible start: no step at all
    ev0 = Counted()
    res0 = trust_region_sqp(ev0, np.array([0.1, 0.2]), options=SQPConfig(stop_when_feasible=True, ctol=1e-6))
    assert ev0.calls == 1 and not res0.steps and np.allclose(res0.z, [0.1, 0.2])


def test_cheap_constraint_is_held_exactly():
    # with z1^2 <= 0.25 (cheap, exact in every subproblem) the optimum is z1 = 0.5, z2 = sqrt(R^2 - 0.25)
    ev = Counted()
    cheap = CheapConstraints(fun=lambda z: np.array([0.25 - z[0] ** 2]),
                             jac=lambda z: np.array([[-2.0 * z[0], 0.0]]))
    res = trust_region_sqp(ev, np.array([0.1, 0.1]), options=SQPConfig(radius=0.1, max_evaluations=30, ctol=1e-6),
                           cheap=cheap)
    assert res.converged, res.message
    assert np.allclose(res.z, [0.5, math.sqrt(R**2 - 0.25)], atol=2e-3)
    assert all(z[0] <= 0.5 + 1e-9 for z in ev.seen)  # no trial outside it: it costs no evaluation
    assert ev.calls <= 10


def test_failed_evaluations_shrink_the_region():
    # designs with z2 > 0.58 cannot be evaluated (a simulation that fails): the method backs off and
    # still ends feasible, below the failing band, with f above the unconstrained optimum's
    ev = Counted(fail=lambda z: z[1] > 0.58)
    res = trust_region_sqp(ev, np.array([0.1, 0.1]), options=SQPConfig(radius=0.2, max_evaluations=30, ctol=1e-6))
    assert any(not st.sample.ok and not st.accepted for st in res.steps)
    assert res.sample.ok and res.sample.violation() <= 1e-4 and res.z[1] <= 0.58
    assert res.sample.f <= float(np.sum((np.array([math.sqrt(R**2 - 0.58**2), 0.58]) - A_POINT) ** 2)) + 1e-2
    assert ev.calls <= 30


def test_start_must_be_valid():
    with pytest.raises(ValueError):
        trust_region_sqp(Counted(fail=lambda z: True), np.array([0.1, 0.1]))
    with pytest.raises(ValueError):
        SQPConfig(radius=0.0)
