"""The insertion loop's stage timer books every second once: nested blocks pause the enclosing one,
and a block opened with ``into`` takes the time of everything nested in it (see simfab.coupling.timing)."""

import time

from simfab.coupling.timing import Timer


def _work():
    s = 0.0
    for i in range(20000):
        s += i * 0.5
    return s


def test_nested_blocks_are_booked_exclusively():
    timer = Timer()
    t0 = time.perf_counter()
    with timer.timed("outer"):
        _work()
        with timer.timed("inner"):
            _work()
        _work()
    total = time.perf_counter() - t0
    assert set(timer.t) == {"outer", "inner"} and timer.n == {"outer": 1, "inner": 1}
    # exclusive: the two add up to the elapsed time, not more (inclusive booking would add the inner twice)
    assert 0 < timer.t["inner"] < total and 0 < timer.t["outer"] < total
    assert timer.t["outer"] + timer.t["inner"] <= total


def test_into_takes_the_nested_blocks():
    timer = Timer()
    with timer.into("predictor"):
        with timer.timed("assembly"):
            _work()
        with timer.into("line_search"):  # nested into: still the outer key
            _work()
    with timer.timed("assembly"):
        _work()
    assert set(timer.t) == {"predictor", "assembly"}
    assert timer.n == {"predictor": 1, "assembly": 1}
