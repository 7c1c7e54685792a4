"""Simulated annealing (simfab.design.anneal) on analytic functions with known minima."""

import numpy as np
import pytest

from simfab.design.anneal import AnnealConfig, anneal


def double_well(x, threshold=None):
    """Tilted double well in each coordinate: minima near x_i = +0.96 (local, f = 5.56 at (1, 1))
    and x_i = -1.0356 (global, f = 4.389); barrier ~1 between them."""
    return float(np.sum((x * x - 1) ** 2 + 0.3 * x) + 5), None


def test_escapes_local_minimum_to_global_minimum():
    x_star = np.full(2, -1.03557789)  # d/dx [(x^2-1)^2 + 0.3 x] = 4x^3 - 4x + 0.3 = 0
    found = 0
    for seed in range(10):
        r = anneal(double_well, np.array([1.0, 1.0]), AnnealConfig(
            iterations=600, sigma0=np.ones(2), lower=np.full(2, -3.0), upper=np.full(2, 3.0), tau0=0.5, seed=seed))
        found += bool(np.allclose(r.x, x_star, atol=0.05)) and abs(r.value - double_well(x_star)[0]) < 1e-2
    # started in the local minimum (a descent method would stay there)
    assert found >= 9


def test_rosenbrock_valley_and_reproducibility():
    def f(x, threshold=None):
        return float((1 - x[0]) ** 2 + 100 * (x[1] - x[0] ** 2) ** 2), None

    opts = AnnealConfig(iterations=4000, sigma0=np.full(2, 0.3), lower=np.full(2, -2.0), upper=np.full(2, 2.0), seed=7)
    a = anneal(f, np.array([-1.5, 2.0]), opts)
    b = anneal(f, np.array([-1.5, 2.0]), opts)
    assert np.allclose(a.x, [1.0, 1.0], atol=0.05)
    assert np.array_equal(a.x, b.x) and a.value == b.value  # same seed, same result


def test_rejected_candidates_are_never_accepted_and_stop_is_honoured():
    calls = []

    def f(x, threshold=None):
        calls.append(x.copy())
        return (np.inf if x[0] > 0 else float(x @ x)), None

    r = anneal(f, np.array([-1.0]), AnnealConfig(iterations=200, sigma0=np.ones(1), lower=-np.full(1, 3.0),
                                                  upper=np.full(1, 3.0), seed=0),
               stop=lambda info, value, k, kb: k >= 50)
    assert r.iterations == 50 and r.stopped_early
    assert all(not rec["accepted"] for rec in r.history[1:] if not np.isfinite(rec["value"]))
    assert r.x[0] <= 0


def test_threshold_is_the_metropolis_test():
    """f sees the acceptance threshold E_cur - T ln u: a value above it is never accepted, one
    below it always (so stopping a computation once a lower bound exceeds it changes nothing)."""
    seen = []

    def f(x, threshold):
        v = float(np.sum(x * x))
        seen.append((v, threshold))
        return v, None

    r = anneal(f, np.array([2.0, 2.0]), AnnealConfig(iterations=300, sigma0=np.full(2, 0.5), lower=np.full(2, -5.0),
                                                      upper=np.full(2, 5.0), seed=3))
    for (v, thr), rec in zip(seen[1:], r.history[1:]):
        assert rec["accepted"] == (v < thr)


class _Done:
    def __init__(self, v):
        self.v = v

    def result(self):
        return self.v

    def done(self):
        return True


class _Speculative:
    """A synchronous speculative evaluator: half the proposals are 'cheap' (screened), the others
    'submitted' (evaluated at once here; the annealer cannot tell)."""

    def __init__(self, f, slots):
        self.f, self.slots, self.submitted, self.screened = f, slots, 0, 0

    def screen(self, x, threshold):
        v = self.f(x, threshold)
        if v[0] > threshold + 1.0:  # clearly rejected: decided by the screen
            self.screened += 1
            return v
        return None

    def submit(self, x, threshold):
        self.submitted += 1
        return _Done(self.f(x, threshold))


@pytest.mark.parametrize("slots", [1, 2, 4])
def test_speculative_evaluation_makes_exactly_the_serial_decisions(slots):
    # proposals drawn ahead of the decisions (each assuming the ones before are rejected), screened
    # or submitted, and rewound at the first acceptance must reproduce the serial chain bit for bit
    def f(x, threshold):
        return float((x[0] - 1) ** 2 + 10 * (x[1] + x[0] ** 2) ** 2), {"x": x.copy()}

    opts = AnnealConfig(iterations=150, sigma0=np.array([0.4, 0.4, 0.2]), lower=np.full(3, -3.0),
                         upper=np.full(3, 3.0), blocks=np.array([0, 0, 1]), seed=3)
    serial = anneal(f, np.array([-1.5, 2.0, 0.0]), opts)
    ev = _Speculative(f, slots)
    spec = anneal(f, np.array([-1.5, 2.0, 0.0]), opts, evaluator=ev)
    assert [r["value"] for r in spec.history] == [r["value"] for r in serial.history]
    assert [r["accepted"] for r in spec.history] == [r["accepted"] for r in serial.history]
    assert np.array_equal(spec.x, serial.x) and spec.iterations == serial.iterations == 150
    assert ev.screened > 0 and ev.submitted > 0
    assert ev.screened + ev.submitted == 150 + len(spec.discarded)  # every proposal decided or discarded
    n_acc = sum(r["accepted"] for r in serial.history[1:])
    assert len(spec.discarded) <= n_acc * 8 * slots
    if slots > 1:
        assert len(spec.discarded) > 0  # it did draw ahead


class _Branching(_Speculative):
    """A speculative evaluator that also serves the acceptance branch: ``f`` returns a lower bound
    (halfway between the threshold and the value) once the value exceeds its threshold, as the
    design objective stops early; ``restrict`` reads a looser-threshold result as ``f`` would."""

    def __init__(self, f, slots):
        super().__init__(f, slots)
        self.restricted = 0

    def restrict(self, out, threshold):
        self.restricted += 1
        return self.f(out[1]["x"], threshold)


@pytest.mark.parametrize("slots,iterations", [(2, 200), (3, 200), (2, 3)])
def test_acceptance_branch_makes_exactly_the_serial_decisions(slots, iterations):
    # with a hot schedule most proposals are accepted, so free slots evaluate the proposal after
    # the running one as if it were accepted, with an upper bound of its unknown threshold; the
    # record, value by value (including early-stop lower bounds), must be the serial one
    def f(x, threshold):
        v = float((x[0] - 1) ** 2 + 10 * (x[1] + x[0] ** 2) ** 2 + x[2] ** 2)
        if v > threshold:  # stops early: a lower bound above the threshold
            v = threshold + 0.5 * (v - threshold)
        return v, {"x": x.copy()}

    opts = AnnealConfig(iterations=iterations, sigma0=np.array([0.2, 0.2, 0.1]), lower=np.full(3, -3.0),
                         upper=np.full(3, 3.0), seed=5, tau0=2.0, tau_end=0.5)
    serial = anneal(f, np.array([-1.5, 2.0, 0.5]), opts)
    ev = _Branching(f, slots)
    spec = anneal(f, np.array([-1.5, 2.0, 0.5]), opts, evaluator=ev)
    assert spec.iterations == serial.iterations == iterations  # (also when the last iteration is reached)
    if iterations < 10:
        assert [r["value"] for r in spec.history] == [r["value"] for r in serial.history]
        return
    assert sum(r["accepted"] for r in serial.history[1:]) > 100  # the branch is the likelier outcome
    assert [r["value"] for r in spec.history] == [r["value"] for r in serial.history]
    assert [r["accepted"] for r in spec.history] == [r["accepted"] for r in serial.history]
    assert [r["temperature"] for r in spec.history[1:]] == [r["temperature"] for r in serial.history[1:]]
    assert np.array_equal(spec.x, serial.x)
    assert ev.restricted > 20  # branch evaluations were adopted and read at their exact thresholds


class _Threaded(_Branching):
    """The same evaluator with submitted evaluations running on threads that take a few ms and
    finish out of order, so the annealer waits, polls and cancels as with worker processes."""

    def __init__(self, f, slots, pool):
        import threading

        super().__init__(f, slots)
        self.pool, self.cancelled = pool, 0
        self.lock, self.running, self.most = threading.Lock(), 0, 0

    def submit(self, x, threshold):
        import time

        self.submitted += 1
        state = {"needed": True}
        with self.lock:  # evaluations still needed and running, at most `slots` of them
            self.running += 1
            self.most = max(self.most, self.running)
        delay = 0.001 * (1 + int(abs(x[0]) * 1e3) % 5)

        def work():
            time.sleep(delay)
            out = self.f(x, threshold)
            with self.lock:
                if state["needed"]:
                    self.running -= 1
                state["needed"] = False
            return out

        fut = self.pool.submit(work)
        outer = self

        class Handle:
            def done(self):
                return fut.done()

            def result(self):
                return fut.result()

            def cancel(self):
                outer.cancelled += 1
                with outer.lock:
                    if state["needed"]:
                        outer.running -= 1
                    state["needed"] = False

        return Handle()


def test_asynchronous_evaluations_make_exactly_the_serial_decisions():
    # real concurrency: the head may still run while later ones finish; the loop must wait for it
    # (polling), keep at most `slots` evaluations running, and decide exactly as the serial loop
    from concurrent.futures import ThreadPoolExecutor

    def f(x, threshold):
        v = float((x[0] - 1) ** 2 + 10 * (x[1] + x[0] ** 2) ** 2 + x[2] ** 2)
        return (threshold + 0.5 * (v - threshold) if v > threshold else v), {"x": x.copy()}

    opts = AnnealConfig(iterations=120, sigma0=np.array([0.2, 0.2, 0.1]), lower=np.full(3, -3.0),
                         upper=np.full(3, 3.0), seed=7, tau0=2.0, tau_end=0.5)
    serial = anneal(f, np.array([-1.5, 2.0, 0.5]), opts)
    with ThreadPoolExecutor(max_workers=8) as pool:  # more threads than slots: the annealer must hold back
        ev = _Threaded(f, 2, pool)
        spec = anneal(f, np.array([-1.5, 2.0, 0.5]), opts, evaluator=ev)
    assert [r["value"] for r in spec.history] == [r["value"] for r in serial.history]
    assert [r["accepted"] for r in spec.history] == [r["accepted"] for r in serial.history]
    assert np.array_equal(spec.x, serial.x) and spec.iterations == serial.iterations
    assert ev.restricted > 0 and ev.cancelled > 0
    assert ev.most <= 2  # never more needed evaluations running than slots
