"""The design area through the public API only: ``simfab.couple.optimize`` / ``simfab.design.run``."""

import csv
import dataclasses
import math

import pytest

import simfab
from simfab.design.optimize import AnnealRow, HistoryRow
from simfab.design.pipeline import DesignFigures
from simfab.errors import InputError
from simfab.results import units

SMALL = dict(steps=6, handles=2, placement="spatial", mesh_check=False)


@pytest.fixture(scope="module")
def gradient(tmp_path_factory):
    out = tmp_path_factory.mktemp("gradient")
    return simfab.couple.optimize("block2d_tight", iterations=2, out=out, **SMALL), out


def test_optimize_returns_a_typed_result(gradient):
    r, _ = gradient
    assert isinstance(r, simfab.design.DesignResult) and r.method == "gradient"
    assert isinstance(r.profile, DesignFigures) and isinstance(r.profile_initial, DesignFigures)
    assert r.profile.category == r.category and r.profile.F_grip_N is not None and r.profile.F_grip_N > 0
    assert units(r)["seconds"] == "s" and units(r)["objective"] == "-"
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.objective = 0.0
    assert r.E_L >= 0 and r.objective <= r.objective_initial  # the optimizer keeps its best design


def test_gradient_history_rows_carry_no_annealing_state(gradient):
    r, out = gradient
    assert r.history and all(type(h) is HistoryRow for h in r.history)  # no temperature / sigma_rel
    assert [h.iteration for h in r.history] == list(range(len(r.history)))
    assert all(math.isfinite(h.current_objective) and math.isfinite(h.best_objective) for h in r.history)
    header = next(csv.reader(open(r.outputs["history_csv"])))
    assert "temperature" not in header and "sigma_rel" not in header
    assert r.outputs["history_csv"].startswith(str(out))


def test_annealing_history_rows_name_the_relative_step(tmp_path):
    r = simfab.design.run("block2d_tight", method="anneal", iterations=2, out=tmp_path, workers=1, **SMALL)
    assert r.method == "anneal" and all(isinstance(h, AnnealRow) for h in r.history)
    assert r.history[0].temperature is None  # the start design: no proposal, no temperature yet
    assert all(h.temperature > 0 for h in r.history[1:])
    assert all(0 < h.sigma_rel <= 1 for h in r.history)  # the step relative to its initial value
    rows = list(csv.DictReader(open(r.outputs["history_csv"])))
    assert [float(x["sigma_rel"]) for x in rows] == pytest.approx([h.sigma_rel for h in r.history], rel=1e-12)


def test_run_without_out_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    r = simfab.design.run("block2d_tight", iterations=1, **SMALL)
    assert r.outputs == {} and not any(tmp_path.iterdir())


def test_to_json_keys_are_the_cli_json_keys(gradient, tmp_path, cli_json):
    r, _ = gradient
    d = cli_json(["couple", "optimize", "block2d_tight", "--iterations", "2", "--steps", "6", "--handles", "2",
                  "--placement", "spatial", "--no-mesh-check", "--out", str(tmp_path)])
    assert list(d) == list(r.to_json())
    assert d["objective"] == pytest.approx(r.objective, rel=1e-12) and d["iterations"] == r.iterations


def test_unknown_override_is_bad_input_naming_it():
    with pytest.raises(InputError, match="iteratoins"):
        simfab.design.run("block2d_tight", iteratoins=3)
