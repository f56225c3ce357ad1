"""End to end over DDS (TM-663 §10.3): bridge_publisher flies the replica Euler model through a
wind-off α/φ sweep and a wind-on α sweep on the simulated LMC6522 (memo cubic matrix as truth, the
model's weight at each attitude, the sting's deflection); balance_calibrator (memo cubic, no tare)
publishes /balance/wrench; aero_coefficients reduces it live while balance_recorder records the
run, and `balance-calib reduce` reduces the bag offline. Live and offline agree to 1e-9, and both
agree with the true coefficients within the uncertainty propagated from the calibration's own σ.
"""

import csv

from geometry_msgs.msg import Vector3Stamped, WrenchStamped
import numpy as np
import pytest
from ros_harness import new_domain_id, NodeProcess, Probe, wait_for
from sensor_msgs.msg import FluidPressure

from balance_calib.cli import main as cli_main
from balance_calib.launchless.aero_story import aero_executable

pytestmark = [pytest.mark.ros, pytest.mark.slow]
COEFFICIENTS = ['CAF', 'CY', 'CN', 'Cl', 'Cm', 'Cn', 'CD', 'CL']
ALPHAS = 13  # -2 ... 22 in steps of 2


def six(msg):
    w = msg.wrench
    return np.array([w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z])


@pytest.mark.parametrize('installation', ['upright', 'inverted'])
def test_live_and_offline_reduction_agree_and_match_the_truth(tmp_path, installation):
    probe = Probe(new_domain_id())
    points = probe.subscribe(WrenchStamped, '/aero/point')
    points_wind = probe.subscribe(WrenchStamped, '/aero/point_wind')
    uncertainty = probe.subscribe(WrenchStamped, '/aero/point_uncertainty')
    attitudes = probe.subscribe(Vector3Stamped, '/aero/point_attitude')
    per_sample = probe.subscribe(WrenchStamped, '/aero/coefficients')
    truth = probe.subscribe(WrenchStamped, '/aero/truth')
    # the publisher waits for 3 subscribers on each:
    probe.subscribe(WrenchStamped, '/balance/raw')
    # calibrator or aero_coefficients, recorder, probe
    probe.subscribe(Vector3Stamped, '/model/attitude')
    probe.subscribe(FluidPressure, '/tunnel/dynamic_pressure')
    bag = tmp_path / 'run'
    # the calibrator as it is, without a tare: a tare file of its own that does not exist yet
    nodes = [
        NodeProcess(
            'balance_calibrator',
            probe.domain_id,
            tmp_path,
            {
                'installation': installation,
                'model': 'cubic',
                'tare_file': str(tmp_path / 'no_tare.yaml'),
            },
        ),
        NodeProcess(
            aero_executable(tmp_path),
            probe.domain_id,
            tmp_path,
            {
                'model': 'euler_replica_lmc6522',
                'estimate_weight': True,
                'calibration_file': 'lmc6522',
                'installation': installation,
            },
        ),
        NodeProcess(
            'balance_recorder',
            probe.domain_id,
            tmp_path,
            {
                'output': str(bag),
                'topics': [
                    '/balance/raw',
                    '/model/attitude',
                    '/tunnel/dynamic_pressure',
                    '/aero/truth',
                    '/aero/truth_wind',
                    '/balance/wrench',
                ],
            },
        ),
    ]
    publisher = None
    try:
        for topic in ('/balance/wrench', '/model/attitude'):
            wait_for(
                lambda: probe.node.count_subscribers(topic) >= 1, 60.0, f'a subscriber on {topic}'
            )
        publisher = NodeProcess(
            'bridge_publisher',
            probe.domain_id,
            tmp_path,
            {
                'mode': 'wind_on',
                'aero_model': 'euler_replica_lmc6522',
                'installation': installation,
                'dynamic_pressure_pa': 50000.0,
                'rate_hz': 100.0,
                'hold_s': 0.5,
                'wind_off_hold_s': 0.3,
                'electrical_zero_mv': 0.0,  # the calibrator's ~/zero was taken before the model
                #   went
                #   on
                'seed': 7,
                'exit_when_done': True,
                'wait_for_subscribers': 3,
                'start_delay_s': 2.0,
            },
        )
        assert publisher.wait(120.0) == 0, publisher.output()
        wait_for(
            lambda: (
                len(points) == ALPHAS and len(attitudes) == ALPHAS and len(uncertainty) == ALPHAS
            ),
            60.0,
            'the 13 held points of the live reduction',
        )
    finally:
        if publisher is not None:
            publisher.stop()
        outputs = {n.name: n.output() for n in nodes}
        print(outputs)  # shown by pytest when the test fails
        for node in reversed(nodes):  # the recorder first: it closes the bag
            node.stop()
        probe.close()
    assert len(per_sample) == ALPHAS * 50, outputs  # every wind-on sample reduced live
    out = tmp_path / 'out'
    assert (
        cli_main(
            [
                'reduce',
                str(bag),
                '--calibration',
                'lmc6522',
                '--model',
                'euler_replica_lmc6522',
                '--estimate-weight',
                '--installation',
                installation,
                # the live node cannot know the post-run sweep: the pre-run zero throughout
                '--zero-drift',
                'none',
                '--out',
                str(out),
            ]
        )
        == 0
    )
    with open(out / 'coefficients.csv', newline='') as handle:
        rows = list(csv.DictReader(handle))
    offline = np.array([[float(r[c]) for c in COEFFICIENTS] for r in rows])
    live = np.array(
        [np.concatenate([six(b), six(w)[[0, 2]]]) for b, w in zip(points, points_wind)]
    )
    live_alpha = np.degrees([a.vector.y for a in attitudes])
    assert len(rows) == ALPHAS
    assert np.max(np.abs(live - offline)) < 1e-9, outputs
    assert np.max(np.abs(live_alpha - np.array([float(r['alpha_deg']) for r in rows]))) < 1e-9
    # the truth at each point (its stamp is that of its last sample) against the reduction, in
    # units of u
    true_by_stamp = {(m.header.stamp.sec, m.header.stamp.nanosec): six(m) for m in truth}
    true_body = np.array(
        [true_by_stamp[(m.header.stamp.sec, m.header.stamp.nanosec)] for m in points]
    )
    u = np.array([six(m) for m in uncertainty])
    ratio = np.abs(live[:, :6] - true_body) / u
    assert np.max(ratio) < 4.5, ratio.max(axis=0)


def test_take_point_service_averages_the_next_samples_of_a_held_attitude(tmp_path):
    from std_srvs.srv import Trigger

    probe = Probe(new_domain_id())
    points = probe.subscribe(WrenchStamped, '/aero/point')
    scatter = probe.subscribe(WrenchStamped, '/aero/point_scatter')
    uncertainty = probe.subscribe(WrenchStamped, '/aero/point_uncertainty')
    per_sample = probe.subscribe(WrenchStamped, '/aero/coefficients')
    truth = probe.subscribe(WrenchStamped, '/aero/truth')
    probe.subscribe(WrenchStamped, '/balance/raw')
    probe.subscribe(Vector3Stamped, '/model/attitude')
    probe.subscribe(FluidPressure, '/tunnel/dynamic_pressure')
    nodes = [
        NodeProcess(
            'balance_calibrator',
            probe.domain_id,
            tmp_path,
            {'model': 'cubic', 'tare_file': str(tmp_path / 'no_tare.yaml')},
        ),
        NodeProcess(
            aero_executable(tmp_path),
            probe.domain_id,
            tmp_path,
            {'model': 'euler_replica_lmc6522', 'take_point_samples': 40},
        ),
    ]
    publisher = None
    replies = []
    try:
        for topic in ('/balance/wrench', '/model/attitude'):
            wait_for(
                lambda: probe.node.count_subscribers(topic) >= 1, 60.0, f'a subscriber on {topic}'
            )
        publisher = NodeProcess(
            'bridge_publisher',
            probe.domain_id,
            tmp_path,
            {
                'mode': 'wind_on',
                'aero_model': 'euler_replica_lmc6522',
                'rate_hz': 100.0,
                'hold_s': 2.0,
                'alpha_step_deg': 8.0,
                'wind_off_hold_s': 0.3,
                'electrical_zero_mv': 0.0,
                'seed': 9,
                'exit_when_done': True,
                'wait_for_subscribers': 2,
                'start_delay_s': 2.0,
            },
        )
        wait_for(lambda: len(per_sample) > 0, 60.0, 'the wind-on samples')
        # a request that meets the end of a hold fails; the next lands in a fresh one
        for _ in range(3):
            replies.append(probe.call(Trigger, '/aero_coefficients/take_point', timeout_s=30.0))
            if replies[-1].success:
                break
        assert publisher.wait(120.0) == 0, publisher.output()
        wait_for(
            lambda: len(points) == 5 and len(uncertainty) == 5,
            30.0,
            'four automatic points and the requested one',
        )
    finally:
        if publisher is not None:
            publisher.stop()
        for node in nodes:
            node.stop()
        probe.close()
    assert replies[-1].success and '40 samples at α =' in replies[-1].message, [
        r.message for r in replies
    ]
    assert all('changed after' in r.message for r in replies[:-1])
    stamps = {(m.header.stamp.sec, m.header.stamp.nanosec) for m in points}
    assert len(stamps) == 5  # the requested point ends on its 40th sample, not with its hold
    assert all(np.all(np.isfinite(six(m))) and np.all(six(m) >= 0) for m in scatter)
    true_by_stamp = {(m.header.stamp.sec, m.header.stamp.nanosec): six(m) for m in truth}
    # every point, automatic or requested, at its hold's truth
    for message, u in zip(points, uncertainty):
        expected = true_by_stamp[(message.header.stamp.sec, message.header.stamp.nanosec)]
        assert np.all(np.abs(six(message) - expected) < 4.5 * six(u)), (
            six(message),
            expected,
            six(u),
        )
