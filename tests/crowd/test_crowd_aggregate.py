"""Classical aggregators, RMS and percentile rank on hand-computed examples."""

import numpy as np
import pytest

from simfab.crowd import aggregators as A
from simfab.crowd import metrics
from simfab.crowd.data import Scale, from_matrix

NAN = np.nan
# 4 raters x 3 questions on a 1..10 scale; rater 3 skipped question 2
LABELS = np.array(
    [
        [2.0, 8.0, 5.0],
        [4.0, 8.0, 5.0],
        [8.0, 6.0, NAN],
        [2.0, 6.0, 9.0],
    ]
)


def test_arithmetic_mean_by_hand():
    # q1: (2+4+8+2)/4 = 4; q2: (8+8+6+6)/4 = 7; q3: (5+5+9)/3 = 19/3
    np.testing.assert_allclose(A.arithmetic_mean(LABELS), [4.0, 7.0, 19.0 / 3.0], rtol=1e-15)


def test_geometric_mean_by_hand():
    # q1: (2*4*8*2)^(1/4) = 128^(1/4); q2: (8*8*6*6)^(1/4) = sqrt(48); q3: (5*5*9)^(1/3) = 225^(1/3)
    np.testing.assert_allclose(A.geometric_mean(LABELS), [128 ** 0.25, 48 ** 0.5, 225 ** (1 / 3)], rtol=1e-13)


def test_median_by_hand():
    # q1: sorted 2,2,4,8 -> (2+4)/2 = 3; q2: 6,6,8,8 -> 7; q3: 5,5,9 -> 5
    np.testing.assert_array_equal(A.median(LABELS), [3.0, 7.0, 5.0])


def test_majority_and_tie_rule():
    # q1: 2 twice -> 2. q2: 6 and 8 tie (twice each), median 7 is equally close -> lower, 6.
    # q3: 5 twice -> 5.
    np.testing.assert_array_equal(A.majority(LABELS), [2.0, 6.0, 5.0])
    # tie broken toward the median: values 3,3,9,9,8 -> 3 and 9 tie, median 8 -> 9
    np.testing.assert_array_equal(A.majority(np.array([[3.0], [3.0], [9.0], [9.0], [8.0]])), [9.0])


def test_geometric_mean_needs_positive_scale():
    from simfab.errors import InputError

    with pytest.raises(InputError):
        A.geometric_mean(np.array([[0.0, 1.0]]))


def test_rms_continuous_and_discrete_by_hand():
    sc = Scale(lo=1, hi=10)  # unit scale: (v - 1) / 9
    est = np.array([4.0, 7.0])
    truth = np.array([5.8, 6.2])
    # continuous: errors (4-5.8)/9, (7-6.2)/9 -> sqrt((1.8^2 + 0.8^2)/2)/9
    assert metrics.rms_unit(est, truth, sc) == pytest.approx(np.sqrt((1.8**2 + 0.8**2) / 2) / 9, rel=1e-14)
    # discrete: truth rounds to 6, 6 -> errors 2/9, 1/9
    assert metrics.rms_unit(est, truth, sc, discrete=True) == pytest.approx(np.sqrt((4 + 1) / 2) / 9, rel=1e-14)
    # halves round up: 6.5 -> 7
    assert sc.round(6.5) == 7.0 and sc.round(6.49) == 6.0


def test_individual_errors_and_percentile_by_hand():
    sc = Scale(lo=1, hi=10)
    truth = np.array([2.0, 8.0, 5.0])
    e = metrics.individual_errors(LABELS, truth, sc)
    # rater 0 exact; rater 1: (2/9) on q1 only -> sqrt(4/3)/9; rater 2: q1 6/9, q2 2/9 (q3 missing)
    # -> sqrt((36+4)/2)/9; rater 3: q2 2/9, q3 4/9 -> sqrt((4+16)/3)/9
    np.testing.assert_allclose(e, [0.0, np.sqrt(4 / 3) / 9, np.sqrt(20) / 9, np.sqrt(20 / 3) / 9], rtol=1e-14)
    # crowd error 0.1: beats raters 1 (0.128), 2 (0.497), 3 (0.287) -> 3 of 4 = 75 %
    assert metrics.percentile_rank(0.1, e) == pytest.approx(75.0)
    # tie with rater 1 counts half: (2 + 0.5) / 4
    assert metrics.percentile_rank(float(e[1]), e) == pytest.approx(62.5)


def test_score_uses_discrete_rms_for_discrete_methods():
    sc = Scale(lo=1, hi=10)
    r = from_matrix(LABELS, sc)
    truth = np.array([2.4, 7.6, 5.2])
    row = metrics.score(A.majority(LABELS), r.labels, truth, sc, discrete_method=True)
    assert row["rms"] == row["rms_discrete"]
    # majority 2, 6, 5 vs rounded truth 2, 8, 5 -> sqrt((0 + 4 + 0)/3)/9
    assert row["rms_discrete"] == pytest.approx(np.sqrt(4 / 3) / 9)
    row = metrics.score(A.arithmetic_mean(LABELS), r.labels, truth, sc, discrete_method=False)
    assert row["rms"] == row["rms_continuous"]
