"""The calibrator's math without ROS: TM-663 §10 on live samples, rejection, envelope, tare,
diagnostics.
"""

from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from live_cases import temperature_calibration
import numpy as np
import pytest

from balance_calib.calibration_file import load_calibration
from balance_calib.config import CONFIG_DIR
from balance_calib.live.calibrator_core import compute_wrench, LoadHistory
from balance_calib.live.diagnostics_status import (
    diagnostics,
    InputCounters,
    LiveState,
    OK,
    STALE,
    WARN,
)
from balance_calib.live.load_text import describe_tare, describe_zero
from balance_calib.live.tare_window import tare_zero, TareWindow
from balance_calib.model.active_calibration import activate
from balance_calib.model.inverse import outputs_for_loads
from balance_calib.tunnel_axes import INVERTED, UPRIGHT

MEMO = load_calibration(CONFIG_DIR / 'lmc6522.yaml')
CAPACITY = MEMO.capacity

# TM-663 eqs. (50)-(55) (upright, §10.2.1) and (68)-(73) (inverted, §10.2.2) as printed:
# load_i = OUTER_i * sum_j C_ij * INNER_j * V̄_j, V̄ the outputs in tunnel axes.
PRINTED_SIGNS = {
    'upright': ((-1, 1, -1, 1, 1, 1), (-1, 1, -1, 1, 1, 1)),
    'inverted': ((-1, -1, 1, 1, -1, -1), (-1, -1, 1, 1, -1, -1)),
}


@pytest.mark.parametrize('installation', ['upright', 'inverted'])
def test_linear_model_in_tunnel_axes_is_the_memos_eqs_50_55_and_68_73(installation):
    outer, inner = PRINTED_SIGNS[installation]
    active = activate(MEMO, 'linear', installation)
    axes = UPRIGHT if installation == 'upright' else INVERTED
    rng = np.random.default_rng(1)
    outputs_tunnel = rng.uniform(-1.5, 1.5, size=(20, 6))  # what the tunnel's DAQ calls V̄
    model = MEMO.model('linear')
    c = np.array(
        [[model.coefficient(comp, out) for out in MEMO.bridge_outputs] for comp in MEMO.components]
    )
    printed = np.array(outer) * ((outputs_tunnel * np.array(inner)) @ c.T)
    # the node sees the bridges' own (calibration-axis) outputs: F_XV = -F_X̄V, ... (§10.2)
    batch = compute_wrench(active, axes.from_tunnel(outputs_tunnel))
    np.testing.assert_allclose(batch.wrench_tunnel, printed, rtol=1e-12, atol=1e-9)


def test_constant_terms_are_dropped_for_wind_on_use():
    """§10.1: C1 = C8 = ... = 0; the memo's linear constants are not zero, zero outputs still
    give zero load.
    """
    assert np.any(MEMO.model('linear').coefficients[:, 0] != 0)
    for name in ('linear', 'quadratic', 'cubic'):
        batch = compute_wrench(activate(MEMO, name, 'upright'), np.zeros((1, 6)))
        np.testing.assert_array_equal(batch.wrench_tunnel, 0.0)


@pytest.mark.parametrize('installation', [UPRIGHT, INVERTED])
def test_cubic_model_returns_the_load_that_produced_the_outputs(installation):
    rng = np.random.default_rng(2)
    loads_tunnel = rng.uniform(-0.6, 0.6, size=(30, 6)) * np.abs(installation.to_tunnel(CAPACITY))
    truth = MEMO.model('cubic').without_constant()
    outputs = outputs_for_loads(truth, installation.from_tunnel(loads_tunnel))
    batch = compute_wrench(activate(MEMO, 'cubic', installation), outputs)
    np.testing.assert_allclose(
        batch.wrench_tunnel / np.abs(installation.to_tunnel(CAPACITY)),
        loads_tunnel / np.abs(installation.to_tunnel(CAPACITY)),
        atol=1e-9,
    )


def test_nan_and_inf_samples_are_rejected_without_touching_the_others():
    active = activate(MEMO, 'cubic', 'upright')
    good = np.array([[0.2, -0.1, 0.4, 0.05, -0.3, 0.1], [0.1, 0.1, 0.1, 0.1, 0.1, 0.1]])
    batch = compute_wrench(
        active, np.vstack([good[0], [np.nan, 0, 0, 0, 0, 0], good[1], [0, 0, np.inf, 0, 0, 0]])
    )
    assert batch.accepted.tolist() == [True, False, True, False]
    assert np.all(np.isnan(batch.wrench_tunnel[[1, 3]]))
    np.testing.assert_array_equal(
        batch.wrench_tunnel[[0, 2]], compute_wrench(active, good).wrench_tunnel
    )
    assert not batch.out_of_envelope.any()
    counters = InputCounters()
    counters.count(batch)
    assert (counters.received, counters.published, counters.rejected_nonfinite) == (4, 2, 2)


def test_loads_beyond_the_envelope_are_computed_but_flagged():
    active = activate(MEMO, 'linear', 'upright', envelope_margin=1.1)
    truth = MEMO.model('linear').without_constant()
    fz = np.zeros((3, 6))
    fz[:, 2] = np.array([0.5, 1.05, 1.2]) * CAPACITY[2]
    batch = compute_wrench(active, outputs_for_loads(truth, fz))
    assert batch.out_of_envelope.tolist() == [False, False, True]
    # upright: F_Z = -F_Z̄
    np.testing.assert_allclose(-batch.wrench_tunnel[:, 2], fz[:, 2], rtol=1e-9)


@settings(max_examples=60, deadline=None)
@given(arrays(float, st.tuples(st.integers(1, 40), st.just(6)), elements=st.floats(-3.0, 3.0)))
def test_tare_of_a_tared_window_is_zero(window_mv):
    zero = tare_zero(window_mv)
    np.testing.assert_allclose(tare_zero(window_mv - zero), 0.0, atol=1e-12)
    tare = TareWindow(len(window_mv))
    # later samples do not enter the window
    assert tare.add(window_mv) and tare.add(window_mv + 5.0)
    np.testing.assert_allclose(tare.zero_mv, zero, atol=1e-12)


@settings(max_examples=25, deadline=None)
@given(
    fractions=arrays(float, 6, elements=st.floats(-0.5, 0.5)),
    zero_mv=arrays(float, 6, elements=st.floats(-0.2, 0.2)),
    installation=st.sampled_from([UPRIGHT, INVERTED]),
)
def test_wind_on_load_is_read_from_the_tared_outputs(fractions, zero_mv, installation):
    """Tare in the output domain: model(V + z - z) = load, however nonlinear the model and large
    the zero.
    """
    truth = MEMO.model('cubic').without_constant()
    loads = fractions * CAPACITY
    outputs = outputs_for_loads(truth, loads[None, :]) + zero_mv
    batch = compute_wrench(activate(MEMO, 'cubic', installation), outputs, zero_mv=zero_mv)
    np.testing.assert_allclose(
        batch.wrench_tunnel[0] / installation.to_tunnel(CAPACITY),
        installation.to_tunnel(loads) / installation.to_tunnel(CAPACITY),
        atol=1e-9,
    )


def test_zero_and_tare_descriptions_give_units_per_component():
    text = describe_zero(np.full(6, 0.04), activate(MEMO, 'cubic', 'upright'))
    assert 'FXV=+0.04000 mV' in text and 'MZV=+0.04000 mV' in text
    assert ' N,' in text and 'N·m' in text and 'upright' in text
    # a tare load is stated in tunnel axes: upright F_Z = -F_Z(balance) (§10.2.1)
    text = describe_tare(np.array([0, 0, 2940.0, 0, 39.2, 0]), activate(MEMO, 'cubic', 'upright'))
    assert 'FZ=-2940.000 N' in text and 'MY=+39.200 N·m' in text


def test_temperature_model_uses_dT_and_falls_back_to_the_base_model_without_temperature():
    calibration = temperature_calibration()
    active = activate(calibration, 'adopted', 'balance')
    assert active.requires == ('temperature',) and active.base_name == 'linear'
    outputs = np.full((1, 6), 0.1)
    with_temperature = compute_wrench(active, outputs, temperature_c=25.0)
    without = compute_wrench(active, outputs, temperature_c=None)
    assert (
        with_temperature.model_used == 'linear+temperature'
        and with_temperature.fallback_reason == ''
    )
    assert without.model_used == 'linear' and 'temperature' in without.fallback_reason
    difference = with_temperature.wrench_tunnel - without.wrench_tunnel
    np.testing.assert_allclose(difference, [[0, 0, 50.0, 0, 0, 0]], atol=1e-9)  # 10 N/K x 5 K


def test_load_history_flips_only_beyond_its_deadband():
    history = LoadHistory(CAPACITY, deadband_fraction=0.01)
    loads = np.zeros((6, 6))
    loads[:, 2] = [0.0, 0.5, 0.3, 0.2, -50.0, 60.0]
    direction = history.update(loads)[:, 2]
    # deadband 98 N on F_Z (1 % of 9800 N): noise and ±60 N from the start do not flip it, -150 N
    # does
    assert direction.tolist() == [1, 1, 1, 1, 1, 1]
    loads2 = np.zeros((2, 6))
    loads2[:, 2] = [-150.0, 100.0]
    assert history.update(loads2)[:, 2].tolist() == [-1, 1]


def _state(**overrides):
    values = {
        'period_s': 1.0,
        'counters': InputCounters(received=200, published=200, period_received=200),
        'last_sample_age_s': 0.01,
        'stale_after_s': 1.0,
        'temperature_age_s': None,
        'fallback_reason': '',
        'tare_zero_mv': None,
    }
    values.update(overrides)
    return LiveState(**values)


def test_diagnostics_report_rate_staleness_rejections_and_calibration():
    active = activate(MEMO, 'cubic', 'inverted')
    healthy = diagnostics(active, _state())
    assert [r.level for r in healthy] == [OK, OK, OK]  # input, calibration, overload
    values = dict(healthy[0].values) | dict(healthy[1].values)
    assert values['input_rate_hz'] == '200.0' and values['stale'] == 'False'
    assert values['model'] == 'cubic' and values['installation'].startswith('inverted')
    assert values['sigma_pct_fs'].startswith('FX=0.080')  # Table 17, cubic row
    assert values['requires'] == 'none' and values['age_days'] == 'unknown'

    stale = diagnostics(active, _state(last_sample_age_s=3.0))
    assert stale[0].level == STALE and 'stale' in stale[0].message
    assert diagnostics(active, _state(last_sample_age_s=None))[0].level == STALE
    rejected = diagnostics(
        active,
        _state(
            counters=InputCounters(
                received=10, rejected_nonfinite=3, period_rejected=3, period_out_of_envelope=2
            )
        ),
    )
    assert (
        rejected[0].level == WARN
        and '3 NaN/inf' in rejected[0].message
        and '2 samples outside' in rejected[0].message
    )

    temperature = activate(temperature_calibration(), 'adopted', 'upright')
    fallback = diagnostics(
        temperature, _state(fallback_reason='temperature input missing or stale')
    )
    values = dict(fallback[1].values)
    assert fallback[1].level == WARN and 'FALLBACK to linear' in fallback[1].message
    assert values['requires'] == 'temperature' and values['inputs'] == 'temperature: missing'
    assert values['model_in_use'] == 'linear'


def test_temperature_terms_act_on_the_change_since_the_zero_or_the_tare():
    """A zero (or a tare) at 25 °C zeroes the output there; at 27 °C the dT term adds 10 N/K x 2
    K.
    """
    active = activate(temperature_calibration(), 'adopted', 'balance')
    zero = np.full(6, 0.02)
    at_zero = compute_wrench(
        active, zero[None, :], zero_mv=zero, temperature_c=25.0, zero_temperature_c=25.0
    )
    np.testing.assert_allclose(at_zero.wrench_tunnel, np.zeros((1, 6)), atol=1e-9)
    later = compute_wrench(
        active, zero[None, :], zero_mv=zero, temperature_c=27.0, zero_temperature_c=25.0
    )
    np.testing.assert_allclose(later.wrench_tunnel, [[0, 0, 20.0, 0, 0, 0]], atol=1e-9)
    # load space
    tare_load = compute_wrench(active, zero[None, :], temperature_c=25.0).loads_total[0]
    later = compute_wrench(active, zero[None, :], tare_load=tare_load, temperature_c=27.0)
    np.testing.assert_allclose(later.wrench_tunnel, [[0, 0, 20.0, 0, 0, 0]], atol=1e-9)
