"""How many runs the insertion benchmark takes per case (its timings are not asserted)."""

import importlib
import pathlib
import sys
from types import SimpleNamespace

import pytest

TOOLS = pathlib.Path(__file__).resolve().parents[2] / "tools"


@pytest.fixture(scope="module")
def wanted():
    sys.path.insert(0, str(TOOLS))
    try:
        return importlib.import_module("benchmarks.insertion")._runs_wanted
    finally:
        sys.path.remove(str(TOOLS))


def _args(repeat=None, budget=10.0, max_repeat=15):
    return SimpleNamespace(repeat=repeat, budget=budget, max_repeat=max_repeat)


def test_fixed_repeat_takes_exactly_that_many_runs(wanted):
    assert wanted(_args(repeat=3), [0.1]) == 3
    assert wanted(_args(repeat=3), [0.1] * 3) == 3  # done
    assert wanted(_args(repeat=1), []) == 1


def test_budget_keeps_running_until_spent_within_the_bounds(wanted):
    a = _args()
    assert wanted(a, []) == 2 and wanted(a, [30.0]) == 2  # at least two, however slow
    assert wanted(a, [30.0] * 2) == 2  # over budget after two: done
    assert wanted(a, [1.0] * 9) == 10  # budget left: one more
    assert wanted(a, [1.0] * 10) == 10  # budget spent: done
    assert wanted(a, [0.1] * 15) == 15  # capped
