"""The outlier statistic and the one outlier rule both acceptance gates use
(gates/outlier_statistic.py, gates/outliers.py): standardised leave-one-out residuals, their
robust σ and the rule's choices, checked on hand-worked numbers.
"""

import numpy as np

from balance_calib.gates.outlier_statistic import robust_sigma, standardized_press, worst_first
from balance_calib.gates.outliers import judge_outliers, JudgedResiduals, OutlierRule


def test_standardised_press_residuals_are_press_times_root_one_minus_leverage():
    leverage = np.array([0.0, 0.5, 0.75, 0.96])
    residuals = np.array([[2.0], [1.0], [-3.0], [0.5]])  # N
    press = residuals / (1.0 - leverage)[:, None]  # e / (1 - h)
    press_pct, standardized = standardized_press(residuals, press, np.array([200.0]))
    np.testing.assert_allclose(press_pct[:, 0], [1.0, 1.0, -6.0, 6.25])  # % of 200 N
    # × sqrt(1 - h): 1, √0.5, 0.5, 0.2
    np.testing.assert_allclose(standardized[:, 0], [1.0, np.sqrt(0.5), -3.0, 1.25])


def test_robust_sigma_is_1_4826_mad_of_the_loaded_points_and_the_tail_bound_on_request():
    values = np.arange(1.0, 13.0)  # 1 … 12, median 6.5
    loaded = np.ones(12, bool)
    # |x - 6.5| = 0.5, 0.5, 1.5, 1.5, …, 5.5, 5.5: median 3.0
    assert robust_sigma(values[:, None], loaded)[0] == 1.4826 * 3.0
    # 90 % point of those deviations: 5.5, and 5.5 / 1.6449 < 1.4826 · 3: the MAD's σ stays
    assert robust_sigma(values[:, None], loaded, tail_quantile=True)[0] == 1.4826 * 3.0
    # wide tails: 14 points at ±1, 6 at ±10; median 0, MAD 1, 90 % point of |x| 10 (positions
    # 17 and 18 of 20 sorted are both 10): σ = 10 / 1.6449 rather than 1.4826
    tails = np.array([1.0, -1.0] * 7 + [10.0, -10.0] * 3)[:, None]
    assert robust_sigma(tails, np.ones(20, bool))[0] == 1.4826
    assert robust_sigma(tails, np.ones(20, bool), tail_quantile=True)[0] == 10.0 / 1.6449
    # zero points out: a series of 12 loaded points plus 8 exact zeros keeps the same σ
    with_zeros = np.concatenate([values, np.zeros(8)])[:, None]
    assert robust_sigma(with_zeros, np.arange(20) < 12)[0] == 1.4826 * 3.0
    # fewer than 10 loaded points: all points count
    assert robust_sigma(with_zeros, np.arange(20) < 5)[0] == 1.4826 * np.median(
        np.abs(with_zeros[:, 0] - np.median(with_zeros[:, 0]))
    )


def test_flagged_points_come_worst_first_with_their_worst_component():
    standardized = np.array([[1.0, 0.0], [5.0, 1.0], [0.0, -9.0], [np.nan, 0.0], [3.0, 3.5]])
    threshold = np.array([2.0, 3.0])
    flagged = (np.abs(standardized) > threshold) | ~np.isfinite(standardized)
    rows, components = worst_first(flagged, standardized, threshold)
    # excess: row 3 NaN (infinitely far), row 2 9/3 = 3, row 1 5/2 = 2.5, row 4 max(1.5, 1.17)
    assert rows.tolist() == [3, 2, 1, 4] and components.tolist() == [0, 1, 0, 0]


def test_the_rule_excuses_points_flagged_alike_and_keeps_the_one_that_stands_out():
    # one load, capacity 100 (residuals are % capacity), leverage 0 (press = residual): 24 points
    # at ±1, five at 20 … 24 (a shape the model lacks), one typed weight at 200.
    # median of all 30: 1; |x - 1|: 12 x 0, 12 x 2, 19 … 23, 199, median 2: σ = 1.4826 · 2,
    # threshold 7σ = 20.76: 21, 22, 23, 24 and 200 are beyond it, 20 is not
    values = np.array([1.0, -1.0] * 12 + [20.0, 21.0, 22.0, 23.0, 24.0, 200.0])[:, None]
    data = JudgedResiduals(['F'], values, values, np.array([100.0]), np.ones(30, bool))
    plain = judge_outliers(data, OutlierRule())
    assert plain.threshold[0] == 7.0 * 1.4826 * 2.0
    assert plain.rows.tolist() == [29, 28, 27, 26, 25] and plain.alike == {}
    # alike: five flagged (> 3), their median |residual| 23; all but 200 (> 4 x 23 = 92) are
    # structure
    alike = judge_outliers(data, OutlierRule(alike=True))
    assert alike.rows.tolist() == [29] and alike.alike['F'].tolist() == [25, 26, 27, 28]
    # the tail bound: the 90 % point of |x - 1| (linear, between 21 and 22 at 0.1) is 21.1,
    # σ = 21.1 / 1.6449; only 200 is beyond 7σ = 89.8, and one point is never "alike"
    tail = judge_outliers(data, OutlierRule(tail_quantile=True, alike=True))
    np.testing.assert_allclose(tail.robust[0], 21.1 / 1.6449)
    assert tail.rows.tolist() == [29] and tail.alike == {}
    # nothing explains anything without a structure from the diagnosis
    assert not np.any(tail.explained)
