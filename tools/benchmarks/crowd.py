"""Crowd benchmark: time to a converged posterior versus the original's plain Metropolis.

``python tools/bench.py crowd [--ref-iterations N] [--corpus K] [--seed S]``

1. One synthetic practitioner crowd (15 raters x 6 questions, planted truth). Our sampler:
   4 chains of blocked Metropolis-within-Gibbs, run until R-hat < 1.01 and bulk ESS >= 400.
   Reference, in the same run: one chain of plain Metropolis as the original ran it (PyMC2
   style: one random-walk Metropolis step per vector stochastic -- alpha, beta, x -- each
   proposing the whole vector and accepting it jointly, proposal scales tuned every 1000
   iterations during burn-in by PyMC2's acceptance table) for 5e5 iterations, burn-in 1e5,
   thinning 3 (the numbers are read from the reference figures). Both use the identical
   model code. Reported: wall times, the speed-up, RMS of each posterior mean against the
   planted truth, and the RMS between the two posterior means.
2. Accuracy on a corpus of K synthetic practitioner crowds: mean RMS (unit scale) of every
   aggregator, ours, and crowd-kit's DawidSkene and GLAD (ratings as categories;
   crowd-kit is a benchmark-only dependency, imported here only).
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def _reference_metropolis(y01, half_width, *, iterations, burn_in, thin, seed, tune_interval=1000):
    """Single-chain plain Metropolis (PyMC2 semantics), returns x draws (n, Q) and seconds."""
    from simfab.crowd import model as M
    from simfab.crowd.config import Priors

    p = Priors()
    rng = np.random.default_rng(seed)
    R, Q = y01.shape
    obs = M.Observations.make(y01, np.isfinite(y01), half_width)
    state = {"alpha": rng.normal(1, 1, R), "beta": np.abs(rng.normal(1, 1, Q)) + 0.05, "x": rng.uniform(0.05, 0.95, Q)}
    scale = {k: 1.0 for k in state}  # PyMC2: adaptive_scale_factor times the prior sd
    prior_sd = {"alpha": 1.0, "beta": 1.0, "x": 0.25}  # x: sd of its (effectively flat) prior on [0, 1]
    accepted = {k: 0 for k in state}
    logp = M.log_posterior(obs, state["alpha"], state["beta"], state["x"], p)
    out = np.empty(((iterations - burn_in) // thin, Q))
    t0 = time.perf_counter()
    for it in range(iterations):
        for k in ("alpha", "beta", "x"):
            prop = dict(state)
            prop[k] = state[k] + scale[k] * prior_sd[k] * rng.standard_normal(state[k].shape)
            lp = M.log_posterior(obs, prop["alpha"], prop["beta"], prop["x"], p)
            if np.log(rng.random()) < lp - logp:
                state, logp = prop, lp
                accepted[k] += 1
        if it < burn_in and (it + 1) % tune_interval == 0:
            for k in state:  # PyMC2 Metropolis.tune
                r = accepted[k] / tune_interval
                scale[k] *= (0.1 if r < 0.001 else 0.5 if r < 0.05 else 0.9 if r < 0.2
                             else 10.0 if r > 0.95 else 2.0 if r > 0.75 else 1.1 if r > 0.5 else 1.0)
                accepted[k] = 0
        if it >= burn_in and (it - burn_in) % thin == 0 and (it - burn_in) // thin < out.shape[0]:
            out[(it - burn_in) // thin] = state["x"]
    return out, time.perf_counter() - t0


def _crowdkit_rms(crowds):
    import pandas as pd
    from crowdkit.aggregation import GLAD, DawidSkene

    res = {"dawid_skene": [], "glad": []}
    for c in crowds:
        rows = c.ratings.to_long()
        df = pd.DataFrame(rows, columns=["worker", "task", "label"])
        sc = c.ratings.scale
        for name, algo in (("dawid_skene", DawidSkene(n_iter=100)), ("glad", GLAD(n_iter=100, silent=True))):
            pred = algo.fit_predict(df)
            est = np.array([float(pred[t]) for t in c.ratings.tasks])
            res[name].append(float(np.sqrt(np.mean((sc.to_unit(est) - c.x) ** 2))))
    return {k: float(np.mean(v)) for k, v in res.items()}


def run(argv):
    from benchmarks._reference import required
    from simfab.crowd import analysis, metrics, synth
    from simfab.crowd.config import PRACTITIONERS, SamplerConfig
    from simfab.crowd.data import Scale
    from simfab.crowd.sampler import sample

    ref = required("crowd_original")
    mc = ref["mcmc"]  # the original's chain: iterations, burn-in, thinning
    ap = argparse.ArgumentParser(prog="bench crowd")
    ap.add_argument("--ref-iterations", type=int, default=mc["iterations"])
    ap.add_argument("--corpus", type=int, default=30, help="synthetic crowds for the accuracy table")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    burn = int(round(a.ref_iterations * mc["burn_in"] / mc["iterations"]))

    scale = Scale(lo=1, hi=10)
    crowd = synth.simulate_crowd(PRACTITIONERS, scale=scale, n_tasks=6, seed=a.seed)
    y01, hw = crowd.ratings.unit, 0.5 / scale.span

    cfg = SamplerConfig()  # 4 chains, R-hat < 1.01, ESS >= 400
    sample(y01, config=SamplerConfig(burn_in=50, draws=50, max_draws=50), half_width=hw)  # warm caches
    ours = sample(y01, config=cfg, seed=a.seed, half_width=hw)
    ours_x = ours.mean("x")[0]

    ref_draws, ref_seconds = _reference_metropolis(y01, hw, iterations=a.ref_iterations, burn_in=burn, thin=mc["thin"],
                                                   seed=a.seed)
    ref_x = ref_draws.mean(axis=0)

    speed = {
        "crowd": "15 practitioners x 6 questions, planted truth",
        "ours_seconds": ours.seconds,
        "ours_chains": cfg.chains,
        "ours_iterations_per_chain": ours.iterations,
        "ours_rhat_max": float(ours.rhat_max[0]),
        "ours_ess_min": float(ours.ess_min[0]),
        "ours_converged": bool(ours.converged[0]),
        "reference_seconds": ref_seconds,
        "reference_iterations": a.ref_iterations,
        "reference_burn_in": burn,
        "reference_thin": mc["thin"],
        "speedup": ref_seconds / ours.seconds,
        "speedup_target": 50.0,
        "ours_rms_vs_truth": metrics.rms(ours_x, crowd.x),
        "reference_rms_vs_truth": metrics.rms(ref_x, crowd.x),
        "rms_between_posterior_means": metrics.rms(ours_x, ref_x),
        # Monte Carlo standard error of our posterior means (sd / sqrt(ESS)), RMS over questions:
        # differences from the reference below a few of these are sampling noise, not accuracy
        "ours_mc_se_rms": float(np.sqrt(np.mean(ours.x[0].var(axis=(0, 1)) / ours.ess[0, : ours_x.size]))),
    }

    corpus = [synth.simulate_crowd(PRACTITIONERS, scale=scale, n_tasks=6, seed=1000 + k) for k in range(a.corpus)]
    Y = np.stack([c.ratings.unit for c in corpus])
    t0 = time.perf_counter()
    post = sample(Y, config=cfg, seed=a.seed, half_width=hw)  # all 30 run until the worst converges
    batch_seconds = time.perf_counter() - t0
    acc = {m: [] for m in analysis.METHODS}
    for k, c in enumerate(corpus):
        est = analysis.classical(c.ratings)
        est["bayesian"] = scale.from_unit(post.mean("x")[k])
        for m, e in est.items():
            acc[m].append(metrics.rms(scale.to_unit(e), c.x))
    table = {m: float(np.mean(v)) for m, v in acc.items()}
    try:
        table.update(_crowdkit_rms(corpus))
    except ImportError:
        table["crowdkit"] = "not installed (pip install crowd-kit)"
    row = ref.get("rows", {}).get("3D printing-1, practitioner")
    cols = ref.get("columns", [])
    original = dict(zip(cols, row)) if row else {}
    return {
        "speed": speed,
        "accuracy": {
            "corpus": f"{a.corpus} synthetic practitioner crowds, 15 x 6, scale 1-10, RMS on [0, 1] vs planted truth",
            "mean_rms": table,
            "bayesian_batch_seconds": batch_seconds,
            "bayesian_converged_fraction": float(post.converged.mean()),
            "bayesian_rhat_max": float(post.rhat_max.max()),
            "reference_original_3dp1_practitioner": original,
            "bayes_over_mean_ours": table["bayesian"] / table["arithmetic_mean"],
            "bayes_over_mean_original": (original["bayesian"] / original["arithmetic mean"]) if original else None,
        },
    }
