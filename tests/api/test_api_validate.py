"""The rods validation through the public API only: ``simfab.validate.buckling``."""

import dataclasses

import pytest

import simfab
from simfab.errors import InputError
from simfab.results import units

CASE = dict(g_over_L=[0.9], n=[8, 16], support="pinned", path="direct")


@pytest.fixture(scope="module")
def table():
    return simfab.validate.buckling(**CASE)


def test_buckling_returns_a_typed_result_whose_error_converges(table):
    r = table
    assert isinstance(r, simfab.validate.BucklingResult) and r.outputs == {}
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.passed = False
    by_n = {row["n"]: row for row in r.rows}
    assert set(by_n) == {8, 16}
    # discrete elastic rods converge to the exact elastica (delta/L = k/K(k)) at second order in n
    assert by_n[16]["rel_err"] < by_n[8]["rel_err"]
    assert by_n[16]["order"] == pytest.approx(2.0, abs=0.5)
    assert r.passed and not r.failures  # no case at the tolerance's n = 80 in this table
    assert [c["support"] for c in r.critical_load] == ["pinned"]
    assert units(r)["insert_vs_direct_max_rel_diff"] == "-"


def test_to_json_keys_are_the_cli_json_keys(table, tmp_path, cli_json):
    d = cli_json(["validate", "buckling", "--g-over-L", "0.9", "--n", "8", "16", "--support", "pinned",
                  "--path", "direct", "--out", str(tmp_path)])
    assert list(d) == list(table.to_json())
    assert [row["rel_err"] for row in d["rows"]] == pytest.approx([row["rel_err"] for row in table.rows], rel=1e-12)
    assert set(d["outputs"]) == {"csv", "json", "png"} and (tmp_path / "buckling.csv").is_file()


def test_seed_has_no_effect_the_figures_are_bit_identical(table):
    # nothing in the validation is drawn at random (a deterministic first-mode imperfection starts the
    # continuation): any seed gives the same figures, bit for bit (wall times aside)
    other = simfab.validate.buckling(**CASE, seed=12345).to_json()
    base = table.to_json()
    for d in (base, other):
        d["rows"] = [{k: v for k, v in row.items() if k != "seconds"} for row in d["rows"]]
    assert other == base


def test_bad_segment_count_is_bad_input():
    with pytest.raises(InputError, match="--n|even|segment"):
        simfab.validate.buckling(n=[5])
