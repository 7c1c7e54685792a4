"""The design area through the public API only: ``simfab.couple.optimize`` / ``simfab.design.run``."""

import csv
import dataclasses
import math

import pytest

import simfab
from simfab.design.brief import ConstraintReport
from simfab.design.gradient import NonsmoothEvents
from simfab.design.optimize import AnnealRow, HistoryRow
from simfab.design.pipeline import AcceptanceBranches, CorrectionRound, DesignFigures, DesignUnits, HandleCounts
from simfab.design.verify import CheckLevel, FigureCheck, MeshCheck
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


def test_nested_entries_are_typed_and_their_json_keeps_the_keys(gradient):
    r, _ = gradient
    assert isinstance(r.handles, HandleCounts) and r.handles.active == 2
    assert isinstance(r.acceptance_branches, AcceptanceBranches) and isinstance(r.units, DesignUnits)
    assert isinstance(r.nonsmooth_events, NonsmoothEvents) and r.nonsmooth_events.pairs >= 0
    c = r.constraints["grip_force"]
    assert isinstance(c, ConstraintReport) and c.name is None and c.unit == "N" and c.initial is not None
    assert c.satisfied == (c.lo <= c.value <= c.hi)
    d = r.to_json()
    assert list(d["constraints"]["grip_force"]) == ["value", "lo", "hi", "unit", "satisfied", "initial"]
    assert list(d["handles"]) == ["active", "inactive", "placement"]
    assert "rms_error" not in d and "rms_error" not in d["units"]  # no target profile: left out, not null
    assert r.mesh_check is None and "mesh_check" not in d  # (mesh_check=False)


def test_mesh_check_is_typed():
    r = simfab.design.run("block2d_tight", iterations=1, steps=6, handles=2, placement="spatial",
                          check_refinements=0, correction_rounds=0)
    mc = r.mesh_check
    assert isinstance(mc, MeshCheck) and all(isinstance(lv, CheckLevel) for lv in mc.levels)
    assert [(lv.element_order, lv.subdivisions) for lv in mc.levels] == [(1, 0), (2, 0)]
    assert all(isinstance(f, FigureCheck) and len(f.values) == 2 for f in mc.figures.values())
    assert mc.feasible_fine == all(c.satisfied for c in mc.constraints)
    assert r.correction_rounds == () and all(isinstance(x, CorrectionRound) for x in r.correction_rounds)
    d = r.to_json()["mesh_check"]
    assert list(d)[-6:] == ["levels", "figures", "constraints", "feasible_fine", "reference", "units"]
    assert list(d["constraints"][0]) == ["name", "value", "lo", "hi", "satisfied"]  # (units: the check's table)
    assert ("step_check" in d) == (mc.step_check is not None)


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
