"""The momentary speed of a shared machine, for benchmarks whose wall time moves with it."""

from __future__ import annotations

import time


def machine_reference_ms() -> float:
    """Milliseconds of a fixed CPU workload (a pure-Python loop and small dense products), timed
    beside a benchmark's runs: the same simulation's wall time on a shared machine moves with the
    machine's momentary speed, and this figure moves with it (best of 3).
    ~25 ms on this 2-core virtual machine in its usual phases; 15-56 ms over one hour of 2 December
    (and once 276 ms)."""
    import numpy as np

    a = np.random.default_rng(0).standard_normal((200, 200))
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        s = 0.0
        for i in range(200_000):
            s += i * 0.5
        for _ in range(20):
            a = np.tanh(a @ a * 1e-3)
        best = min(best, time.perf_counter() - t0)
    return round(best * 1e3, 2)
