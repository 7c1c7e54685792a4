"""simfab crowd CLI: end to end on small inputs, and bad input -> exit 2, one line, no outputs."""

import json
import os

import pytest
import trimesh

from simfab.cli import main


def _write(path, text):
    path.write_text(text)
    return str(path)


@pytest.fixture(scope="module")
def crowd_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("crowd")
    assert main(["crowd", "simulate", "--tasks", "4", "--scale", "1", "10", "--practitioners", "8", "--out", str(d),
                 "--seed", "3", "--quiet"]) == 0
    return d / "ratings.csv", d / "truth.csv"


def test_simulate_writes_long_form_ratings(crowd_files):
    ratings, truth = crowd_files
    lines = ratings.read_text().splitlines()
    assert lines[0] == "worker,task,label" and len(lines) == 1 + 8 * 4
    assert truth.read_text().splitlines()[0] == "task,truth"


def test_aggregate_json_keys(crowd_files, tmp_path, capsys):
    ratings, truth = crowd_files
    out = tmp_path / "agg"
    args = ["crowd", "aggregate", str(ratings), "--scale", "1", "10", "--truth", str(truth), "--out", str(out),
            "--json", "--burn-in", "400", "--draws", "800", "--max-draws", "800"]
    assert main(args) == 0
    d = json.loads(capsys.readouterr().out)
    assert set(d["methods"]) == {"arithmetic_mean", "geometric_mean", "median", "majority", "bayesian"}
    for m in d["methods"].values():
        assert set(m["estimates"]) == {"q1", "q2", "q3", "q4"}
        assert all(1 <= v <= 10 for v in m["estimates"].values())
        assert 0 <= m["rms"] <= 1 and 0 <= m["rms_discrete"] <= 1 and 0 <= m["percentile"] <= 100
    assert {"rhat_max", "ess_min", "seconds"} <= set(d["bayes"])
    for k in ("aggregates_csv", "raters_csv", "expert_network_png", "errors_png", "summary_json"):
        assert os.path.isfile(d["outputs"][k])
    # the arithmetic mean in the table is the plain mean of the file's labels
    import pandas as pd

    df = pd.read_csv(ratings)
    mean_q1 = df[df.task == "q1"].label.mean()
    assert d["methods"]["arithmetic_mean"]["estimates"]["q1"] == pytest.approx(mean_q1)


def test_aggregate_without_truth_gives_null_errors(crowd_files, tmp_path, capsys):
    ratings, _ = crowd_files
    assert main(["crowd", "aggregate", str(ratings), "--scale", "1", "10", "--out", str(tmp_path / "a"), "--json",
                 "--draws", "300", "--max-draws", "300"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["methods"]["median"]["rms"] is None and d["methods"]["bayesian"]["percentile"] is None


def test_study_small(crowd_files, tmp_path, capsys):
    ratings, truth = crowd_files
    out = tmp_path / "study"
    assert main(["crowd", "study", str(ratings), "--scale", "1", "10", "--truth", str(truth), "--subcrowds", "4",
                 "--min-size", "6", "--burn-in", "100", "--draws", "100", "--out", str(out), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert [r["size"] for r in d["sizes"]] == [6, 7]
    assert [r["subcrowds"] for r in d["sizes"]] == [4, 4]  # C(8,6)=28 > 4 random; C(8,7)=8 > 4
    assert all(0 <= r["percentile_mean"] <= 100 for r in d["sizes"])
    assert os.path.isfile(d["outputs"]["study_png"])


def test_truth_on_a_mesh_file(tmp_path, capsys):
    box = trimesh.creation.box((20.0, 20.0, 20.0))  # mm
    path = tmp_path / "cube.stl"
    box.export(path)
    out = tmp_path / "truth"
    assert main(["crowd", "truth", str(path), "--units", "mm", "--orientations", "flat=0:0:0", "edge=45:0:0",
                 "--out", str(out), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    rows = {r["orientation"]: r for r in d["orientations"]}
    # 20 mm cube on an edge: V = L a^2 / 2 = 0.02^3 / 2 m^3
    assert rows["edge"]["support_volume"] == pytest.approx(0.02**3 / 2, rel=1e-9)
    assert abs(rows["edge"]["raycast_rel_diff"]) < 0.01
    assert rows["flat"]["support_volume"] == 0.0
    assert (out / "truth_support.csv").read_text().splitlines()[1:] == ["flat,1.0", "edge,10.0"]


BAD_RATINGS = {
    "missing_column": ("worker,task\na,q1\n", "missing column 'label'"),
    "non_numeric": ("worker,task,label\na,q1,5\nb,q1,high\n", "line 3, column 'label': 'high' is not a finite number"),
    "off_scale": ("worker,task,label\na,q1,5\nb,q1,11\n",
                  "line 3, column 'label': 11 is not an integer on the scale [1, 10]"),
    "non_integer": ("worker,task,label\na,q1,5.5\n", "line 2, column 'label': 5.5 is not an integer"),
    "duplicate": ("worker,task,label\na,q1,5\nb,q1,4\na,q1,6\n",
                  "line 4: duplicate rating of task 'q1' by worker 'a' (first at line 2)"),
    "empty_crowd": ("worker,task,label\n", "no ratings (empty crowd)"),
    "empty_file": ("", "empty file"),
    "empty_worker": ("worker,task,label\n,q1,5\n", "line 2, column 'worker': empty"),
}


@pytest.mark.parametrize("case", sorted(BAD_RATINGS))
def test_bad_ratings_exit_2_with_clear_message(case, tmp_path, capsys):
    text, msg = BAD_RATINGS[case]
    path = _write(tmp_path / "r.csv", text)
    out = tmp_path / "out"
    assert main(["crowd", "aggregate", path, "--scale", "1", "10", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and path in err and msg in err, err
    assert not out.exists()  # no partial outputs


@pytest.mark.parametrize(
    "truth,msg",
    [
        ("task,truth\nq1,5\n", "no truth for rated task 'q2'"),
        ("task,truth\nq1,5\nq2,3\nq9,4\n", "task 'q9' has a truth but no ratings"),
        ("task,truth\nq1,5\nq2,30\n", "30 is outside the scale"),
        ("task,value\nq1,5\n", "missing column 'truth'"),
    ],
)
def test_bad_truth_exit_2(truth, msg, tmp_path, capsys):
    r = _write(tmp_path / "r.csv", "worker,task,label\na,q1,5\na,q2,4\nb,q1,6\nb,q2,4\n")
    t = _write(tmp_path / "t.csv", truth)
    assert main(["crowd", "aggregate", r, "--scale", "1", "10", "--truth", t, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert msg in err and t in err, err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "argv,msg",
    [
        (["crowd", "aggregate", "nope.csv", "--scale", "1", "10"], "nope.csv: file not found"),
        (["crowd", "aggregate", "nope.csv", "--scale", "10", "1"], "--scale: scale must have lo < hi"),
        (["crowd", "aggregate", "nope.csv", "--scale", "1", "9.5"], "--scale: scale hi=9.5 must be a finite integer"),
        (["crowd", "aggregate", "nope.csv", "--scale", "1", "10", "--chains", "1"], "--chains: must be >= 2"),
        (["crowd", "truth", "nope.stl"], "nope.stl"),
        (["crowd", "truth", "nope.stl", "--orientations", "tilted"], "--orientations"),
        (["crowd", "simulate", "--tasks", "3", "--scale", "1", "5", "--malicious", "2"],
         "--malicious: must be within [0, 1]"),
        (["crowd"], "choose an action"),
    ],
)
def test_bad_arguments_exit_2(argv, msg, capsys, tmp_path):
    assert main(argv + ["--out", str(tmp_path / "o")]) == 2
    assert msg in capsys.readouterr().err


def test_study_needs_enough_raters(tmp_path, capsys):
    r = _write(tmp_path / "r.csv", "worker,task,label\n" + "".join(f"w{i},q1,{1 + i}\n" for i in range(5)))
    t = _write(tmp_path / "t.csv", "task,truth\nq1,3\n")
    assert main(["crowd", "study", r, "--scale", "1", "10", "--truth", t, "--out", str(tmp_path / "o")]) == 2
    assert "a crowd of 5 raters has no sub-crowds of sizes 5..4" in capsys.readouterr().err


def test_density_likelihood_on_tied_integer_answers_warns_chains_disagree(tmp_path, capsys):
    """The thesis' density at integer answers is unbounded where raters agree exactly
    (delta -> 0): the posterior splits into spikes and the chains disagree. The sampler must
    say so (the default rounded likelihood exists for this reason)."""
    labels = [[2, 7, 5], [2, 7, 5], [2, 8, 4], [3, 7, 5], [2, 6, 5], [4, 7, 6]]
    rows = "".join(f"w{i},q{j},{v}\n" for i, r in enumerate(labels) for j, v in enumerate(r))
    path = _write(tmp_path / "r.csv", "worker,task,label\n" + rows)
    args = ["crowd", "aggregate", path, "--scale", "1", "10", "--out", str(tmp_path / "o"), "--json",
            "--burn-in", "300", "--draws", "600", "--max-draws", "600"]
    assert main(args + ["--likelihood", "density"]) == 0
    cap = capsys.readouterr()
    d = json.loads(cap.out)
    assert d["bayes"]["rhat_max"] > 1.1 and d["warnings"] and "chains disagree" in cap.err
    assert main(args + ["--max-draws", "4000"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["bayes"]["rhat_max"] < 1.05
