"""Deformation-profile analysis on synthetic profiles with known answers."""

import numpy as np
import pytest

from simfab.coupling.profile import SLIDING_REL, analyze, hold_force, steady_state_index

S = np.linspace(0.0, 0.01, 41)


def _bump(s, center, width):
    return np.exp(-((s - center) / width) ** 2)


def test_tight_profile_finds_the_dip_after_the_peak():
    # energy rises to a peak, dips to a non-zero minimum, then rises a little at the end
    E = 1.0 * _bump(S, 0.004, 0.002) + 0.3 * _bump(S, 0.0105, 0.002)
    F = -np.gradient(E, S)
    p = analyze(S, E, F, np.linspace(0, 2, S.size))
    assert p.category == "tight"
    assert p.index_max == int(np.argmax(E))
    # E_ss: the first local minimum seen from the end lies between the two bumps
    k = p.index_ss
    assert 0.004 < S[k] < 0.0105 and E[k - 1] >= E[k] <= E[k + 1]
    assert p.E_ss == pytest.approx(E[k]) and 0 < p.coupling_ratio < 100
    assert p.F_in == pytest.approx(-F.min()) and p.F_rm == pytest.approx(F.max())
    assert p.F_grip == pytest.approx(np.linspace(0, 2, S.size)[k])


def test_loose_profile_has_zero_steady_state_energy():
    E = np.where(S < 0.007, _bump(S, 0.004, 0.0015), 0.0)
    E[S >= 0.007] = 0.0
    p = analyze(S, E, -np.gradient(E, S), np.zeros_like(S))
    assert p.category == "loose" and p.E_ss == 0.0 and p.coupling_ratio == 0.0
    assert S[p.index_ss] == S[-1]


def test_monotonic_profile_ejects_and_uses_e_max_as_steady_state():
    E = np.maximum(S - 0.002, 0.0) ** 2
    p = analyze(S, E, -np.gradient(E, S), np.zeros_like(S))
    # CR = 100 E_ss / E_max with E_ss = E_max: a product and a quotient, each rounded (one ulp each)
    assert p.category == "ejects" and p.E_ss == p.E_max
    assert p.coupling_ratio == pytest.approx(100.0, rel=2 * np.finfo(float).eps)
    assert p.index_ss == p.index_max == S.size - 1


def test_plateau_and_noise_below_tolerance_do_not_create_minima():
    E = np.r_[np.zeros(5), 1.0, 2.0, 3.0, 3.0 + 1e-12, 3.0]
    assert steady_state_index(E, 1e-9) == E.size - 1  # flat end: the end itself is the minimum seen
    p = analyze(np.arange(E.size) * 1.0, E, np.zeros_like(E), np.zeros_like(E))
    assert p.category == "ejects"


def test_a_path_ending_in_a_prescribed_pose_has_its_steady_state_there():
    # the door knocker's design: a snap (peak), energy ~0 while the ring turns, then the ring
    # pressed into the clip in the rotation's last step. Pushed on past a seat (a translation) that
    # last rise is not part of the coupling; at a prescribed end pose it is where the ring rests.
    E = np.where(S < 0.007, _bump(S, 0.004, 0.0015), 0.0)
    E[-1] = 0.7 * E.max()
    F = -np.gradient(E, S)
    seat = analyze(S, E, F, np.zeros_like(S))
    assert seat.category == "loose" and seat.index_ss < S.size - 1
    end = analyze(S, E, F, np.arange(S.size, dtype=float), end_pose=True)
    assert end.category == "tight" and end.index_ss == S.size - 1
    assert end.coupling_ratio == pytest.approx(70.0) and end.F_grip == S.size - 1


def test_hold_force_is_read_at_the_onset_of_sliding():
    """F_hold: the largest pull before the contact slides, the onset interpolated in the slipping
    fraction; the draw past the onset (a detent's) is F_rm's, not F_hold's."""
    force = np.array([-40.0, 10.0, 30.0, 120.0, 175.0])
    slipping = np.array([0.0, 0.5, 1.0, 1.0, 1.0])
    w = (SLIDING_REL - 0.5) / 0.5
    assert hold_force(force, slipping, 175.0) == pytest.approx(10.0 + w * 20.0, rel=1e-12)
    # a contact that never slides drags the part out: the whole removal force holds it
    assert hold_force(force, np.zeros(5), 175.0) == 175.0
    # free from the start (no normal force: slipping 1): nothing holds it
    assert hold_force(np.array([0.0, 0.0, 1.2]), np.ones(3), 1.2) == 0.0
    # a pull that peaked while sticking counts
    assert hold_force(np.array([50.0, 20.0, 25.0]), np.array([0.0, 0.0, 1.0]), 50.0) == 50.0


def test_grip_interpolated_over_the_rest_search_bracket_at_its_last_record():
    """A tight profile continued to rest: planned records, then the rest search's (from index 6),
    whose last record lies past the force's zero crossing (O pushed back from the seat). The grip is
    read at F = 0 between the search's last two records, G linear in F there: G(F=0) = 4 exactly,
    wherever the search stopped; with the record before the last a planned one, it is the last
    record's value (no bracket of the rest point)."""
    s = np.r_[np.linspace(0.0, 5e-3, 6), 5.002e-3, 5.003e-3]
    E = np.array([0.0, 2.0, 5.0, 3.0, 2.0, 1.6, 1.5, 1.45])
    for F_last in (-1.0, -3.0):  # two stops of the search, both past the rest point
        F = np.array([0.0, -2.0, -3.0, 2.0, 1.0, 0.5, 2.0, F_last])
        G = 4.0 + 0.5 * F  # grip linear in the force near the seat
        p = analyze(s, E, F, G, rest_from=6)
        assert p.index_ss == 7 and p.F_grip == pytest.approx(4.0)
        assert analyze(s, E, F, G).F_grip == pytest.approx(G[7])  # no rest search: the record itself
        assert analyze(s, E, F, G, rest_from=7).F_grip == pytest.approx(G[7])  # record before it planned


def test_plotted_traversal_ends_at_the_rest_point_between_the_bracketing_probes():
    """The profile plot's curve (coupling.outputs.traversal_curve) ends where the force crosses zero
    between the two rest-search records that bracket the rest point (linear interpolation, F = 0 there),
    and draws no record past it - whether the bracket starts at the steady-state record or the one
    before it (cclamp2d: E_ss at a probe with F = +1.6 N, the next probe -29 N)."""
    import simfab
    from simfab.coupling.outputs import traversal_curve
    from simfab.coupling.profile import record_phases, rest_bracket

    r = simfab.coupling.run("cclamp2d")
    res, prof = r.insertion, r.profile
    phases = record_phases(res)[:len(res.steps)]
    F = res.column("force")
    a = rest_bracket(F, prof.index_ss, phases.index("rest"))
    assert a is not None and phases[a + 1] == "rest"
    c = traversal_curve(res, prof)
    s = res.column("s") * 1e3
    assert c.force[-1] == 0.0
    assert s[a] < c.s_mm[-1] < s[a + 1]
    assert max(c.records) == a  # nothing drawn past the bracket's first record but the rest point
    if a == prof.index_ss:  # the E_ss marker sits on its own record, the curve goes on to the rest point
        assert c.records[c.marker_index[prof.index_ss]] == prof.index_ss
