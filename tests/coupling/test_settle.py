"""The run continues past the keyframes until the object comes to rest, says when it cannot, and
warns when its steps are too coarse for the profile or the part is stressed beyond yield."""

import numpy as np
import pytest

from simfab.coupling.outputs import summarize
from simfab.coupling.profile import analyze
from simfab.coupling.scene import load_coupling_scene
from simfab.coupling.simulate import simulate_insertion


@pytest.fixture(scope="module")
def cclamp():
    return simulate_insertion(load_coupling_scene("cclamp2d"))


def test_cclamp_continues_past_the_keyframes_until_the_cylinder_seats(cclamp):
    # cclamp2d's keyframes end ~0.1 mm before the cylinder seats: the clamp still draws it in with
    # ~18.7 N there. The run goes on until the path force passes through zero: the last two
    # records bracket the rest point (force > 0 then <= 0, or one record with |force| <= 1% of the peak)
    res = cclamp
    n = len(res.model.s_steps)
    P, E, s = res.column("path_force"), res.column("energy"), res.column("s")
    assert len(res.steps) > n and s[-1] > res.model.path.length
    peak = np.abs(P[:n]).max()
    assert P[n - 1] > 0.5 * peak  # drawn in hard at the last keyframe
    assert abs(P[-1]) <= 0.01 * peak or (P[-2] > 0 >= P[-1])
    prof, summary = summarize(res)
    # E_ss is the energy's minimum along the path, below the value at the last keyframe, and a
    # stationary point; the steady state lies past the keyframes
    assert prof.stationary and prof.E_ss == pytest.approx(E[prof.index_max:].min(), rel=1e-12)
    assert prof.E_ss < 0.95 * E[n - 1]
    assert summary["s_ss"] > res.model.path.length
    # no run warning (only the design's yield warning)
    assert all("yield stress" in w for w in res.warnings)


def test_a_run_cut_short_warns_and_its_steady_state_is_not_stationary():
    cm = load_coupling_scene("cclamp2d", overrides={"simulation": {"L_max": 0.0095}})
    res = simulate_insertion(cm)
    assert len(res.steps) == len(cm.s_steps)  # an explicit L_max is not extended
    assert any("still draws the object in" in w and "E_ss is not a stationary point" in w for w in res.warnings)
    prof, _ = summarize(res)
    assert not prof.stationary and prof.index_ss == len(res.steps) - 1


def test_too_few_steps_warn_and_the_default_steps_do_not(cclamp):
    # --steps 1 and 2 change the answer (category, F_in by 40%): the work of the force over a step
    # no longer matches the change of stored energy; the 35-step default resolves the profile
    for steps in (1, 2):
        res = simulate_insertion(load_coupling_scene("cclamp2d", overrides={"simulation": {"steps": steps}}))
        assert any("steps too coarse" in w for w in res.warnings), (steps, res.warnings)
    assert not any("steps too coarse" in w for w in cclamp.warnings)


def test_yield_warning_follows_the_material(cclamp):
    vm = cclamp.column("max_von_mises").max()
    for yield_stress, warned in ((0.5 * vm, True), (2.0 * vm, False)):
        res = simulate_insertion(load_coupling_scene("cclamp2d", overrides={
            "material": {"name": "stiff", "youngs_modulus": 3.5e9, "poisson_ratio": 0.36,
                         "yield_stress": yield_stress}}))
        assert any("exceeds the yield stress" in w for w in res.warnings) == warned


def test_profile_forces_stop_at_the_steady_state():
    # past the steady state O is pushed into its seat: that force is not part of inserting it
    s = np.linspace(0, 1, 7)
    E = np.array([0, 2, 3, 2, 1, 1.2, 3.0])
    F = np.array([0, -2, 0.5, 1.5, 0.5, -1, -20.0])
    p = analyze(s, E, F, np.zeros(7))
    assert p.category == "tight" and p.index_ss == 4 and p.stationary
    assert p.F_in == pytest.approx(2.0) and p.F_rm == pytest.approx(1.5)
    # ending while the energy still falls and the force still draws O in: not stationary
    p = analyze(s[:4], E[:4], F[:4], np.zeros(4))
    assert p.index_ss == 3 and not p.stationary


def _records(s, E, P):
    """Frictionless step records: no friction force, no dissipation, nothing left to lag."""
    from types import SimpleNamespace
    return [SimpleNamespace(s=si, energy=e, barrier_energy=0.0, path_force=p, path_force_friction=0.0,
                            dissipated=0.0, lag_change=0.0, phase="insert", max_von_mises=0.0)
            for si, e, p in zip(s, E, P)]


@pytest.mark.parametrize("scale, coarse", [(1e-14, False), (1e-3, False), (1e3, True)])
def test_step_checks_ignore_a_negligible_profile(scale, coarse):
    # a profile whose steps do not resolve it (the work of the force over each step misses the
    # change of energy by ~50% of E_max, and the force peak lies between steps) warns, unless its
    # E_max is within what Newton's force tolerance f_tol leaves unresolved over the travel
    # (f_tol * travel, NEGLIGIBLE_NOISE of it): a run that barely touched the object (E_max 1e-14 J)
    from types import SimpleNamespace

    from simfab.coupling import config as C
    from simfab.coupling import settle

    s = np.linspace(0.0, 0.01, 5)
    cm = SimpleNamespace(name="t", s_steps=s, force_scale=1e4, fem=SimpleNamespace(material=None),
                         options=SimpleNamespace(L_max=0.01), end_direction=None,
                         contact=SimpleNamespace(lag_tol=0.01, max_lag_iterations=5))
    floor = C.NEWTON_GRAD_TOL_REL * cm.force_scale * s[-1]  # 1e-4 J
    E = scale * floor * np.array([0.0, 0.2, 1.0, 0.3, 0.1])
    P = scale * floor / s[-1] * np.array([0.0, -40.0, -10.0, 80.0, 5.0])
    out = settle.warnings(cm, _records(s, E, P))
    assert any("steps too coarse" in w for w in out) == coarse, out


def _run_to_rest(cm, monkeypatch=None, rest_energy_rel=None):
    """The planned steps, then the rest search with every solve past the path's end counted:
    (outcome, the kept records, [(s, Newton iterations or None)] of the rest search's solves)."""
    from simfab.coupling import settle
    from simfab.coupling.stepper import Stepper

    class Counting(Stepper):
        def step(self, s, *, tolerate=False):
            attempt = super().step(s, tolerate=tolerate)
            if self.steps and s > self.steps[0].s and len(self.steps) >= len(cm.s_steps):
                self.solves.append((s, None if attempt.record is None else attempt.record.iterations))
            return attempt

    stepper = Counting(cm)
    stepper.solves = []
    for s in cm.s_steps:
        stepper.keep(stepper.step(float(s)).record)
    if rest_energy_rel is not None:
        monkeypatch.setattr(settle, "REST_ENERGY_REL", rest_energy_rel)
    return settle.to_rest(cm, stepper), stepper.steps, stepper.solves


def test_rest_search_brackets_the_seat_in_few_solves(monkeypatch):
    # cclamp2d at 455 P2 triangles (the bench case): the clamp still draws the cylinder in at the
    # last keyframe (P ~ +12.5 N, flat) and the seat engages ~0.1 mm on, where P falls to -120 N
    # within 40 um. The search predicts the seat's onset from the contact points' closing rates and
    # stops the step into the seat short of it: at most 3 solves and 20 Newton iterations past the
    # path (bisection after a quarter step into the seat took 4 solves and 28 iterations), ending
    # with the rest point bracketed to the search's tolerance, P_lo (s_hi - s_lo) <= REST_ENERGY_REL
    # E_max, and that bracket containing the rest point of a search 1000x tighter
    from simfab.coupling import settle

    over = {"compliant": {"target_elements": 450}, "simulation": {"element_order": 2}}
    cm = load_coupling_scene("cclamp2d", overrides=over)
    rest, steps, solves = _run_to_rest(cm)
    assert rest == "rest"
    assert len(solves) <= 3 and sum(it for _, it in solves) <= 20, solves
    P = np.array([r.path_force for r in steps])
    s = np.array([r.s for r in steps])
    E_max = max(r.energy for r in steps)
    assert P[-2] > 0 >= P[-1]
    assert P[-2] * (s[-1] - s[-2]) <= settle.REST_ENERGY_REL * E_max
    rest_f, steps_f, solves_f = _run_to_rest(load_coupling_scene("cclamp2d", overrides=over), monkeypatch, 1e-6)
    P_f, s_f = np.array([r.path_force for r in steps_f]), np.array([r.s for r in steps_f])
    assert rest_f == "rest" and len(solves_f) > len(solves)
    # the tight search's rest point: where its last bracket crosses zero (or its last record at rest)
    at_rest = abs(P_f[-1]) <= settle.REST_FORCE_REL * np.abs(P_f).max()
    s_rest = s_f[-1] if at_rest else s_f[-2] + (s_f[-1] - s_f[-2]) * P_f[-2] / (P_f[-2] - P_f[-1])
    assert s[-2] - 1e-9 <= s_rest <= s[-1] + 1e-9, (s[-2:], s_rest, solves_f)


def test_the_stress_figures_and_the_yield_warning_read_the_removal_too():
    # with friction the removal can load the part more than the insertion (claw3d at mu = 0.3: F_rm 65 N
    # against F_in 56 N); the summary's max von Mises stress, penetration and min det F and the yield
    # warning are over every record, as the averaged stress is
    import dataclasses

    from simfab.coupling.outputs import summarize
    from simfab.coupling.scene import load_coupling_scene
    from simfab.coupling.settle import warnings
    from simfab.coupling.simulate import simulate_insertion

    cm = load_coupling_scene("cclamp2d", overrides={"contact": {"friction": 0.3}, "simulation": {"steps": 12}})
    res = simulate_insertion(cm)
    assert res.removal
    peak = max(r.max_von_mises for r in res.steps)
    k = len(res.removal) // 2
    r = res.removal[k]
    res.removal[k] = dataclasses.replace(r, max_von_mises=2.0 * peak, penetration=1e-3, min_det_F=0.5)
    _, summ = summarize(res)
    assert summ["max_von_mises"] == 2.0 * peak
    assert summ["max_penetration"] == 1e-3 and summ["min_det_F"] == 0.5
    msg = [w for w in warnings(cm, res.steps, removal=res.removal) if "yield stress" in w]
    assert len(msg) == 1 and f"{2.0 * peak / 1e6:.4g} MPa" in msg[0] and "removal" in msg[0]
