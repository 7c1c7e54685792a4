"""A coupling run's viewer MJCF stays readable by simfab however many records the run has: more than
simfab.io.mjcf.MAX_KEYFRAMES records (a run of more than 10,000 steps) get that many keyframes,
evenly spread, ends and steady state kept (issue 44, class 3)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from simfab.coupling.outputs import key_steps, write_mjcf
from simfab.coupling.profile import analyze_run
from simfab.coupling.scene import load_coupling_scene
from simfab.coupling.simulate import simulate_insertion
from simfab.io.mjcf import MAX_KEYFRAMES, load_model


def test_key_steps():
    assert np.array_equal(key_steps(5, 3), np.arange(5))
    assert np.array_equal(key_steps(MAX_KEYFRAMES, 7), np.arange(MAX_KEYFRAMES))
    for n, keep in ((MAX_KEYFRAMES + 1, 4321), (35_001, 17), (10**6, 10**6 - 2)):
        k = key_steps(n, keep)
        assert len(k) <= MAX_KEYFRAMES and k[0] == 0 and k[-1] == n - 1 and keep in k
        assert np.all(np.diff(k) >= 1) and np.diff(k).max() <= int(np.ceil((n - 1) / (MAX_KEYFRAMES - 2))) + 1


def test_a_run_of_more_records_than_keyframes_writes_an_mjcf_simfab_reads(tmp_path):
    res = simulate_insertion(load_coupling_scene("cclamp2d", overrides={"simulation": {"steps": 3}}), quiet=True)
    n = MAX_KEYFRAMES + 40  # the records of a 10,039-step run (O's poses along the same straight path)
    p0, p1 = np.asarray(res.steps[0].pos, float), np.asarray(res.steps[-1].pos, float)
    steps = [dataclasses.replace(res.steps[min(3 * i // (n - 1), len(res.steps) - 1)], pos=p0 + t * (p1 - p0))
             for i, t in enumerate(np.linspace(0.0, 1.0, n))]
    long = dataclasses.replace(res, steps=steps)
    prof = dataclasses.replace(analyze_run(res), index_ss=n - 2)
    path = write_mjcf(long, prof, tmp_path / "long.xml")
    model = load_model(path)  # refused (InputError) past MAX_KEYFRAMES keys
    assert MAX_KEYFRAMES - 1 <= model.nkey <= MAX_KEYFRAMES  # (the steady state may be a spread index)
    # the keys still scrub the whole path: the last one holds O at its end (slide joint, metres along it)
    assert model.key_qpos[-1][0] == pytest.approx(np.linalg.norm(p1 - p0), rel=1e-6)
