"""The crowd area through the public API only: ``simfab.crowd.synthesize`` / ``aggregate`` (``run``) / ``study``."""

import dataclasses

import numpy as np
import pytest

import simfab
from simfab.crowd.config import SamplerConfig
from simfab.errors import InputError

QUICK = SamplerConfig(burn_in=400, draws=800, max_draws=800)


@pytest.fixture(scope="module")
def crowd(tmp_path_factory):
    out = tmp_path_factory.mktemp("crowd")
    s = simfab.crowd.synthesize(scale=(1, 10), tasks=4, practitioners=8, seed=3, out=out)
    return s, out


def test_synthesize_is_typed_and_seeded(crowd):
    s, out = crowd
    assert isinstance(s, simfab.crowd.SynthResult) and (s.raters, len(s.tasks)) == (8, 4)
    again = simfab.crowd.synthesize(scale=(1, 10), tasks=4, practitioners=8, seed=3)
    np.testing.assert_array_equal(again.crowd.ratings.labels, s.crowd.ratings.labels)  # same seed, same crowd
    assert again.outputs == {} and set(s.outputs) == {"ratings_csv", "truth_csv", "planted_json"}


def test_aggregate_scores_every_method_against_truth(crowd, tmp_path, cli_json):
    s, out = crowd
    r = simfab.crowd.run(out / "ratings.csv", scale=(1, 10), truth=out / "truth.csv", config=QUICK, seed=0)
    assert isinstance(r, simfab.crowd.AggregateResult) and r.outputs == {}
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.workers = 0
    assert set(r.methods) == {"arithmetic_mean", "geometric_mean", "median", "majority", "bayesian"}
    for m in r.methods.values():
        est = np.array(list(m["estimates"].values()))
        assert np.all((est >= 1) & (est <= 10))  # on the survey scale
        assert 0 <= m["rms_continuous"] <= 1  # RMS on the unit scale
    assert set(r.individual_errors) == set(s.crowd.ratings.workers) and r.workers == 8
    d = cli_json(["crowd", "aggregate", str(out / "ratings.csv"), "--scale", "1", "10", "--truth",
                  str(out / "truth.csv"), "--burn-in", "400", "--draws", "800", "--max-draws", "800",
                  "--out", str(tmp_path)])
    assert list(d) == list(r.to_json())
    assert d["methods"]["bayesian"]["rms_continuous"] == pytest.approx(r.methods["bayesian"]["rms_continuous"],
                                                                       rel=1e-12)  # seeded: the same estimate


def test_study_is_typed(crowd):
    _, out = crowd
    r = simfab.crowd.study(out / "ratings.csv", scale=(1, 10), truth=out / "truth.csv", subcrowds=3, min_size=6,
                           scheduler="serial", config=dataclasses.replace(QUICK, max_draws=800), seed=0)
    assert isinstance(r, simfab.crowd.StudyResult) and [row["size"] for row in r.sizes] == [6, 7]
    assert all(0 <= row["percentile_mean"] <= 100 for row in r.sizes) and r.seconds > 0
    assert list(r.to_json()) == ["sizes", "seconds", "outputs"]


def test_run_needs_the_scale():
    with pytest.raises(InputError, match="scale"):
        simfab.crowd.run("ratings.csv")
