"""The micro-crowd study on Dask gives exactly the result of the plain serial loop it replaced."""

import dataclasses

import numpy as np

from simfab.crowd import metrics, synth
from simfab.crowd.analysis import half_width
from simfab.crowd.config import PRACTITIONERS, STUDY_SAMPLER
from simfab.crowd.data import Scale
from simfab.crowd.microcrowd import micro_crowd_study, subcrowds
from simfab.crowd.sampler import sample


def _serial_reference(ratings, truth, *, n_sub, min_size, config, seed):
    """The study run serially in this process: sizes in order, one generator for sub-crowds and seeds."""
    rng = np.random.default_rng(seed)
    sc, N = ratings.scale, len(ratings.workers)
    indiv = metrics.individual_errors(ratings.labels, truth, sc)
    rows = []
    for k in range(min_size, N):
        idx = subcrowds(N, k, n_sub, rng)
        post = sample(ratings.unit[idx], config=config, seed=int(rng.integers(2**31 - 1)),
                      half_width=half_width(ratings, config), keep_latent=False)
        bias = np.sqrt(np.mean((post.mean("x") - sc.to_unit(truth)[None]) ** 2, axis=1))
        pct = np.array([metrics.percentile_rank(b, indiv[m]) for b, m in zip(bias, idx)])
        rows.append([k, len(idx), pct.mean(), pct.std(ddof=1), bias.mean(), bias.std(ddof=1),
                     np.mean(post.rhat_max > config.rhat_target), np.median(post.rhat_max)])
    return np.array(rows)


def test_study_on_local_cluster_identical_to_serial_loop():
    crowd = synth.simulate_crowd(dataclasses.replace(PRACTITIONERS, size=9), scale=Scale(lo=1, hi=10), n_tasks=5,
                                 seed=3)
    truth = crowd.ratings.scale.from_unit(crowd.x)
    cfg = dataclasses.replace(STUDY_SAMPLER, burn_in=60, draws=60, max_draws=60)
    kw = dict(n_sub=5, min_size=5, config=cfg, seed=11)
    ref = _serial_reference(crowd.ratings, truth, **kw)
    res = micro_crowd_study(crowd.ratings, truth, **kw, scheduler=None)  # a LocalCluster
    got = np.array([list(r.values()) for r in res.rows()])
    assert got.shape == ref.shape == (4, 8)
    np.testing.assert_array_equal(got, ref)  # bit for bit: same sub-crowds, seeds and arithmetic
