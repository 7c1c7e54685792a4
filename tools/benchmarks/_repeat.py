"""How many timed runs a benchmark case takes: a fixed count, or as many as fit in a time budget.

A run of a short case (the snap-fit's ~0.05 s, cclamp2d's ~0.2 s) varies by +-30 % with the machine's
load; one run's figure, or a ratio of two single runs, can be off by 2x. Repeating a case until a few
seconds are spent makes the default's figure trustworthy without making a long case (minutes per
run) slower: it runs ``min_runs`` times and stops.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

#: Seconds of runs per case when no fixed count is given, and the most runs a case takes.
BUDGET_SECONDS = 10.0
MAX_RUNS = 15


@dataclass(frozen=True, kw_only=True)
class RepeatRule:
    """The number of timed runs of one case.

    Args:
        repeat: a fixed count of runs; None: runs until ``budget`` seconds are spent.
        budget: seconds of runs per case (the sum of the runs' wall seconds).
        min_runs: at least this many runs under the budget, however slow.
        max_runs: at most this many runs under the budget.
        first_outside_budget: leave the first run's seconds out of the budget (it pays the process's
            one-off costs: compiling or loading kernels, a first factorization's library load).
    """

    repeat: int | None = None
    budget: float = BUDGET_SECONDS
    min_runs: int = 1
    max_runs: int = MAX_RUNS
    first_outside_budget: bool = False

    def wanted(self, seconds: list) -> int:
        """How many runs the case should have, given the wall seconds of those done so far."""
        if self.repeat is not None:
            return max(1, self.repeat)
        if len(seconds) < self.min_runs:
            return self.min_runs
        spent = sum(seconds[1:] if self.first_outside_budget else seconds)
        return len(seconds) + 1 if spent < self.budget and len(seconds) < self.max_runs else len(seconds)


def add_repeat_options(ap: argparse.ArgumentParser, *, what: str, repeat_help: str) -> None:
    """The ``--repeat``, ``--budget`` and ``--max-repeat`` options of a bench's command line."""
    ap.add_argument("--repeat", type=int, default=None, help=repeat_help)
    ap.add_argument("--budget", type=float, default=BUDGET_SECONDS,
                    help=f"seconds of {what} per case when --repeat is not given (default {BUDGET_SECONDS:g})")
    ap.add_argument("--max-repeat", type=int, default=MAX_RUNS,
                    help=f"at most this many {what} per case under --budget (default {MAX_RUNS})")


def repeat_rule(a: argparse.Namespace, *, min_runs: int, first_outside_budget: bool = False) -> RepeatRule:
    """The rule of the parsed options of :func:`add_repeat_options`; raises InputError on a bad one."""
    from simfab.errors import InputError

    if a.repeat is not None and a.repeat < 1:
        raise InputError(f"--repeat must be at least 1, got {a.repeat}")
    if not a.budget > 0 or a.max_repeat < 1:
        raise InputError(f"--budget must be > 0 seconds and --max-repeat at least 1, got {a.budget} and {a.max_repeat}")
    return RepeatRule(repeat=a.repeat, budget=a.budget, min_runs=min(min_runs, a.max_repeat), max_runs=a.max_repeat,
                      first_outside_budget=first_outside_budget)
