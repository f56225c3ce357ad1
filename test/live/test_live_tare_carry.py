"""A tare load outlives a change of calibration only when re-read by the new one (without ROS: the
session the node drives).

The tare load is the active calibration's reading of the model's weight, in the installation's
balance axes. Subtracting it after a refit, a model switch or an installation change mixes two
readings: the wind-off outputs then read f_new(V) - f_old(V_tare), not zero. So another model or
calibration content re-reads it from the wind-off outputs it was taken at, another installation
clears it, and either is said and persisted for the new owner.
"""

from dataclasses import replace
from types import SimpleNamespace

from live_cases import CAPACITY, MEMO, NOISE_MV, TRUTH
import numpy as np
import pytest
from tare_cases import session, take_tare, WEIGHT_BALANCE
import yaml

from balance_calib.calibration_file import save_calibration
from balance_calib.live.session import activate_file
from balance_calib.live.tare_store import calibration_sha256
from balance_calib.simulation.wind_on import wind_on_outputs

# the memo's TM-663 §10.2.2: mounted inverted, F_X, F_Y, M_Y and M_Z change sign in tunnel axes
INVERTED_SIGNS = np.array([-1.0, -1.0, 1.0, 1.0, -1.0, -1.0])


def outputs(load_balance, n=1, noise=False, seed=0):
    return wind_on_outputs(
        TRUTH,
        np.repeat(np.asarray(load_balance, float)[None], n, axis=0),
        electrical_zero_mv=0.0,
        noise_mv=NOISE_MV if noise else 0.0,
        seed=seed,
    )


def read(made, rows):
    """The published wrench (N, 6), tunnel axes, of raw outputs `rows`."""
    rows = np.atleast_2d(rows)
    return made.live.process(rows, 5 * 10**9 + np.arange(len(rows)) * 10**6, now_s=0.0).wrench


def switch_model(made, values, model):
    values['model'] = model
    made.validate({'model': model})
    made.apply({'model'})


def mutable_session(calibration, **parameters):
    made, lines = session(calibration, **parameters)
    values = {name: made.value(name) for name in ('model', 'installation', 'calibration_file')}
    fallback = made.value
    made.value = lambda name: values[name] if name in values else fallback(name)
    return made, lines, values


def test_a_model_switch_re_reads_the_tare_so_wind_off_still_reads_zero(calibration):
    made, lines, values = mutable_session(calibration)
    take_tare(made)
    tare_mean = made.live.tare.tare_outputs_mv.copy()
    cubic_tare = made.live.tare.tare_load.copy()
    switch_model(made, values, 'linear')
    said = [line for _, line in lines if 'tare load re-read' in line]
    assert len(said) == 1 and 'linear model' in said[0] and '(was ' in said[0], lines
    # linear model, loads = C (V - 0): the wind-off mean outputs read C (V - V) = 0 exactly, and a
    # wind-on sample reads C (V_on - V_tare), the linear map of the difference (no zero taken)
    linear = activate_file(str(calibration), made.value)
    np.testing.assert_allclose(read(made, tare_mean)[0], 0.0, atol=1e-9 * CAPACITY.max())
    wind_on = outputs(WEIGHT_BALANCE + np.array([0.02, 0.05, 0.1, 0.01, 0.03, 0.02]) * CAPACITY)
    expected = linear.installation.to_tunnel(
        linear.model.loads(wind_on - tare_mean)  # the six bridges in FXV..MZV order
    )
    np.testing.assert_allclose(read(made, wind_on), expected, atol=1e-9 * CAPACITY.max())
    # what the old calibration's tare would have left in the reading: the gap this closes
    left = np.abs(made.live.tare.tare_load - cubic_tare) / CAPACITY * 100
    assert left.max() > 0.05, left  # % FS: the memo's linear and cubic models differ at 0.3 FS
    # persisted for the linear model's owner: a restart with model linear restores it
    saved = yaml.safe_load((calibration.parent / 'calibration.tare.yaml').read_text())
    assert saved['format'] == 'balance_calib/tare 3'
    np.testing.assert_allclose(
        [saved['tare_load_balance_axes'][c] for c in ('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ')],
        made.live.tare.tare_load,
    )


def test_an_installation_change_at_run_time_clears_the_tare_load_and_keeps_the_zero(calibration):
    made, lines, values = mutable_session(calibration)
    zero = outputs(np.zeros(6), 50, noise=True, seed=3)
    assert made.start_window('zero', lambda: None) is None
    made.live.process(zero, 10**9 + np.arange(50) * 10**6, now_s=0.0)
    assert made.finish_window('zero', True, 1.0)[0]
    take_tare(made)
    zero_mv = made.live.tare.zero_mv.copy()
    values['installation'] = 'inverted'
    made.validate({'installation': 'inverted'})
    made.apply({'installation'})
    assert made.live.tare.tare_load is None
    np.testing.assert_array_equal(made.live.tare.zero_mv, zero_mv)
    warned = [line for level, line in lines if level == 'warning' and 'tare load cleared' in line]
    assert len(warned) == 1 and 'upright installation, now inverted' in warned[0], lines
    # the weight rolled with the balance: the untared load in the inverted tunnel axes, the truth
    inverted_load = np.array([0.0, 0.0, -0.3, 0.0, -0.05, 0.0]) * CAPACITY
    got = read(made, outputs(inverted_load) + zero_mv)[0]
    np.testing.assert_allclose(
        got / CAPACITY, INVERTED_SIGNS * inverted_load / CAPACITY, atol=1e-6
    )
    saved = yaml.safe_load((calibration.parent / 'calibration.tare.yaml').read_text())
    assert saved['tare_load_balance_axes'] is None and saved['zero_mv'] is not None
    assert saved['taken_for']['installation_name'] == 'inverted'


def refit_into(made, calibration, new_calibration):
    """A refit that replaced the calibration file in place, as run_refit_job reports one."""
    save_calibration(calibration, new_calibration)
    job = SimpleNamespace(calibration_file=calibration)
    new_active = activate_file(str(calibration), made.value)
    return made.finish_refit((job, (new_active, calibration, 'refit: sigma before/after ...')))


def stiffer(factor=1.02):
    """The memo's calibration with every cubic coefficient scaled: another calibration content."""
    cubic = MEMO.models['cubic']
    return replace(
        MEMO, models=MEMO.models | {'cubic': cubic.with_coefficients(cubic.coefficients * factor)}
    )


def test_a_refit_re_reads_the_tare_persists_it_and_a_restart_restores_it(calibration):
    made, lines = session(calibration)
    take_tare(made)
    tare_mean = made.live.tare.tare_outputs_mv.copy()
    old_tare = made.live.tare.tare_load.copy()
    ok, reply, switch_to = refit_into(made, calibration, stiffer(1.02))
    assert ok and switch_to is None and 'tare load re-read' in reply, reply
    # every coefficient ×1.02, no constant term: the re-read tare is 1.02 × f_old(V_tare),
    # the old one the mean of f_old over the window (a noise-order difference)
    np.testing.assert_allclose(
        made.live.tare.tare_load / CAPACITY, 1.02 * old_tare / CAPACITY, atol=1e-6
    )
    np.testing.assert_allclose(read(made, tare_mean)[0] / CAPACITY, 0.0, atol=1e-12)
    owner = yaml.safe_load((calibration.parent / 'calibration.tare.yaml').read_text())
    assert owner['taken_for']['calibration_sha256'] == calibration_sha256(calibration)
    again, lines = session(calibration)
    assert again.tare_refused == ''
    np.testing.assert_array_equal(again.live.tare.tare_load, made.live.tare.tare_load)


@pytest.mark.parametrize('how', ['older file', 'no load at the outputs'])
def test_a_tare_the_new_calibration_cannot_re_read_is_cleared_and_said(calibration, how):
    made, lines = session(calibration)
    take_tare(made)
    if how == 'older file':  # restored from a 'tare 2' file: its wind-off outputs not recorded
        path = calibration.parent / 'calibration.tare.yaml'
        data = yaml.safe_load(path.read_text())
        for key in ('tare_outputs_mv', 'tare_temperature_c', 'tare_direction'):
            del data[key]
        data['format'] = 'balance_calib/tare 2'
        path.write_text(yaml.safe_dump(data, sort_keys=False))
        made, lines = session(calibration)
        assert made.live.tare.tare_load is not None and made.live.tare.tare_outputs_mv is None
        new, why = stiffer(1.02), 'not recorded'
    else:  # a calibration whose bridges' range the wind-off outputs exceed: no load there
        new = replace(MEMO, rated_output_mv=MEMO.rated_output_mv * 1e-3)
        why = 'gives no load'
    ok, reply, _ = refit_into(made, calibration, new)
    assert ok and 'tare load cleared' in reply and why in reply, reply
    assert made.live.tare.tare_load is None
