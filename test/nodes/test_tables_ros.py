"""A calibration fitted from a table drives balance_calibrator like any other calibration.yaml:
the node process, over real DDS, publishes for each raw sample the wrench the fitted model gives.
"""

from geometry_msgs.msg import WrenchStamped
import numpy as np
import pytest
from ros_harness import new_domain_id, NodeProcess, Probe, RELIABLE, wait_for

from balance_calib.calibration_file import load_calibration
from balance_calib.cli import main
from balance_calib.nodes._messages import set_wrench
from balance_calib.tables import synthetic as sy
from balance_calib.tables.balfit_writer import write_table
from balance_calib.tunnel_axes import parse_installation

pytestmark = pytest.mark.ros


def test_table_fitted_direct_calibration_drives_the_calibrator(tmp_path):
    rng = np.random.default_rng(12)
    truth = sy.direct_truth(rng, nonlinear_fraction=0.01)
    schedule = sy.support_schedule(rng, 15, 30)
    tares = sy.tares_for(rng, np.unique(schedule.series))
    applied, outputs = sy.direct_campaign(rng, truth, schedule, tares, 0.0002 * sy.capacity_si())
    write_table(
        tmp_path / 'cal.csv',
        sy.make_table(applied, outputs, schedule.series, natural_zero_mv=[0.1] * 6),
    )
    assert (
        main(
            [
                'fit',
                str(tmp_path / 'cal.csv'),
                '--out',
                str(tmp_path / 'fit'),
                '--method',
                'direct',
                '--no-plots',
            ]
        )
        == 0
    )
    calibration = load_calibration(tmp_path / 'fit' / 'calibration.yaml')
    samples = outputs[rng.choice(len(outputs), 40, replace=False)]  # mV, natural zero removed
    expected = parse_installation('upright').to_tunnel(
        calibration.model().without_constant().loads(samples)
    )

    probe = Probe(new_domain_id())
    calibrator = NodeProcess(
        'balance_calibrator',
        probe.domain_id,
        tmp_path / 'logs',
        {'calibration_file': str(tmp_path / 'fit' / 'calibration.yaml')},
    )
    try:
        wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
        publisher = probe.node.create_publisher(WrenchStamped, '/balance/raw', RELIABLE)
        subscription = [s for s in probe.node.subscriptions if s.topic_name == '/balance/wrench'][
            0
        ]
        wait_for(
            lambda: (
                publisher.get_subscription_count() >= 1 and subscription.get_publisher_count() >= 1
            ),
            60.0,
            'the calibrator to connect',
        )
        for i, values in enumerate(samples):
            msg = WrenchStamped()
            msg.header.stamp.sec, msg.header.stamp.nanosec = 100, i * 1000
            set_wrench(msg.wrench, values)
            publisher.publish(msg)
        wait_for(lambda: len(wrenches) >= len(samples), 60.0, f'{len(samples)} wrenches')
        received = np.array(
            [
                [
                    m.wrench.force.x,
                    m.wrench.force.y,
                    m.wrench.force.z,
                    m.wrench.torque.x,
                    m.wrench.torque.y,
                    m.wrench.torque.z,
                ]
                for m in sorted(wrenches, key=lambda m: m.header.stamp.nanosec)
            ]
        )
        np.testing.assert_allclose(
            received, expected, rtol=1e-9, atol=1e-9 * sy.capacity_si().max()
        )
        # and the loads are the table's: within the calibration's own scatter of the true total
        # loads
        upright = parse_installation('upright')
        truth_loads = upright.to_tunnel(truth.loads(samples))
        capacity = np.abs(upright.to_tunnel(sy.capacity_si()[None, :]))[0]
        assert np.max(np.abs(received - truth_loads) / capacity) < 0.002
    finally:
        calibrator.stop()
        probe.close()
