"""How many runs the insertion and peer benchmarks take per case (their timings are not asserted)."""

import importlib
import pathlib
import sys
from types import SimpleNamespace

import numpy as np
import pytest

TOOLS = pathlib.Path(__file__).resolve().parents[2] / "tools"


@pytest.fixture(scope="module")
def rule():
    """The rule of a bench's parsed --repeat / --budget / --max-repeat and its least count of runs."""
    sys.path.insert(0, str(TOOLS))
    try:
        repeat = importlib.import_module("benchmarks._repeat")
    finally:
        sys.path.remove(str(TOOLS))

    def make(repeat_=None, budget=10.0, max_repeat=15, min_runs=2, first_outside_budget=False):
        a = SimpleNamespace(repeat=repeat_, budget=budget, max_repeat=max_repeat)
        return repeat.repeat_rule(a, min_runs=min_runs, first_outside_budget=first_outside_budget)

    return make


def test_fixed_repeat_takes_exactly_that_many_runs(rule):
    assert rule(3).wanted([0.1]) == 3
    assert rule(3).wanted([0.1] * 3) == 3  # done
    assert rule(1).wanted([]) == 1


def test_budget_keeps_running_until_spent_within_the_bounds(rule):
    r = rule()
    assert r.wanted([]) == 2 and r.wanted([30.0]) == 2  # at least two, however slow
    assert r.wanted([30.0] * 2) == 2  # over budget after two: done
    assert r.wanted([1.0] * 9) == 10  # budget left: one more
    assert r.wanted([1.0] * 10) == 10  # budget spent: done
    assert r.wanted([0.1] * 15) == 15  # capped
    # the peer's rule (at least one pair): a case of minutes runs once, a sub-second one to the cap
    p = rule(min_runs=1)
    assert p.wanted([]) == 1 and p.wanted([120.0]) == 1
    assert p.wanted([0.35] * 14) == 15 and p.wanted([0.35] * 15) == 15
    assert rule(max_repeat=1).wanted([0.1]) == 1  # the cap wins over the least count
    # the insertion bench's: a first run that compiled the kernels (15 s) does not spend the budget
    w = rule(first_outside_budget=True)
    assert w.wanted([15.0, 0.25]) == 3 and w.wanted([15.0] + [0.25] * 14) == 15
    assert w.wanted([15.0, 6.0, 5.0]) == 3


def test_bad_repeat_options_are_refused(rule):
    from simfab.errors import InputError

    for kw in ({"repeat_": 0}, {"budget": 0.0}, {"budget": float("nan")}, {"max_repeat": 0}):
        with pytest.raises(InputError, match="--repeat|--budget"):
            rule(**kw)


def test_scaling_repeats_levels_in_alternating_order_and_keeps_each_fastest(monkeypatch):
    sys.path.insert(0, str(TOOLS))
    try:
        scaling = importlib.import_module("benchmarks._scaling")
    finally:
        sys.path.remove(str(TOOLS))
    calls, wall = [], {(1.0, 0): 2.0, (2.0, 0): 4.5, (1.0, 1): 1.8, (2.0, 1): 4.0}  # (factor, round) -> seconds

    def child(scene, factor, mu, timeout):
        k = sum(f == factor for f in calls)
        calls.append(factor)
        return {"scene": scene, "factor": factor, "friction": mu, "tets": 100, "free_dofs": int(1000 * factor),
                "seconds": wall[(factor, k)], "cpu_seconds": wall[(factor, k)], "peak_memory_mib": 1.0,
                "newton_iterations_per_step": 1.0, "factorizations": 1, "ms_per_factorization": 1.0,
                "factorization_share": 0.1, "assembly_share": 0.1, "fill": 2.0}

    monkeypatch.setattr(scaling, "_run_child", child)
    out = scaling.run_scaling(["clip3d"], [1.0, 2.0], [0.0], timeout=10.0, repeat=2)
    assert calls == [1.0, 2.0, 2.0, 1.0]  # the second round in reverse
    rows = out["groups"][0]["rows"]
    assert [r["seconds"] for r in rows] == [1.8, 4.0] and rows[1]["seconds_runs"] == [4.5, 4.0]
    # the exponent of the fastest runs: log(4.0 / 1.8) / log(2)
    assert out["groups"][0]["time_exponent_vs_dofs"]["overall"] == round(float(np.log(4.0 / 1.8) / np.log(2.0)), 2)


def test_scaling_peak_memory_after_a_reset_leaves_out_what_was_freed_before_it():
    """A level's peak memory is its own: the warm-up's memory, freed before the reset, is not in it."""
    sys.path.insert(0, str(TOOLS))
    try:
        scaling = importlib.import_module("benchmarks._scaling")
    finally:
        sys.path.remove(str(TOOLS))
    if not scaling.reset_peak_memory():
        pytest.skip("this kernel refuses to reset the peak resident memory")
    base = scaling.peak_memory_mib(True)
    big = np.ones(40 * 2**20)  # 320 MiB of float64, touched
    during = scaling.peak_memory_mib(True)
    del big
    assert scaling.reset_peak_memory()
    after = scaling.peak_memory_mib(True)
    assert during > base + 300 and after < during - 300


def test_scaling_rejects_an_unknown_scene_before_any_level_runs():
    import subprocess

    argv = ["insertion", "--scaling", "--scenes", "clip3d,knocker9", "--factors", "1", "--frictions", "0"]
    out = subprocess.run([sys.executable, str(TOOLS / "bench.py"), *argv], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    assert out.stderr.strip().count("\n") == 0 and "'knocker9'" in out.stderr  # one line, no level's table
    assert out.stdout == ""


def test_insertion_rejects_an_unknown_case():
    import subprocess

    out = subprocess.run([sys.executable, str(TOOLS / "bench.py"), "insertion", "--only", "cclamp2d,nope"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and out.stdout == ""
    assert out.stderr.strip().count("\n") == 0 and "'nope'" in out.stderr


@pytest.mark.parametrize("argv, names", [
    (["--repeat", "0"], "--repeat"),  # ran one run per case and exited 0
    (["--budget", "0"], "--budget"),
    (["--scaling", "--factors", "inf"], "--factors"),
    (["--scaling", "--level-timeout", "0"], "--level-timeout"),
    (["--scaling", "--plot", "scaling.txt"], ".png"),
    # a folder where nothing can be created: refused before any level runs, not after the last (a
    # traceback, exit 1); /proc takes no new folder, also for root, for whom os.access says yes
    (["--scaling", "--scenes", "clip3d", "--factors", "1", "--frictions", "0", "--plot", "/proc/simfab-x/s.png"],
     "--plot"),
])
def test_insertion_rejects_bad_options_before_running(argv, names):
    import subprocess

    out = subprocess.run([sys.executable, str(TOOLS / "bench.py"), "insertion", *argv],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and out.stdout == ""
    assert out.stderr.strip().count("\n") == 0 and names in out.stderr, out.stderr
