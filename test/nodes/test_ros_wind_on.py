"""Wind-on through the graph: bridge_publisher (α sweep, LMC6522 cubic truth) -> balance_calibrator
(memo cubic, ~/zero on the wind-off samples: the simulated model weighs nothing, so they are the
electrical zero) -> /balance/wrench equals the true load in tunnel axes (§10.2).
"""

from geometry_msgs.msg import WrenchStamped
import numpy as np
import pytest
from ros_harness import new_domain_id, NodeProcess, Probe, wait_for
from std_srvs.srv import Trigger

from balance_calib.config import load_balance_config

pytestmark = pytest.mark.ros
CAPACITY = load_balance_config('lmc6522').capacity


def by_stamp(messages):
    return {
        (m.header.stamp.sec, m.header.stamp.nanosec): np.array(
            [
                m.wrench.force.x,
                m.wrench.force.y,
                m.wrench.force.z,
                m.wrench.torque.x,
                m.wrench.torque.y,
                m.wrench.torque.z,
            ]
        )
        for m in messages
    }


@pytest.mark.parametrize('installation', ['upright', 'inverted'])
def test_held_points_read_the_true_tunnel_axis_load_within_0_1_percent_fs(tmp_path, installation):
    probe = Probe(new_domain_id())
    wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
    truth = probe.subscribe(WrenchStamped, '/balance/truth')
    probe.subscribe(WrenchStamped, '/balance/raw')  # so that the publisher waits for us too
    calibrator = NodeProcess(
        'balance_calibrator',
        probe.domain_id,
        tmp_path,
        {'installation': installation, 'tare_samples': 100},
    )  # calibration_file: the memo's
    #   matrices
    publisher = None
    try:
        # waits for the next 100 samples
        tare = probe.call_async(Trigger, '/balance_calibrator/zero')
        subscription = [s for s in probe.node.subscriptions if s.topic_name == '/balance/wrench'][
            0
        ]
        wait_for(lambda: subscription.get_publisher_count() >= 1, 20.0, '/balance/wrench')
        publisher = NodeProcess(
            'bridge_publisher',
            probe.domain_id,
            tmp_path,
            {
                'mode': 'wind_on',
                'installation': installation,
                'rate_hz': 200.0,
                'wind_off_s': 1.0,
                'hold_s': 0.4,
                'alpha_start_deg': -2.0,
                'alpha_end_deg': 22.0,
                'alpha_step_deg': 6.0,
                'noise_sigma_pct_fs': 0.005,
                'exit_when_done': True,
                'wait_for_subscribers': 2,
            },
        )
        assert publisher.wait(60.0) == 0, publisher.output()
        wait_for(tare.done, 10.0, 'the zero reply')
        assert tare.result().success and 'mV' in tare.result().message, tare.result().message
        wait_for(
            lambda: len(truth) == 200 + 5 * 80 and len(wrenches) >= 0.95 * len(truth),
            10.0,
            'the truth and wrenches of the run',
        )
    finally:
        if publisher is not None:
            publisher.stop()
        calibrator.stop()
        probe.close()

    true_loads, measured = by_stamp(truth), by_stamp(wrenches)
    stamps = sorted(set(true_loads) & set(measured))
    true_values = np.array([true_loads[s] for s in stamps])
    measured_values = np.array([measured[s] for s in stamps])
    held = np.any(true_values != 0, axis=1)  # the α points (wind-off samples went to ~/tare)
    conditions, condition = np.unique(true_values[held], axis=0, return_inverse=True)
    assert len(conditions) == 5  # α = -2, 4, 10, 16, 22°
    capacity_tunnel = np.abs(CAPACITY)  # a signed permutation keeps magnitudes here
    for k, load in enumerate(conditions):
        samples = measured_values[held][condition.ravel() == k]
        assert len(samples) >= 0.8 * 80
        error_pct_fs = (samples.mean(axis=0) - load) / capacity_tunnel * 100
        assert np.all(np.abs(error_pct_fs) <= 0.1), (load, error_pct_fs)
    # and it is a real load: F_Z̄ of the largest α is about half the capacity, of the
    # installation's sign
    assert np.max(np.abs(conditions[:, 2])) == pytest.approx(0.5 * CAPACITY[2], rel=1e-9)
