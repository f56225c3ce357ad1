"""balance_calibrator in the test process for the DDS tests (test_ros_calibrator*.py): the
probe and the memo's calibration file as fixtures, the node started with parameter overrides,
/balance/raw published from the probe, and a ~/tare or ~/zero window fed and answered.
"""

from geometry_msgs.msg import WrenchStamped
import numpy as np
from rclpy.parameter import Parameter
from ros_harness import RELIABLE, wait_for
from std_srvs.srv import Trigger

from balance_calib.calibration_file import load_calibration
from balance_calib.config import CONFIG_DIR
from balance_calib.nodes._messages import set_wrench
from balance_calib.nodes.balance_calibrator import BalanceCalibrator

MEMO = load_calibration(CONFIG_DIR / 'lmc6522.yaml')
SAMPLE_MV = (0.3, -0.2, 0.5, 0.1, -0.4, 0.2)


def start_calibrator(probe, tmp_path, calibration_file, refit=None, **parameters):
    bag = tmp_path / 'campaign'
    bag.mkdir(exist_ok=True)
    overrides = {
        'calibration_file': str(calibration_file),
        'report_dir': str(tmp_path / 'reports'),
        'calibration_bags': [str(bag)],
        'diagnostics_period_s': 0.2,
        **parameters,
    }
    node = BalanceCalibrator(
        refit_function=refit,
        context=probe.context,
        parameter_overrides=[Parameter(k, value=v) for k, v in overrides.items()],
    )
    probe.add_node(node)
    return node


class RawSource:
    """Publishes /balance/raw from the probe: one sample per call to send(), or a steady stream."""

    def __init__(self, probe):
        self.probe = probe
        self.publisher = probe.node.create_publisher(WrenchStamped, '/balance/raw', RELIABLE)
        self.sent = 0
        self.timer = None

    def send(self, outputs=SAMPLE_MV):
        msg = WrenchStamped()
        msg.header.stamp.sec, msg.header.stamp.nanosec = (
            1000 + self.sent // 1000,
            (self.sent % 1000) * 1000,
        )
        msg.header.frame_id = 'LMC6522'
        set_wrench(msg.wrench, outputs)
        self.publisher.publish(msg)
        self.sent += 1

    def stream(self, rate_hz=200.0):
        self.timer = self.probe.node.create_timer(1.0 / rate_hz, self.send)

    def stop(self):
        self.timer.cancel()


def wrench_values(messages):
    return np.array(
        [
            [
                m.wrench.force.x,
                m.wrench.force.y,
                m.wrench.force.z,
                m.wrench.torque.x,
                m.wrench.torque.y,
                m.wrench.torque.z,
            ]
            for m in messages
        ]
    )


def connected(node, source):
    """Both links matched on the writer side, so that no sample of a volatile topic is lost."""
    wait_for(
        lambda: source.publisher.get_subscription_count() >= 1, 10.0, 'the calibrator to subscribe'
    )
    wait_for(
        lambda: node._wrench_pub.get_subscription_count() >= 1, 10.0, '/balance/wrench to connect'
    )


class Stamped(RawSource):
    """RawSource with sample stamps of our choosing (1 kHz by default) and a frame id."""

    def __init__(self, probe, topic='/balance/raw'):
        self.probe = probe
        self.publisher = probe.node.create_publisher(WrenchStamped, topic, RELIABLE)
        self.sent = 0

    def send(self, outputs=(0.1, 0.0, 0.1, 0.0, 0.0, 0.0), stamp_ns=None, frame_id='LMC6522'):
        stamp_ns = (10**9 + self.sent * 10**6) if stamp_ns is None else stamp_ns
        msg = WrenchStamped()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp_ns), 10**9)
        msg.header.frame_id = frame_id
        set_wrench(msg.wrench, outputs)
        self.publisher.publish(msg)
        self.sent += 1


def window(probe, node, source, service, outputs):
    """Call ~/tare or ~/zero, wait for its window to open, feed it, return the reply."""
    reply = probe.call_async(Trigger, f'/balance_calibrator/{service}')
    wait_for(lambda: node.session.live.window is not None, 10.0, f'the {service} window to open')
    for row in outputs:
        source.send(row)
    wait_for(reply.done, 20.0, f'the {service} reply')
    return reply.result()
