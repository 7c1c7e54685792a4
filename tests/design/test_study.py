"""Handle-placement study and optimization restarts (both run their optimizations as tasks)."""

import json

import numpy as np


def test_handle_study_reports_every_method_and_count(tmp_path):
    from simfab.design.study import handle_study

    r = handle_study("block2d_tight", out=tmp_path, counts=[1, 2], randoms=2, design={"iterations": 2},
                     simulation={"steps": 6}, seed=0, scheduler="serial")
    rows = {(x["method"], x["handles"]): x for x in r["rows"]}
    assert set(rows) == {(m, k) for m in ("displacement", "spatial", "random") for k in (1, 2)}
    assert rows[("random", 2)]["runs"] == 2 and rows[("spatial", 1)]["runs"] == 1
    assert r["runs"] == 8 and r["failed_runs"] == 0
    for row in r["rows"]:
        assert 0.0 <= row["converged_fraction"] <= 1.0
    for p in r["outputs"].values():
        assert (tmp_path / p.split("/")[-1]).is_file()
    runs = (tmp_path / "block2d_tight_handle_study.csv").read_text().splitlines()
    assert len(runs) == 9  # header + 8 runs


def test_restarts_keep_the_best_run(tmp_path):
    from simfab.design import run as optimize_design

    s = optimize_design("block2d_tight", out=tmp_path, design={"iterations": 3, "handles": 2, "placement": "spatial"},
                        simulation={"steps": 6}, seed=0, restarts=2, scheduler="serial").to_json()
    assert [r["seed"] for r in s["restarts"]] == [0, 1]
    best = min(s["restarts"], key=lambda r: (not r["feasible"], r["objective"]))
    assert np.isclose(s["objective"], best["objective"], rtol=1e-12)  # re-evaluated in the client: identical
    saved = json.loads((tmp_path / "block2d_tight_design_summary.json").read_text())
    assert saved["objective"] == s["objective"] and saved["restarts"] == json.loads(json.dumps(s["restarts"]))
