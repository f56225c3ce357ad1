"""balance_calibrator over real DDS: the stream through a refit, bad input, parameters, start-up
errors.

Most tests run the node in the test process (so a refit function can be injected that blocks until
the test lets it finish); samples still travel over DDS on loopback in the test's own domain.
"""

from dataclasses import replace
from pathlib import Path
import threading

from calibrator_harness import (
    connected,
    MEMO,
    RawSource,
    SAMPLE_MV,
    start_calibrator,
    wrench_values,
)
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
import numpy as np
import pytest
from rcl_interfaces.msg import ParameterType
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from ros_harness import new_domain_id, NodeProcess, RELIABLE, wait_for
from sensor_msgs.msg import Temperature
from std_srvs.srv import Trigger

from balance_calib.calibration_file import load_calibration, save_calibration

pytestmark = pytest.mark.ros


class FakeResult:
    def __init__(self, calibration, out_dir):
        self.calibration = calibration
        self.calibration_path = Path(out_dir) / 'calibration.yaml'
        self.report = {}
        self.summary = 'sigma before FX=0.080 after FX=0.040 % FS; effects: none'


class BlockingRefit:
    """A refit that waits for the test's go-ahead, then returns the memo with a doubled cubic
    matrix.
    """

    def __init__(self, error: Exception | None = None):
        self.started, self.release, self.error, self.calls = (
            threading.Event(),
            threading.Event(),
            error,
            [],
        )
        cubic = MEMO.models['cubic']
        doubled = cubic.with_coefficients(2 * cubic.coefficients)
        self.calibration = replace(
            MEMO, models={**MEMO.models, 'cubic': doubled}, fitted_at='2026-11-20T00:00:00Z'
        )

    def __call__(self, bag_paths, balance, out_dir, settings):
        self.calls.append((list(bag_paths), balance, Path(out_dir), settings.model))
        settings.progress('reading bags')
        self.started.set()
        assert self.release.wait(30.0), 'the test never released the refit'
        if self.error is not None:
            raise self.error
        return FakeResult(self.calibration, out_dir)


def test_stream_keeps_flowing_through_a_refit_and_the_new_calibration_takes_over_between_samples(
    probe, tmp_path, calibration_file
):
    refit = BlockingRefit()
    node = start_calibrator(probe, tmp_path, calibration_file, refit)
    wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
    source = RawSource(probe)
    connected(node, source)
    source.stream(200.0)
    wait_for(lambda: len(wrenches) >= 20, 10.0, 'wrenches before the refit')
    reply = probe.call_async(Trigger, '/balance_calibrator/refit')
    wait_for(refit.started.is_set, 10.0, 'the refit to start')
    during = len(wrenches)
    # the refit is blocked: 200 more samples (1 s at 200 Hz) must still come through
    wait_for(lambda: len(wrenches) >= during + 200, 10.0, 'wrenches while the refit runs')
    assert not reply.done()
    refit.release.set()
    wait_for(reply.done, 10.0, 'the refit reply')
    after_reply = len(wrenches)
    assert reply.result().success, reply.result().message
    assert 'refit OK' in reply.result().message and 'FX=0.080' in reply.result().message
    wait_for(lambda: len(wrenches) >= after_reply + 20, 10.0, 'wrenches after the refit')
    source.stop()
    wait_for(lambda: len(wrenches) == source.sent, 10.0, f'count out = count in ({source.sent})')

    # every wrench is the old or the new calibration's reading, old ones first: a clean swap
    values = wrench_values(wrenches)
    old, new = values[0], values[-1]
    np.testing.assert_allclose(new, 2 * old, rtol=1e-12)
    is_old = np.all(np.isclose(values, old, rtol=1e-12), axis=1)
    is_new = np.all(np.isclose(values, new, rtol=1e-12), axis=1)
    assert np.all(is_old | is_new)
    switch = np.argmax(is_new)
    assert np.all(is_old[:switch]) and np.all(is_new[switch:]) and switch >= during + 200
    # calibration_file was replaced (atomically: no temporary file left) by the refit's calibration
    np.testing.assert_array_equal(
        load_calibration(calibration_file).models['cubic'].coefficients,
        refit.calibration.models['cubic'].coefficients,
    )
    assert (
        sorted(p.name for p in calibration_file.parent.iterdir() if p.name.startswith('.')) == []
    )
    bags, balance, out_dir, model = refit.calls[0]
    assert bags == [tmp_path / 'campaign'] and balance == 'lmc6522' and model == 'cubic'
    assert out_dir.parent == tmp_path / 'reports'


@pytest.mark.parametrize('problem', ['refit_error', 'missing_bag', 'no_bags'])
def test_failed_refit_says_why_and_keeps_the_previous_calibration(
    probe, tmp_path, calibration_file, problem
):
    error = ValueError(
        f'{tmp_path}/campaign: no /calibration/gravity messages before the first load point'
    )
    refit = BlockingRefit(error if problem == 'refit_error' else None)
    refit.release.set()
    node = start_calibrator(probe, tmp_path, calibration_file, refit)
    if problem == 'missing_bag':
        node.set_parameters([Parameter('calibration_bags', value=[str(tmp_path / 'no_such_bag')])])
    if problem == 'no_bags':
        node.set_parameters([Parameter('calibration_bags', Parameter.Type.STRING_ARRAY, [])])
    before = calibration_file.read_bytes()
    wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
    source = RawSource(probe)
    connected(node, source)
    source.send()
    wait_for(lambda: len(wrenches) == 1, 10.0, 'a wrench')
    reply = probe.call(Trigger, '/balance_calibrator/refit')
    assert not reply.success
    expected = {
        'refit_error': 'no /calibration/gravity messages',
        'missing_bag': 'no_such_bag does not exist',
        'no_bags': 'calibration_bags is empty',
    }[problem]
    assert (
        expected in reply.message
        and 'stays in force' in reply.message
        and str(calibration_file) in reply.message
    )
    source.send()
    wait_for(lambda: len(wrenches) == 2, 10.0, 'a wrench after the failed refit')
    np.testing.assert_array_equal(wrench_values(wrenches)[1], wrench_values(wrenches)[0])
    assert calibration_file.read_bytes() == before
    # bad parameters never reach the refit
    assert len(refit.calls) == (1 if problem == 'refit_error' else 0)


def test_nan_samples_are_rejected_counted_and_reported(probe, tmp_path, calibration_file):
    node = start_calibrator(probe, tmp_path, calibration_file)
    wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
    diagnostics = probe.subscribe(DiagnosticArray, '/diagnostics')
    source = RawSource(probe)
    connected(node, source)
    for outputs in (SAMPLE_MV, (np.nan,) * 6, SAMPLE_MV, (0.0, np.inf, 0, 0, 0, 0), SAMPLE_MV):
        source.send(outputs)
    wait_for(lambda: len(wrenches) == 3, 10.0, 'the three valid wrenches')

    def rejected_report():
        for array in reversed(diagnostics):
            values = {kv.key: kv.value for kv in array.status[0].values}
            if values.get('rejected_nonfinite') == '2':
                return array.status[0], values

    status, values = wait_for(rejected_report, 10.0, 'diagnostics counting 2 rejected samples')
    assert values['samples_received'] == '5' and values['wrenches_published'] == '3'
    assert any(a.status[0].level == b'\x01' and 'NaN' in a.status[0].message for a in diagnostics)
    assert np.all(np.isfinite(wrench_values(wrenches)))


def test_tare_subtracts_the_wind_off_load_and_says_what_it_subtracted(
    probe, tmp_path, calibration_file
):
    node = start_calibrator(probe, tmp_path, calibration_file, tare_samples=10, tare_timeout_s=1.0)
    wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
    source = RawSource(probe)
    connected(node, source)
    timed_out = probe.call(Trigger, '/balance_calibrator/tare')  # no samples at all
    assert not timed_out.success and 'only 0 of 10' in timed_out.message
    node.set_parameters([Parameter('tare_timeout_s', value=10.0)])
    reply = probe.call_async(Trigger, '/balance_calibrator/tare')
    source.stream(200.0)
    wait_for(reply.done, 10.0, 'the tare reply')
    # the load of the wind-off outputs with the cubic model on the full outputs, in tunnel axes
    # (upright)
    from balance_calib.live.calibrator_core import compute_wrench
    from balance_calib.model.active_calibration import activate

    expected = compute_wrench(activate(MEMO, 'adopted', 'upright'), [SAMPLE_MV]).wrench_tunnel[0]
    assert reply.result().success, reply.result().message
    assert (
        f'FX={expected[0]:+.3f} N' in reply.result().message
        and f'MZ={expected[5]:+.3f} N·m' in reply.result().message
    )
    count = len(wrenches)
    wait_for(lambda: len(wrenches) >= count + 5, 10.0, 'wrenches after the tare')
    source.stop()
    np.testing.assert_allclose(wrench_values(wrenches)[-1], 0.0, atol=1e-9)
    assert (tmp_path / 'calibration.tare.yaml').exists()  # persisted beside the calibration


def test_bad_parameters_are_rejected_with_a_reason_and_good_ones_applied(
    probe, tmp_path, calibration_file
):
    node = start_calibrator(probe, tmp_path, calibration_file)
    wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
    source = RawSource(probe)
    connected(node, source)
    client = AsyncParameterClient(probe.node, 'balance_calibrator')
    assert client.wait_for_services(10.0)
    corrupt = tmp_path / 'corrupt.yaml'
    corrupt.write_text('models: {cubic: [1, 2\n')

    def set_parameter(name, value):
        future = client.set_parameters([Parameter(name, value=value)])
        wait_for(future.done, 10.0, f'setting {name}')
        return future.result().results[0]

    rejected = {
        'model': ('quartic', "no 'quartic' model"),
        'installation': ('sideways', "installation 'sideways'"),
        'calibration_file': (str(tmp_path / 'missing.yaml'), 'missing.yaml: cannot read'),
        'tare_samples': (0, 'out of range'),
        'diagnostics_period_s': (float('inf'), 'out of range'),
    }
    for name, (value, reason) in rejected.items():
        result = set_parameter(name, value)
        assert not result.successful and reason in result.reason, (name, result.reason)
    result = set_parameter('calibration_file', str(corrupt))
    assert not result.successful and 'corrupt.yaml' in result.reason
    source.send()
    wait_for(lambda: len(wrenches) == 1, 10.0, 'a wrench with the old settings')
    assert set_parameter('installation', 'inverted').successful
    source.send()
    wait_for(lambda: len(wrenches) == 2, 10.0, 'a wrench with the new installation')
    upright, inverted = wrench_values(wrenches)
    # §10.2.1 vs §10.2.2
    np.testing.assert_allclose(inverted, upright * [1, -1, -1, 1, -1, -1], rtol=1e-12)
    get = client.get_parameters(['model', 'installation'])
    wait_for(get.done, 10.0, 'parameters')
    assert [v.string_value for v in get.result().values] == ['adopted', 'inverted']
    assert get.result().values[0].type == ParameterType.PARAMETER_STRING


def test_temperature_model_falls_back_to_its_base_when_temperature_is_missing(probe, tmp_path):
    from live_cases import temperature_calibration

    path = tmp_path / 'calibration.yaml'
    save_calibration(path, temperature_calibration())
    node = start_calibrator(probe, tmp_path, path, installation='balance', stale_after_s=0.5)
    wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
    diagnostics = probe.subscribe(DiagnosticArray, '/diagnostics')
    source = RawSource(probe)
    temperature = probe.node.create_publisher(Temperature, '/balance/temperature', RELIABLE)
    connected(node, source)
    wait_for(
        lambda: temperature.get_subscription_count() >= 1, 10.0, 'the temperature subscription'
    )
    source.send()
    wait_for(lambda: len(wrenches) == 1, 10.0, 'a wrench without temperature')
    temperature.publish(Temperature(temperature=25.0))

    def calibration_status(predicate):
        for array in reversed(diagnostics):
            if predicate(array.status[1]):
                return array.status[1]

    assert (
        'FALLBACK to linear'
        in wait_for(
            lambda: calibration_status(lambda s: 'FALLBACK' in s.message),
            10.0,
            'a fallback report',
        ).message
    )
    wait_for(
        lambda: calibration_status(
            lambda s: 'temperature: fresh' in str([kv.value for kv in s.values])
        ),
        10.0,
        'fresh temperature in diagnostics',
    )
    source.send()
    wait_for(lambda: len(wrenches) == 2, 10.0, 'a wrench with temperature')
    without, with_temperature = wrench_values(wrenches)
    # 10 N/K x 5 K
    np.testing.assert_allclose(with_temperature - without, [0, 0, 50.0, 0, 0, 0], atol=1e-9)


def test_corrupt_calibration_file_at_start_up_exits_non_zero_naming_the_file(tmp_path):
    corrupt = tmp_path / 'broken_calibration.yaml'
    corrupt.write_text(
        'format: balance_calib/calibration 1\nmodels:\n  cubic: {terms: [FXV], coefficients: 3}\n'
    )
    node = NodeProcess(
        'balance_calibrator', new_domain_id(), tmp_path, {'calibration_file': str(corrupt)}
    )
    try:
        assert node.wait(30.0) == 1
        assert 'broken_calibration.yaml' in node.output() and 'cannot start' in node.output()
    finally:
        node.stop()
