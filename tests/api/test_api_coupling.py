"""The coupling area through the public API only: ``simfab.couple.simulate`` / ``simfab.coupling.run``."""

import dataclasses
import subprocess
import sys

import numpy as np
import pytest

import simfab
from simfab.errors import InputError
from simfab.results import units


@pytest.fixture(scope="module")
def loose():
    return simfab.couple.simulate("clip2d_loose", steps=3)


def test_simulate_returns_a_typed_frozen_result_with_its_profile(loose):
    r = loose
    assert isinstance(r, simfab.coupling.CouplingResult) and isinstance(r.profile, simfab.coupling.Profile)
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.F_in = 0.0
    # the profile's figures are the result's, read from its per-record arrays
    assert r.profile.F_in == r.F_in and r.profile.E_max == r.E_max and r.profile.category == r.category
    assert r.E_max == pytest.approx(float(r.profile.energy.max()), rel=1e-12)
    assert r.F_in == pytest.approx(max(0.0, -float(r.profile.force[: r.profile.index_ss + 1].min())), rel=1e-12)
    assert r.outputs == {}  # nothing written without out
    u = units(r)
    assert (u["F_in"], u["E_max"], u["max_von_mises"], u["s_max"], u["coupling_ratio"]) == ("N", "J", "Pa", "m", "%")
    assert r.units["F_in"] == "N"  # (the JSON's own units table agrees)


def test_profile_is_its_summary_plus_the_records(loose):
    from simfab.coupling.profile import ProfileSummary, analyze_run

    # one declaration of the figures: Profile adds only the per-record arrays to ProfileSummary
    assert issubclass(simfab.coupling.Profile, ProfileSummary)
    summary = analyze_run(loose.insertion)
    for f in dataclasses.fields(ProfileSummary):
        assert getattr(loose.profile, f.name) == getattr(summary, f.name), f.name
    assert units(loose.profile)["F_grip"] == "N" and units(loose.profile)["E_ss"] == "J"


def test_profile_to_pandas_has_one_row_per_record_with_units_in_the_names(loose):
    df = loose.profile.to_pandas()
    assert len(df) == len(loose.insertion.steps) + len(loose.insertion.removal)
    assert {"s_m", "energy_J", "force_N", "grip_N", "max_von_mises_Pa", "phase"} <= set(df.columns)
    np.testing.assert_array_equal(df["force_N"].to_numpy(), loose.profile.force)
    assert set(df["phase"]) == {"insert"}  # frictionless: no removal traversal


def test_run_writes_only_with_out_and_its_json_is_the_cli_json(tmp_path, cli_json):
    r = simfab.coupling.run("clip2d_loose", steps=3, out=tmp_path / "api")
    assert set(r.outputs) == {"profile_csv", "plot_png", "usd", "mjcf", "profile_json"}
    assert all((tmp_path / "api" / p).is_file() for p in map(lambda s: s.rsplit("/", 1)[1], r.outputs.values()))
    d = cli_json(["couple", "simulate", "clip2d_loose", "--steps", "3", "--out", str(tmp_path / "cli")])
    assert list(d) == list(r.to_json())  # the same keys, in the same order
    for k in ("category", "E_max", "F_in", "F_rm", "F_grip", "newton_iterations", "averaged_von_mises"):
        assert d[k] == pytest.approx(r.to_json()[k], rel=1e-12), k  # deterministic: the same figures


def test_friction_override_reaches_the_scene():
    r = simfab.couple.simulate("clip2d_loose", steps=3, friction=0.2)
    assert r.friction == pytest.approx(0.2) and r.profile.friction == pytest.approx(0.2)
    assert r.removal_steps > 0 and "remove" in set(r.profile.phase)  # with friction the removal is simulated


def test_seed_has_no_effect_the_figures_are_bit_identical(loose):
    # the insertion is deterministic (a 3D mesh object's sampling takes the scene's [object] seed): any
    # run seed gives the same figures, bit for bit (wall times aside)
    timing = {"seconds", "time_split", "phase_split"}
    other = simfab.couple.simulate("clip2d_loose", steps=3, seed=12345)
    assert {k: v for k, v in other.to_json().items() if k not in timing} == \
        {k: v for k, v in loose.to_json().items() if k not in timing}
    np.testing.assert_array_equal(other.profile.force, loose.profile.force)


def test_unknown_override_is_bad_input_naming_it():
    with pytest.raises(InputError, match="frcition"):
        simfab.couple.simulate("clip2d_loose", frcition=0.2)


def test_import_simfab_and_its_conveniences_load_no_solver():
    code = ("import sys, simfab; simfab.couple; simfab.validate; simfab.crowd; simfab.grow; "
            "bad = [m for m in sys.modules if m.split('.')[0] in ('warp', 'mujoco', 'pxr')]; print(bad)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "[]"


def test_converge_returns_the_study_typed(tmp_path):
    # the study of `simfab couple converge` as a typed result: per figure its values, limit, order and errors;
    # on the 2D clamp from 2,400 to 9,700 triangles the errors fall level by level at an order near 2 (P1
    # triangles: h^2 in energy; its coarser 1,200-triangle level is not yet asymptotic, order 1.1)
    from simfab.coupling.converge import ConvergenceResult

    c = simfab.couple.converge("cclamp2d", factors=(0.5, 1, 2))
    assert isinstance(c, ConvergenceResult) and c.outputs == {} and c.warnings == ()
    assert [lv.factor for lv in c.levels] == [0.5, 1.0, 2.0] and c.levels[0].elements < c.levels[-1].elements
    F = c.figures["F_in"]
    assert 1.5 < F.order < 3.0 and abs(F.relative_error[0]) > abs(F.relative_error[1]) > abs(F.relative_error[2])
    assert c.error_of_default["F_in"] == F.relative_error[1]  # the scene's own mesh: factor 1
    assert F.relative_error[1] == pytest.approx((F.values[1] - F.extrapolated) / F.extrapolated, rel=1e-12)
    j = c.to_json()
    assert j["figures"]["F_in"]["order"] == F.order and "figures" not in j["levels"][0]
    assert units(c)["friction"] == "-"
    with pytest.raises(InputError, match="two positive factors"):
        simfab.couple.converge("cclamp2d", factors=(1,))
    with pytest.raises(InputError):
        simfab.couple.converge("cclamp2d", factors=(0.25, 0.5), frcition=0.2)
    # out: the CLI's three files
    w = simfab.couple.converge("cclamp2d", factors=(0.25, 0.5), out=tmp_path)
    assert sorted(w.outputs) == ["csv", "json", "png"] and all((tmp_path / p.split("/")[-1]).is_file()
                                                                for p in w.outputs.values())
