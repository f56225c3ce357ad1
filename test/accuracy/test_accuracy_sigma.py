"""The two σ of the code, on hand-worked residuals: the memo's eq. (44) (root mean square about
zero, divided by N_max) and the tables' sample standard deviation (about the mean, N - 1).
"""

import numpy as np
import pytest

from balance_calib.accuracy.sigma import sample_std_pct_fs, sigma_pct_fs


def test_eq_44_divides_the_sum_of_squares_by_the_number_of_points():
    residuals = np.array([[1.0, 2.0], [-1.0, 0.0], [3.0, -2.0]])  # N, N·m
    full_scale = np.array([10.0, 4.0])
    # Σr² / 3 = 11/3 and 8/3; σ = sqrt of that / F.S. × 100
    np.testing.assert_allclose(
        sigma_pct_fs(residuals, full_scale),
        [np.sqrt(11 / 3) * 10.0, np.sqrt(8 / 3) * 25.0],
        rtol=1e-15,
    )
    # one component as a 1-D array: a float, the same number
    one = sigma_pct_fs(residuals[:, 0], 10.0)
    assert isinstance(one, float) and one == pytest.approx(np.sqrt(11 / 3) * 10.0, rel=1e-15)


def test_the_sample_standard_deviation_is_about_the_mean_with_n_minus_1():
    residuals = np.array([[1.0, 2.0], [-1.0, 0.0], [3.0, -2.0]])
    full_scale = np.array([10.0, 4.0])
    # column 0: mean 1, deviations 0, -2, 2, Σ = 8, / 2 -> σ 2; column 1: mean 0, Σ = 8 -> 2
    np.testing.assert_allclose(sample_std_pct_fs(residuals, full_scale), [20.0, 50.0], rtol=1e-15)
    # a constant offset moves eq. (44)'s σ and leaves the sample standard deviation
    shifted = residuals + 5.0
    np.testing.assert_allclose(sample_std_pct_fs(shifted, full_scale), [20.0, 50.0], rtol=1e-14)
    assert np.all(sigma_pct_fs(shifted, full_scale) > sigma_pct_fs(residuals, full_scale))
