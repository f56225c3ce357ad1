"""The thrust stand's calibration line: eqs. (25)-(27) of the lab manual, §4.2's hysteresis
correction, the package's QR fit agreeing with the closed forms, and §A1.3's value ± error.
"""

import numpy as np
import pytest

from balance_calib.fit.least_squares import fit_model
from balance_calib.model.terms import parse_terms
from balance_calib.simulation.thrust_stand import ThrustStandSimulator
from balance_calib.thrust_stand.calibration import calibrate, CalibrationReadings
from balance_calib.thrust_stand.line_fit import (
    fit_line,
    line_sums,
    slope_and_intercept,
    slope_partials,
)
from balance_calib.thrust_stand.significant import format_value_error, round_result

# Worked by hand, the manual's worksheet layout:
#   x = 0, 1, 2, 3     y = 1, 3, 4, 7     n = 4
#   Σx = 6   Σy = 15   Σxy = 0 + 3 + 8 + 21 = 32   Σx² = 0 + 1 + 4 + 9 = 14
#   D = nΣx² - (Σx)² = 56 - 36 = 20
#   a = (nΣxy - ΣxΣy)/D = (128 - 90)/20 = 1.9                        eq. (25)
#   b = (Σx²Σy - ΣxΣxy)/D = (210 - 192)/20 = 0.9                     eq. (26)
# σ_x = 0.1, σ_y = 0.2 at every point, eq. (27):
#   ∂a/∂y_i = (n x_i - Σx)/D = (4x_i - 6)/20 = -0.3, -0.1, 0.1, 0.3  Σ² = 0.2
#   ∂a/∂x_i = (n y_i - Σy)/D - 2(n x_i - Σx)(nΣxy - ΣxΣy)/D²
#           = (4y_i - 15)/20 - (4x_i - 6)·2·38/400
#           = -0.55 + 1.14, -0.15 + 0.38, 0.05 - 0.38, 0.65 - 1.14
#           = 0.59, 0.23, -0.33, -0.49                                Σ² = 0.75
#   σ_a² = 0.2·0.2² + 0.75·0.1² = 0.008 + 0.0075 = 0.0155,  σ_a = 0.12450
# Without σ: residuals y - (1.9x + 0.9) = 0.1, 0.2, -0.7, 0.4; Σr² = 0.70, s² = 0.70/2 = 0.35,
#   Σ(x - x̄)² = 5, σ_a = sqrt(0.35/5) = sqrt(0.07) = 0.26458
HAND_X = [0.0, 1.0, 2.0, 3.0]
HAND_Y = [1.0, 3.0, 4.0, 7.0]


def test_slope_intercept_and_sigma_match_the_hand_worked_example():
    fit = fit_line(HAND_X, HAND_Y, sigma_x=0.1, sigma_y=0.2)
    assert fit.slope == pytest.approx(1.9, rel=1e-12)
    assert fit.intercept == pytest.approx(0.9, rel=1e-12)
    assert fit.sigma_slope == pytest.approx(np.sqrt(0.0155), rel=1e-12)
    assert fit.sigma_source == 'eq27'
    sums = fit.sums
    assert (sums.n, sums.sum_x, sums.sum_y, sums.sum_xy, sums.sum_xx) == (4, 6.0, 15.0, 32.0, 14.0)
    assert format_value_error(fit.slope, fit.sigma_slope, name='a') == 'a = 1.90 ± 0.12'


def test_eq27_partials_by_hand_and_by_finite_differences_of_eq25():
    da_dx, da_dy = slope_partials(HAND_X, HAND_Y)
    np.testing.assert_allclose(da_dy, [-0.3, -0.1, 0.1, 0.3], atol=1e-14)
    np.testing.assert_allclose(da_dx, [0.59, 0.23, -0.33, -0.49], atol=1e-14)
    # the printed eq. (27) against a direct numerical derivative of eq. (25)
    rng = np.random.default_rng(3)
    x, y = rng.normal(size=7), rng.normal(size=7)
    da_dx, da_dy = slope_partials(x, y)
    h = 1e-6
    for i in range(x.size):
        step = np.zeros_like(x)
        step[i] = h
        numeric_x = (
            slope_and_intercept(line_sums(x + step, y))[0]
            - slope_and_intercept(line_sums(x - step, y))[0]
        ) / (2 * h)
        numeric_y = (
            slope_and_intercept(line_sums(x, y + step))[0]
            - slope_and_intercept(line_sums(x, y - step))[0]
        ) / (2 * h)
        assert da_dx[i] == pytest.approx(numeric_x, rel=1e-6, abs=1e-9)
        assert da_dy[i] == pytest.approx(numeric_y, rel=1e-6, abs=1e-9)


def test_sigma_from_residuals_when_no_point_sigmas_are_given():
    fit = fit_line(HAND_X, HAND_Y)
    assert fit.sigma_source == 'residuals'
    assert fit.sigma_slope == pytest.approx(np.sqrt(0.07), rel=1e-12)
    assert fit.residual_std == pytest.approx(np.sqrt(0.35), rel=1e-12)


def test_closed_forms_survive_a_large_reading_offset():
    # readings with a 1e6 offset: the literal nΣx² - (Σx)² would cancel to garbage
    fit = fit_line(np.array(HAND_X) + 1e6, HAND_Y, 0.1, 0.2)
    assert fit.slope == pytest.approx(1.9, rel=1e-8)
    assert fit.sigma_slope == pytest.approx(np.sqrt(0.0155), rel=1e-8)


def test_fit_model_agrees_with_eqs_25_26():
    rng = np.random.default_rng(7)
    x = np.sort(rng.uniform(0, 1, 6))
    y = 4.8 * x - 0.15 + rng.normal(0, 0.01, 6)
    result = fit_model(
        parse_terms(['1', 'FXV']),
        x[:, None],
        y[:, None],
        name='thrust_stand',
        components=('FX',),
        inputs=('FXV',),
        on_unexcited='raise',
    )
    intercept, slope = result.model.coefficients[0]
    a, b = slope_and_intercept(line_sums(x, y))
    assert slope == pytest.approx(a, rel=1e-12)
    assert intercept == pytest.approx(b, rel=1e-10)
    # and the QR fit's standard error is eq. (27) with σ_y = residual scatter
    assert result.standard_errors[0, 1] == pytest.approx(fit_line(x, y).sigma_slope, rel=1e-10)


def test_hysteresis_correction_recovers_the_stand_sensitivity():
    simulator = ThrustStandSimulator(seed=11)
    readings = simulator.calibration_readings()
    corrected = calibrate(readings, reading_sigma_mv=1e-4, mass_sigma_kg=1e-7)
    raw = calibrate(
        readings, reading_sigma_mv=1e-4, mass_sigma_kg=1e-7, hysteresis_correction=False
    )
    true_slope = simulator.calibration_slope_n_per_mv
    assert corrected.slope_n_per_mv == pytest.approx(true_slope, rel=1e-3)
    # the set accumulates with load, so the uncorrected slope is biased low by ~ 2-3 %
    assert raw.slope_n_per_mv < true_slope * 0.985
    # intercept: minus the pan's weight (footnote 13)
    assert corrected.intercept_n == pytest.approx(-simulator.pan_mass_kg * 9.80665, abs=2e-3)
    assert corrected.config_matrix()['coefficients']['FX'][1] == corrected.slope_n_per_mv
    assert corrected.formatted().startswith('a = (5.00')


def test_calibration_readings_are_validated():
    with pytest.raises(ValueError, match='5 weights need 6 loaded'):
        CalibrationReadings(np.full(5, 0.085), np.zeros(5), np.zeros(6))


@pytest.mark.parametrize(
    'value, error, text',
    [
        (1.9, 0.1245, '1.90 ± 0.12'),  # leading 1: two digits
        (12.3456, 0.0456, '12.35 ± 0.05'),  # leading 4: one digit
        (1234.5, 56, '1230 ± 60'),  # error in the tens
        (2.25, 0.5, '2.3 ± 0.5'),  # 四捨五入: half up, not to even
        (-0.001, 0.3, '0.0 ± 0.3'),  # no "-0.0"
        (3.14159, 0.0996, '3.14 ± 0.10'),  # rounding carries into a new digit
    ],
)
def test_value_and_error_share_their_last_digit(value, error, text):
    assert str(round_result(value, error)) == text


def test_rounding_needs_a_positive_error():
    with pytest.raises(ValueError):
        round_result(1.0, 0.0)


# --- the residual of a one-axis calibration examined --------------------------------
# A load cell read on loading and unloading, twice (0, 10, ..., 100 N up, down, up, down: 41
# points). Its effects are written from the physics, not from the candidate columns: a hysteresis
# loop widest at mid-range, h sin(pi y / FS) with the sign of the direction of travel (the
# candidates have dir, dir*x, dir*x^2 and the travel since the turning point, no sine), and a
# quadratic nonlinearity of the reading. Noise: 0.02 % FS per reading, so a correct fit's residual
# σ is 0.02 % FS x sqrt((n - p) / n) <= 0.02 % FS, the clean floor.
FS_N, SENSITIVITY, NOISE_PCT_FS = 100.0, 0.02, 0.02


def _load_cell(seed, hysteresis=0.0, quadratic=0.0, pickup=0.0, drift=0.0):
    rng = np.random.default_rng(seed)
    up = np.linspace(0.0, FS_N, 11)
    loads = np.concatenate([up, up[::-1][1:], up[1:], up[::-1][1:]])
    direction = np.ones(len(loads))
    for i in range(1, len(loads)):
        direction[i] = (
            np.sign(loads[i] - loads[i - 1]) if loads[i] != loads[i - 1] else direction[i - 1]
        )
    full = SENSITIVITY * FS_N
    readings = (
        SENSITIVITY * loads
        + hysteresis * full * direction * np.sin(np.pi * loads / FS_N)
        + quadratic * full * (loads / FS_N) ** 2
        + pickup * full * np.sin(2 * np.pi * np.arange(len(loads)) / 3.3)
        + drift * full * np.arange(len(loads)) / len(loads)
        + rng.normal(size=len(loads)) * NOISE_PCT_FS / 100 * full
    )
    return readings, loads


@pytest.mark.parametrize(
    'case, kwargs, names',
    [
        ('clean', {}, ()),
        ('hysteresis', {'hysteresis': 0.003}, ('hysteresis',)),
        ('quadratic', {'quadratic': 0.005}, ('nonlinearity',)),
        ('both', {'hysteresis': 0.003, 'quadratic': 0.005}, ('hysteresis', 'nonlinearity')),
        ('drift', {'drift': 0.002}, ('zero_drift',)),
    ],
)
@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_load_unload_calibration_names_its_effects_and_returns_to_the_floor(
    case, kwargs, names, seed
):
    from balance_calib.thrust_stand.one_axis import examine_line

    x, y = _load_cell(seed, **kwargs)
    result = examine_line(x, y)  # direction inferred from the order of y
    assert sorted(result.effect_names) == sorted(names), [e.evidence for e in result.effects]
    assert result.sigma_pct_fs['after'] <= 1.2 * NOISE_PCT_FS
    assert result.sigma_pct_fs_crossval['after'] <= 1.3 * NOISE_PCT_FS
    if names:
        assert result.sigma_pct_fs['before'] > 1.5 * NOISE_PCT_FS  # the effect was really there
    # the repeated points (same load, same direction) give the repeatability: about the noise
    assert 0.5 * NOISE_PCT_FS < result.repeatability_pct_fs < 1.6 * NOISE_PCT_FS


def test_structure_no_candidate_explains_is_unexplained_and_not_adopted():
    """A pickup periodic in point order (3.3 points a cycle): no hysteresis, no curvature, no
    drift.
    """
    from balance_calib.thrust_stand.one_axis import examine_line

    x, y = _load_cell(5, pickup=0.002)
    result = examine_line(x, y)
    assert [e.name for e in result.effects][-1:] == ['unexplained']
    unexplained = result.effects[-1]
    assert 'lack of fit p = ' in unexplained.evidence and unexplained.terms == ()


def test_few_points_carry_no_extra_terms_and_given_sigmas_are_the_yardstick():
    """Six loading steps (the thrust stand's §4.2): at most n // 4 = 1 -> the line alone; with
    σ_y given, a residual 10x beyond it is unexplained.
    """
    from balance_calib.thrust_stand.one_axis import examine_line

    x = np.arange(6.0)
    y = 2.0 * x + 0.05 * (x - 2.5) ** 2
    quiet = examine_line(x, y, np.ones(6), None, 0.5)
    assert quiet.effect_names == () and quiet.terms == ('1', 'x')
    loud = examine_line(x, y, np.ones(6), None, 0.005)
    assert loud.effect_names == ('unexplained',)


def test_line_fit_command_reports_the_examined_residual(tmp_path):
    import json
    import subprocess
    import sys

    x, y = _load_cell(1, hysteresis=0.003)
    path = tmp_path / 'load_cell.csv'
    direction = [1.0] + [float(np.sign(b - a)) if b != a else 1.0 for a, b in zip(y[:-1], y[1:])]
    path.write_text(
        'x,y,direction\n'
        + ''.join(f'{float(a)!r},{float(b)!r},{d:+.0f}\n' for a, b, d in zip(x, y, direction))
    )
    done = subprocess.run(
        [sys.executable, '-m', 'balance_calib.cli', 'line-fit', str(path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result['a'] == pytest.approx(1 / SENSITIVITY, rel=0.01)
    assert set(result['sigma_pct_fs']) == {'before', 'after'} and set(
        result['sigma_pct_fs_crossval']
    ) == {'before', 'after'}
    assert [e['name'] for e in result['effects']] == ['hysteresis']
    effect = result['effects'][0]
    assert set(effect) == {'name', 'components', 'evidence', 'terms', 'sigma_after_pct_fs'}
    assert result['sigma_pct_fs']['after'] < result['sigma_pct_fs']['before'] / 5
    bad = tmp_path / 'bad.csv'
    bad.write_text('x,y,direction\n1,2,1\n2,3,0\n3,4,-1\n')
    done = subprocess.run(
        [sys.executable, '-m', 'balance_calib.cli', 'line-fit', str(bad)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert (
        done.returncode == 2
        and 'column direction = 0' in done.stderr
        and done.stderr.count('\n') == 1
    )
