"""balance_calibrator over real DDS: tare in load space with a model weight on the memo's cubic
balance, steadiness, restore after restart, overload, bad input counted, parameters refused,
namespaces, the refit in its own process.
"""

import os
import re
import threading

from calibrator_harness import (
    connected,
    Stamped,
    start_calibrator,
    window,
    wrench_values,
)
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from live_cases import CAPACITY, MEMO, model_weight_tunnel, show_run
import numpy as np
import pytest
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from ros_harness import NodeProcess, RELIABLE, wait_for
from std_msgs.msg import Bool
from std_srvs.srv import Trigger

from balance_calib.calibration_file import ConfigError, save_calibration
from balance_calib.live.calibrator_core import compute_wrench
from balance_calib.live.refit_process import RefitFailed, run_refit_in_process
from balance_calib.model.active_calibration import activate
from balance_calib.model.inverse import outputs_for_loads
from balance_calib.nodes.balance_calibrator import BalanceCalibrator
from balance_calib.tunnel_axes import INVERTED, UPRIGHT

pytestmark = pytest.mark.ros
LATCHED = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)


@pytest.mark.parametrize('installation', [UPRIGHT, INVERTED])
def test_model_weight_tared_wind_off_then_wind_on_reads_the_aerodynamic_load_within_0_1_pct_fs(
    probe, tmp_path, calibration_file, installation
):
    zero, wind_off, wind_on, aero = show_run(installation, samples_per_condition=40, seed=1)
    node = start_calibrator(
        probe, tmp_path, calibration_file, installation=installation.name, model='cubic'
    )
    wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
    source = Stamped(probe)
    connected(node, source)
    assert window(probe, node, source, 'zero', zero).success
    tare = window(probe, node, source, 'tare', wind_off)
    assert tare.success, tare.message
    stated = float(re.search(r'FZ=([-+0-9.]+) N', tare.message).group(1))
    # 0.3 FS, in N, tunnel axes
    assert abs(stated - model_weight_tunnel()[2]) < 0.001 * CAPACITY[2]
    wait_for(lambda: len(wrenches) == source.sent, 10.0, 'the wrenches of the two windows')
    before = len(wrenches)
    for condition in wind_on:
        for row in condition:
            source.send(row)
    wait_for(
        lambda: len(wrenches) == before + wind_on.shape[0] * wind_on.shape[1],
        20.0,
        'the wind-on wrenches',
    )
    read = wrench_values(wrenches[before:]).reshape(wind_on.shape).mean(axis=1)
    error_pct = np.abs(read - aero) / np.abs(installation.to_tunnel(CAPACITY)) * 100
    # noise 0.03 % FS per sample, 40 per condition, 100 in each window: σ of a mean error ≈ 0.006 %
    # FS
    assert error_pct.max() < 0.1, error_pct.max(axis=0)


def test_tare_refused_on_a_ramp_accepted_when_steady_restored_after_a_restart_and_cleared(
    probe, tmp_path, calibration_file
):
    zero, wind_off, _, _ = show_run(UPRIGHT)
    node = start_calibrator(probe, tmp_path, calibration_file)
    wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
    source = Stamped(probe)
    connected(node, source)
    ramp = wind_off + np.linspace(0.0, 0.3, len(wind_off))[:, None] * np.array(
        [0, 0, 1.0, 0, 0, 0]
    )
    refused = window(probe, node, source, 'tare', ramp)
    assert (
        not refused.success
        and 'not steady' in refused.message
        and 'FZ moved by' in refused.message
    )
    assert node.session.live.tare.tare_load is None
    accepted = window(probe, node, source, 'tare', wind_off)
    assert accepted.success and 'saved to' in accepted.message
    tare_load = node.session.live.tare.tare_load.copy()
    probe.retire(node)

    restarted = start_calibrator(probe, tmp_path, calibration_file)
    np.testing.assert_array_equal(restarted.session.live.tare.tare_load, tare_load)
    before = len(wrenches)

    def a_wrench_after_the_restart():  # the wind-off load again (until the new node is matched)
        source.send(wind_off.mean(axis=0))
        return len(wrenches) > before

    wait_for(a_wrench_after_the_restart, 20.0, 'a wrench from the restarted node', poll_s=0.05)
    # reads zero after the restored tare (to the second-order effect of the noise: mean f(V) vs
    # f(mean V))
    np.testing.assert_allclose(
        wrench_values(wrenches[-1:])[0] / np.abs(UPRIGHT.to_tunnel(CAPACITY)), 0.0, atol=1e-6
    )
    cleared = probe.call(Trigger, '/balance_calibrator/clear_tare')
    assert cleared.success and 'tare load removed' in cleared.message
    assert f'FZ={UPRIGHT.to_tunnel(tare_load)[2]:+.3f}' in cleared.message
    assert restarted.session.live.tare.tare_load is None


def test_overload_is_raised_latched_and_cleared_and_diagnostics_name_the_component(
    probe, tmp_path, calibration_file
):
    node = start_calibrator(
        probe, tmp_path, calibration_file, overload_fraction=0.8, overload_clear_s=0.3
    )
    probe.subscribe(WrenchStamped, '/balance/wrench')
    diagnostics = probe.subscribe(DiagnosticArray, '/diagnostics')
    source = Stamped(probe)
    connected(node, source)
    truth = MEMO.model('cubic').without_constant()
    loads = np.zeros((2, 6))
    loads[1, 2] = 0.85 * CAPACITY[2]  # F_Z at 0.85 of rated, limit 0.8
    safe, over = outputs_for_loads(truth, loads)
    source.send(safe)
    source.send(over)
    late = []  # a subscriber that joins after the event still gets the latched state
    wait_for(lambda: node.session.live.overload.active, 10.0, 'the overload')
    probe.node.create_subscription(Bool, '/balance/overload', late.append, LATCHED)
    wait_for(lambda: late and late[-1].data, 10.0, 'the latched overload=true')

    def overload_status():
        for array in reversed(diagnostics):
            status = array.status[2]
            if status.level == b'\x02' and 'FZ' in status.message:
                return status

    wait_for(overload_status, 10.0, 'an ERROR naming FZ')
    source.stream(200.0)  # now inside, for more than overload_clear_s
    wait_for(lambda: late and not late[-1].data, 10.0, 'overload=false after 0.3 s inside')
    source.stop()


def test_bad_live_input_is_counted_and_reported_and_never_published_as_a_number(
    probe, tmp_path, calibration_file
):
    node = start_calibrator(probe, tmp_path, calibration_file)
    wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
    diagnostics = probe.subscribe(DiagnosticArray, '/diagnostics')
    source = Stamped(probe)
    connected(node, source)
    good = (0.1, 0.2, 0.3, 0.1, 0.2, 0.1)
    stamps = 10**9 + np.arange(300) * 10**6  # 1 kHz
    for k in range(100):
        source.send(good, stamps[k])
    for k in range(200, 220):  # 100 samples lost
        source.send(good, stamps[k])
    source.send(good, stamps[210])  # out of order
    source.send(good, stamps[219])  # duplicate
    source.send(good, 0)  # zero stamp
    source.send(good, stamps[220], frame_id='B660H')  # another balance
    # saturated
    for k, outputs in enumerate(
        ((1e103, 0, 0, 0, 0, 0), (0, 0, 1e90, 0, 0, 0), (0, 9.0, 0, 0, 0, 0))
    ):
        source.send(outputs, stamps[221 + k])
    sent = source.sent

    def counted():
        for array in reversed(diagnostics):
            values = {kv.key: kv.value for kv in array.status[0].values}
            if values.get('samples_received') == str(sent):
                return array.status[0], values

    status, values = wait_for(counted, 10.0, 'diagnostics counting every sample')
    # The totals are named _since_start (beside the diagnostics period's _last_period)
    assert values['samples_lost_since_start'] == '100', str(values)
    assert values['stamps_out_of_order_since_start'] == '1'
    assert values['duplicate_stamps_since_start'] == '1'
    assert values['zero_stamps_since_start'] == '1'
    assert values['samples_from_another_balance_since_start'] == '1'
    assert 'B660H' in values['frame_ids_seen_from_other_balances']
    assert values['saturated'] == '3' and values['wrenches_published'] == str(sent - 3)
    assert np.all(np.abs(wrench_values(wrenches)) < 10 * CAPACITY.max())
    assert any(
        a.status[0].level == b'\x02' and 'saturated' in a.status[0].message for a in diagnostics
    )


@pytest.mark.parametrize(
    'name,value',
    [
        ('tare_timeout_s', float('inf')),
        ('diagnostics_period_s', float('inf')),
        ('diagnostics_period_s', 0.0),
        ('diagnostics_period_s', -1.0),
        ('tare_samples', 0),
        ('tare_samples', -5),
        ('envelope_margin', 1e-9),
        ('overload_fraction', float('nan')),
        ('calibration_file', '/dev/zero'),
        ('calibration_file', 'FIFO'),
    ],
)
def test_bad_parameters_at_start_up_are_refused_with_a_reason(probe, tmp_path, name, value):
    if value == 'FIFO':
        value = str(tmp_path / 'calibration.fifo')
        os.mkfifo(value)
    with pytest.raises(
        ConfigError, match=name if name != 'calibration_file' else 'not a calibration file|is a'
    ):
        BalanceCalibrator(
            context=probe.context, parameter_overrides=[Parameter(name, value=value)]
        )


def test_bad_parameters_at_runtime_are_refused_and_the_node_keeps_streaming(
    probe, tmp_path, calibration_file
):
    node = start_calibrator(probe, tmp_path, calibration_file)
    for name, value in (
        ('tare_timeout_s', float('inf')),
        ('diagnostics_period_s', 0.0),
        ('tare_samples', -5),
        ('envelope_margin', 1e-9),
        ('lowpass_hz', float('nan')),
        ('calibration_file', '/dev/zero'),
    ):
        result = node.set_parameters([Parameter(name, value=value)])[0]
        assert not result.successful and result.reason, (name, value)
    wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
    source = Stamped(probe)
    connected(node, source)
    source.send((0.1,) * 6)
    wait_for(lambda: len(wrenches) >= 1, 10.0, 'a wrench after the refused parameters')
    assert node.session.live.settings.stale_after_s == 1.0 and node.session.live.active.envelope[
        0
    ] == pytest.approx(1.1 * 980)


def test_two_namespaced_calibrators_keep_their_streams_apart(probe, tmp_path, calibration_file):
    nodes = {
        side: NodeProcess(
            'balance_calibrator',
            probe.domain_id,
            tmp_path / side,
            {'calibration_file': str(calibration_file), 'installation': installation},
            extra_args=['-r', f'__ns:=/{side}'],
        )
        for side, installation in (('left', 'upright'), ('right', 'inverted'))
    }
    try:
        received = {
            side: probe.subscribe(WrenchStamped, f'/{side}/balance/wrench') for side in nodes
        }
        root = probe.subscribe(WrenchStamped, '/balance/wrench')
        sources = {side: Stamped(probe, f'/{side}/balance/raw') for side in nodes}
        for side in nodes:
            wait_for(
                lambda: sources[side].publisher.get_subscription_count() >= 1,
                30.0,
                f'/{side} calibrator',
            )
            sub = [
                s for s in probe.node.subscriptions if s.topic_name == f'/{side}/balance/wrench'
            ][0]
            wait_for(lambda: sub.get_publisher_count() >= 1, 30.0, f'/{side}/balance/wrench')
        outputs = {
            'left': np.array([0.2, 0.1, 0.4, 0.0, -0.2, 0.1]),
            'right': np.array([-0.3, 0.2, 0.1, 0.1, 0.3, 0.0]),
        }

        # keep sending until each side has 20 (the first may go before matching)
        def twenty_each():
            for side in nodes:
                k = sources[side].sent
                sources[side].send(outputs[side] * (1 + k / 100), stamp_ns=10**9 + k * 10**6)
            return all(len(received[s]) >= 20 for s in nodes)

        wait_for(twenty_each, 30.0, 'both streams', poll_s=0.01)
        for side, installation in (('left', 'upright'), ('right', 'inverted')):
            messages = list(received[side])
            k = np.array([(m.header.stamp.nanosec // 10**6) for m in messages])
            expected = compute_wrench(
                activate(MEMO, 'adopted', installation), outputs[side] * (1 + k[:, None] / 100)
            ).wrench_tunnel
            np.testing.assert_allclose(wrench_values(messages), expected, rtol=1e-12, atol=1e-12)
        assert root == []
        reply = probe.call(Trigger, '/left/balance_calibrator/clear_tare')
        assert reply.success
    finally:
        for node in nodes.values():
            node.stop()


def test_refit_in_its_own_process_replies_the_pipelines_reason_and_keeps_the_calibration(
    probe, tmp_path, calibration_file
):
    # no injected refit: the real pipeline
    node = start_calibrator(probe, tmp_path, calibration_file)
    empty_bag = tmp_path / 'campaign'
    before = calibration_file.read_bytes()
    reply = probe.call(Trigger, '/balance_calibrator/refit', timeout_s=120.0)
    assert not reply.success and 'stays in force' in reply.message
    # the pipeline names the bag
    assert str(empty_bag) in reply.message or 'campaign' in reply.message
    assert calibration_file.read_bytes() == before and node.session.live.active.source == str(
        calibration_file
    )


def test_a_refit_process_killed_mid_way_is_a_failure_with_the_reason(tmp_path):
    killed = threading.Event()

    def kill(pid):
        os.kill(pid, 9)
        killed.set()

    with pytest.raises(RefitFailed, match='killed by signal SIGKILL'):
        run_refit_in_process(
            [tmp_path],
            'lmc6522',
            tmp_path / 'out',
            'cubic',
            progress=lambda line: None,
            timeout_s=60.0,
            started=kill,
        )
    assert killed.is_set()


def test_input_qos_is_set_through_rclpys_standard_qos_overrides(probe, tmp_path, calibration_file):
    node = start_calibrator(
        probe,
        tmp_path,
        calibration_file,
        **{
            'qos_overrides./balance/raw.subscription.reliability': 'best_effort',
            'qos_overrides./balance/raw.subscription.depth': 7,
        },
    )
    assert node._raw_input.subscription.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
    assert node._raw_input.subscription.qos_profile.depth == 7
    # untouched: the default
    assert node._wrench_pub.qos_profile.reliability == ReliabilityPolicy.RELIABLE


def test_wrench_uncertainty_is_published_beside_each_wrench(probe, tmp_path):
    from live_cases import calibration_with_covariance

    from balance_calib.live.stream import wrench_uncertainty

    path = tmp_path / 'calibration.yaml'
    save_calibration(path, calibration_with_covariance())
    node = start_calibrator(probe, tmp_path, path, model='cubic')
    wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
    uncertainties = probe.subscribe(WrenchStamped, '/balance/wrench_uncertainty')
    source = Stamped(probe)
    connected(node, source)
    wait_for(
        lambda: node._uncertainty_pub.get_subscription_count() >= 1, 10.0, 'the uncertainty topic'
    )
    outputs = np.array([[0.2, -0.1, 0.3, 0.05, -0.2, 0.1], [0.1, 0.2, -0.3, 0.0, 0.1, -0.1]])
    for row in outputs:
        source.send(row)
    wait_for(
        lambda: len(uncertainties) == 2 and len(wrenches) == 2,
        10.0,
        'two wrenches and their uncertainties',
    )
    assert [m.header.stamp for m in uncertainties] == [m.header.stamp for m in wrenches]
    expected = wrench_uncertainty(node.session.live.active, outputs, None)
    np.testing.assert_allclose(wrench_values(uncertainties), expected, rtol=1e-12)
    assert np.all(expected > 0) and np.all(expected < 0.01 * CAPACITY.max())


def test_uncertainty_is_computed_while_someone_subscribes_and_stops_when_they_leave(
    probe, tmp_path
):
    """The node keeps the count of uncertainty readers from the publisher's matched events (no rmw
    query per batch once one matched); a reader arriving or leaving mid-stream is heard.
    """
    from live_cases import calibration_with_covariance

    path = tmp_path / 'calibration.yaml'
    save_calibration(path, calibration_with_covariance())
    node = start_calibrator(probe, tmp_path, path, model='cubic')
    wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
    source = Stamped(probe)
    connected(node, source)
    live = node.session.live

    def one_sample(expect_uncertainty: bool):
        before = len(wrenches)
        source.send((0.2, -0.1, 0.3, 0.05, -0.2, 0.1))
        wait_for(lambda: len(wrenches) == before + 1, 10.0, 'the wrench')
        assert live.uncertainty_wanted is expect_uncertainty

    one_sample(False)  # nobody reads balance/wrench_uncertainty: not computed
    assert node._uncertainty_readers == 0
    uncertainties = []
    reader = probe.node.create_subscription(
        WrenchStamped, '/balance/wrench_uncertainty', uncertainties.append, RELIABLE
    )
    wait_for(
        lambda: node._uncertainty_readers == 1,
        10.0,
        'the matched event of the uncertainty publisher',
    )
    one_sample(True)
    wait_for(lambda: len(uncertainties) == 1, 10.0, 'the uncertainty')
    assert uncertainties[0].header.stamp == wrenches[-1].header.stamp
    probe.node.destroy_subscription(reader)
    wait_for(lambda: node._uncertainty_readers == 0, 10.0, 'the unmatched event')
    one_sample(False)
    assert len(uncertainties) == 1


@pytest.mark.slow
def test_refit_process_killed_with_sigkill_keeps_the_calibration_and_the_stream(
    probe, tmp_path, calibration_file, campaigns
):
    import multiprocessing

    bag = campaigns.bag(seed=5, recipe='dds', noise=None)
    node = start_calibrator(probe, tmp_path, calibration_file, calibration_bags=[str(bag)])
    wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
    source = Stamped(probe)
    connected(node, source)
    before = calibration_file.read_bytes()
    reply = probe.call_async(Trigger, '/balance_calibrator/refit')
    child = wait_for(
        lambda: [p for p in multiprocessing.active_children() if p.name == 'balance_calib refit'],
        30.0,
        'the refit process',
    )[0]
    os.kill(child.pid, 9)
    wait_for(reply.done, 30.0, 'the refit reply')
    assert not reply.result().success and 'killed by signal SIGKILL' in reply.result().message
    assert 'stays in force' in reply.result().message and calibration_file.read_bytes() == before
    count = len(wrenches)
    source.send()
    wait_for(lambda: len(wrenches) > count, 10.0, 'a wrench after the killed refit')


def test_an_integer_for_a_float_parameter_is_that_number(probe, tmp_path, calibration_file):
    node = BalanceCalibrator(
        context=probe.context,
        parameter_overrides=[
            Parameter('calibration_file', value=str(calibration_file)),
            Parameter('tare_timeout_s', value=5),
            Parameter('tare_file', value=str(tmp_path / 'tare.yaml')),
        ],
    )
    try:
        assert node.get_parameter('tare_timeout_s').value == 5.0
    finally:
        node.destroy_node()
