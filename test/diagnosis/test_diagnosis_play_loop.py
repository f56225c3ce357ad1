"""The play operator's lag and its loop without the first-loading curve (candidates.play_lag,
play_loop), hand-worked on one output of half-width w = 0.3: the lag is (V - state) / w with the
state dragged within w of V; the loop is that lag less clip(V / w).
"""

import numpy as np
import pytest

from balance_calib.diagnosis.candidates import play_lag, play_loop

# 0 -> 0.15 -> 1 (first loading) -> 0.3 -> 0 -> -1 -> 0: states 0, 0, 0.7, 0.6, 0.3, -0.7, -0.3
OUTPUT = np.array([0.0, 0.15, 1.0, 0.3, 0.0, -1.0, 0.0])
LAG = np.array([0.0, 0.5, 1.0, -1.0, -1.0, -1.0, 1.0])
LOOP = np.array([0.0, 0.0, 0.0, -2.0, -1.0, 0.0, 1.0])


def test_the_lag_of_a_hand_worked_history():
    lag = play_lag(OUTPUT[:, None], np.arange(len(OUTPUT)), 0.3)[:, 0]
    np.testing.assert_allclose(lag, LAG, atol=1e-12)


def test_the_loop_is_zero_on_first_loading_and_spans_two_across_the_backlash():
    loop = play_loop(OUTPUT[:, None], np.arange(len(OUTPUT)), 0.3)[:, 0]
    np.testing.assert_allclose(loop, LOOP, atol=1e-12)


@pytest.mark.parametrize('seed', [1, 2])
def test_points_in_any_order_are_taken_in_time_order(seed):
    order = np.random.default_rng(seed).permutation(len(OUTPUT))
    times = np.arange(len(OUTPUT), dtype=float)
    loop = play_loop(OUTPUT[order, None], times[order], 0.3)[:, 0]
    np.testing.assert_allclose(loop, LOOP[order], atol=1e-12)


def test_each_bridge_has_its_own_half_width():
    outputs = np.column_stack([OUTPUT, 2.0 * OUTPUT])  # the same history at twice the scale
    loop = play_loop(outputs, np.arange(len(OUTPUT)), np.array([0.3, 0.6]))
    np.testing.assert_allclose(loop[:, 1], loop[:, 0], atol=1e-12)
