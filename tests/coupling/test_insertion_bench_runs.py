"""How many runs the insertion benchmark takes per case (its timings are not asserted)."""

import importlib
import pathlib
import sys
from types import SimpleNamespace

TOOLS = pathlib.Path(__file__).resolve().parents[2] / "tools"


def _runs(repeat, budget, max_repeat, times):
    sys.path.insert(0, str(TOOLS))
    try:
        ins = importlib.import_module("benchmarks.insertion")
    finally:
        sys.path.remove(str(TOOLS))
    a = SimpleNamespace(repeat=repeat, budget=budget, max_repeat=max_repeat)
    runs, spent = [], 0.0
    for t in times:  # run while the case wants more, as in run()
        if len(runs) >= ins._runs_wanted(a, runs, spent):
            break
        runs.append(t)
        spent += t
    return len(runs)


def test_fixed_repeat_takes_exactly_that_many_runs():
    assert _runs(3, 10.0, 15, [0.1] * 50) == 3
    assert _runs(1, 10.0, 15, [30.0] * 50) == 1


def test_budget_keeps_running_until_spent_within_the_bounds():
    assert _runs(None, 10.0, 15, [1.0] * 50) == 10  # 10 runs of 1 s fill a 10 s budget
    assert _runs(None, 10.0, 15, [0.1] * 50) == 15  # capped
    assert _runs(None, 10.0, 15, [30.0] * 50) == 2  # at least two, however slow
