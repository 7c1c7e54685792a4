"""Design brief parsing and constraint penalties (simfab.design.brief)."""

import math

import numpy as np
import pytest

from simfab.design import brief as B
from simfab.errors import InputError


def test_penalty_zero_inside_bounds_and_growing_outside():
    lim = {"insertion_force": (2.0, 20.0), "von_mises": (0.0, 60e6), "coupling_ratio": (0.1, 95.0),
           "grip_force": (5.0, math.inf), "removal_force": (0.0, 10.0)}
    inside = {"insertion_force": 10.0, "von_mises": 50e6, "coupling_ratio": 50.0, "grip_force": 7.0, "removal_force": 3}
    assert B.penalty(B.constraints(inside, lim)) == 0.0
    assert all(c.satisfied for c in B.constraints(inside, lim))
    for key, values in {"insertion_force": [21, 25, 40], "von_mises": [61e6, 70e6, 100e6],
                        "coupling_ratio": [96, 99, 100], "grip_force": [4, 2, 0],
                        "removal_force": [11, 15, 30]}.items():
        pens = []
        for v in values:
            fig = dict(inside, **{key: v})
            cons = B.constraints(fig, lim)
            assert not next(c for c in cons if c.name == key).satisfied
            pens.append(B.penalty(cons))
        assert 0 < pens[0] < pens[1] < pens[2], key
    # scaled units: 1 N over the bound weighs as much as 1 MPa over the yield stress
    a = B.penalty(B.constraints(dict(inside, insertion_force=21.0), lim))
    b = B.penalty(B.constraints(dict(inside, von_mises=61e6), lim))
    assert np.isclose(a, b) and np.isclose(a, B.PENALTY_WEIGHT)


def test_correction_margin_aims_inside_force_and_stress_bounds():
    """Correction rounds penalize force and stress figures within the margin of their bounds (the
    reported constraints keep the brief's bounds); the coupling ratio keeps its own."""
    lim = {"insertion_force": (2.0, 20.0), "removal_force": (1.0, math.inf), "von_mises": (0.0, 60e6),
           "coupling_ratio": (0.0, 1e-3)}
    fig = {"insertion_force": 10.0, "removal_force": 1.05, "von_mises": 50e6, "coupling_ratio": 0.0}
    cons = B.constraints(fig, lim)
    assert all(c.satisfied for c in cons) and B.penalty(cons) == 0.0
    m = B.CORRECTION_MARGIN
    # 1.05 N is within 10 % of the 1 N floor: (1.1 - 1.05)^2 W
    assert np.isclose(B.penalty(cons, m), B.PENALTY_WEIGHT * (1.0 * (1 + m) - 1.05) ** 2)
    near_yield = B.constraints(dict(fig, removal_force=2.0, von_mises=57e6), lim)
    assert np.isclose(B.penalty(near_yield, m), B.PENALTY_WEIGHT * ((57e6 - 60e6 * (1 - m)) / 1e6) ** 2)
    # bounds of 0 and inf stay, and so does the coupling ratio's
    assert B.penalty(B.constraints(dict(fig, removal_force=5.0, coupling_ratio=0.99e-3), lim), m) == 0.0


def test_bounds_from_grip():
    assert B.constraint_bounds(B.DesignConfig(grip="tight"), 60e6)["coupling_ratio"] == (0.1, 95.0)
    assert B.constraint_bounds(B.DesignConfig(grip="loose"), 60e6)["coupling_ratio"] == (0.0, 1e-3)
    assert "coupling_ratio" not in B.constraint_bounds(B.DesignConfig(grip="any"), 60e6)
    assert B.constraint_bounds(B.DesignConfig(yield_stress=30e6), 60e6)["von_mises"] == (0.0, 30e6)


@pytest.mark.parametrize("table, field", [({"grip": "firm"}, "grip"), ({"handles": 0}, "handles"),
                                          ({"insertion_force": [5, 1]}, "insertion_force"),
                                          ({"grip_force": 3}, "grip_force"), ({"colour": 1}, "unknown"),
                                          ({"placement": "k-means"}, "placement"),
                                          ({"scale_range": [1.2, 2.0]}, "scale_range"),
                                          ({"check_refinements": -1}, "check_refinements"),
                                          ({"check_refinements": 4}, "check_refinements")])
def test_bad_brief_names_the_field(table, field):
    with pytest.raises(InputError) as e:
        B.DesignConfig.from_dict(table, where="x.toml [design]")
    assert "x.toml" in str(e.value) and field in str(e.value)


def test_target_profile_rms(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("distance_m,force_N\n0,0\n0.01,-5\n0.02,0\n")
    s, f = B.read_target_profile(p)
    t = B.TargetProfile(s=s, force=f)
    assert t.rms_error(np.array([0, 0.01, 0.02]), np.array([0, -5, 0])) == 0.0
    # a constant offset of 1 N: RMS 1 N, however the two profiles are sampled
    assert np.isclose(t.rms_error(np.array([0, 0.005, 0.01, 0.0101, 0.02]), np.array([1, -1.5, -4, -3.95, 1.0])), 1.0)
    # the distance integral (both profiles linear between samples): F_sim = 1 against the target's
    # 0 -> -5 -> 0 N tent: 1/L int (1 + 5 (1 - |2s/L - 1|))^2 ds = 1 + 5 + 25/3
    assert np.isclose(t.rms_error(np.array([0, 0.02]), np.array([1.0, 1.0])), np.sqrt(1 + 5 + 25 / 3))
    # a run that ends (at rest) before the target's end, its last record the rest search's overshoot
    # (-40 N): past it the force is 0, so the target's forces there count (they are not left out)
    t2 = B.TargetProfile(s=np.array([0.0, 0.01, 0.02]), force=np.array([0.0, 5.0, 5.0]))
    assert np.isclose(t2.rms_error(np.array([0.0, 0.01, 0.01000001]), np.array([0.0, 5.0, -40.0])), np.sqrt(12.5),
                      rtol=1e-3)
    # a seat (force jump) a micrometre off costs a micrometre's worth, not a whole sample's
    seat = B.TargetProfile(s=np.array([0.0, 0.010, 0.010004]), force=np.array([0.0, 9.0, -4.0]))
    assert seat.rms_error(np.array([0.0, 0.010001, 0.010004]), np.array([0.0, 9.0009, -4.0])) < 0.3
    # the run ends at its rest point, not at the rest search's overshoot: records (0, 0.01, 0.012) m with
    # forces (5, 5, -5) N rest at 0.011 m (F linear 5 -> 0 over the last millimetre); against a target of
    # 5 N on [0, 0.012]: int_0.01^0.011 (5 (0.011 - s) / 1e-3 - 5)^2 ds = 25e-3 / 3, past 0.011 m 25e-3
    flat = B.TargetProfile(s=np.array([0.0, 0.012]), force=np.array([5.0, 5.0]))
    for overshoot in (-5.0, -50.0):  # how deep the search overshot does not matter beyond moving the rest point
        s_end = 0.01 + 0.002 * 5.0 / (5.0 - overshoot)
        want = (25.0 * (s_end - 0.01) / 3.0 + 25.0 * (0.012 - s_end)) / 0.012
        assert flat.rms_error(np.array([0.0, 0.01, 0.012]), np.array([5.0, 5.0, overshoot])) ** 2 == pytest.approx(want)
    s_r, f_r = B.run_to_rest(np.array([0.0, 0.01, 0.012]), np.array([5.0, 5.0, -5.0]))
    assert np.allclose(s_r, [0.0, 0.01, 0.011]) and np.allclose(f_r, [5.0, 5.0, 0.0])
    (tmp_path / "bad.csv").write_text("0,0\n0,1\n")
    with pytest.raises(InputError):
        B.read_target_profile(tmp_path / "bad.csv")


def test_an_override_is_blamed_on_its_flag_a_file_value_on_the_file():
    from simfab.io.tables import Override

    table = {"grip": "tight", "hold_force": [5.0, 10.0]}
    # the file's value: file, table and key
    with pytest.raises(InputError) as e:
        B.DesignConfig.from_dict({"hold_force": [5, 1]}, where="x.toml [design]")
    assert str(e.value) == "x.toml: [design] hold_force: need 0 <= lo <= hi, got [5, 1]"
    # the same value from --hold-force names the flag, not the file that does not hold it
    for bad, flag in (({"hold_force": Override([5.0, 1.0], "--hold-force")}, "--hold-force"),
                      ({"handles": Override(0, "--handles")}, "--handles"),
                      ({"placement": Override("k-means", "--placement")}, "--placement")):
        with pytest.raises(InputError) as e:
            B.DesignConfig.from_dict(table, where="x.toml [design]", overrides=bad)
        assert str(e.value).startswith(f"{flag}: ") and "x.toml" not in str(e.value), str(e.value)
    notes = []
    b = B.DesignConfig.from_dict(table, where="x.toml [design]", log=notes.append,
                                 overrides={"hold_force": Override((1.0, 2.0), "--hold-force")})
    assert b.hold_force == (1.0, 2.0) and b.grip == "tight"
    assert notes == ["--hold-force (1.0, 2.0) overrides x.toml [design] hold_force = [5.0, 10.0]"]
    with pytest.raises(InputError, match="^--iterations: "):
        b.with_overrides(iterations=-3)
