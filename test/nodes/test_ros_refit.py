"""~/refit of a balance_calibrator process with the real refit pipeline, while samples stream at
200 Hz.
"""

import time

from geometry_msgs.msg import WrenchStamped
import numpy as np
import pytest
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from ros_harness import new_domain_id, NodeProcess, Probe, RELIABLE, wait_for
from std_srvs.srv import Trigger

from balance_calib.calibration_file import load_calibration, save_calibration
from balance_calib.config import CONFIG_DIR
from balance_calib.nodes._messages import set_wrench

pytestmark = [pytest.mark.ros, pytest.mark.slow]
SAMPLE_MV = np.array([0.3, -0.2, 0.5, 0.1, -0.4, 0.2])


@pytest.fixture(scope='module')
def bag(campaigns):
    return campaigns.bag(seed=5, recipe='dds')


@pytest.fixture
def graph(tmp_path, bag):
    """A calibrator process on the memo's matrices, and a probe that streams raw samples to it."""
    domain = new_domain_id()
    calibration_file = tmp_path / 'calibration.yaml'
    save_calibration(calibration_file, load_calibration(CONFIG_DIR / 'lmc6522.yaml'))
    node = NodeProcess(
        'balance_calibrator',
        domain,
        tmp_path / 'logs',
        {
            'calibration_file': str(calibration_file),
            'calibration_bags': [str(bag)],
            'report_dir': str(tmp_path / 'reports'),
        },
    )
    probe = Probe(domain)
    yield probe, node, calibration_file
    probe.close()
    node.stop()


class Stream:
    """Raw samples at 200 Hz, each stamped with its sequence number (sec 1000 + n // 1000, n %
    1000 µs).
    """

    def __init__(self, probe):
        self.publisher = probe.node.create_publisher(WrenchStamped, '/balance/raw', RELIABLE)
        self.wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
        self.sent = 0
        self.probe = probe
        wait_for(
            lambda: self.publisher.get_subscription_count() >= 1,
            20.0,
            'the calibrator to subscribe',
        )
        self.timer = probe.node.create_timer(1 / 200.0, self.send)

    def send(self):
        msg = WrenchStamped()
        msg.header.stamp.sec, msg.header.stamp.nanosec = (
            1000 + self.sent // 1000,
            (self.sent % 1000) * 1000,
        )
        set_wrench(msg.wrench, SAMPLE_MV.tolist())
        self.publisher.publish(msg)
        self.sent += 1

    def received_sequence(self):
        return [
            (m.header.stamp.sec - 1000) * 1000 + m.header.stamp.nanosec // 1000
            for m in self.wrenches
        ]


def test_stream_keeps_flowing_through_a_real_refit(graph):
    probe, node, calibration_file = graph
    before = calibration_file.read_text()
    stream = Stream(probe)
    wait_for(lambda: len(stream.wrenches) >= 20, 20.0, 'wrenches before the refit')
    reply = probe.call_async(Trigger, '/balance_calibrator/refit')
    asked, count_at_request = time.monotonic(), len(stream.wrenches)
    wait_for(reply.done, 120.0, 'the refit reply')
    refit_s, during = time.monotonic() - asked, len(stream.wrenches) - count_at_request
    assert reply.result().success, reply.result().message + node.output()[-3000:]
    assert 'refit OK' in reply.result().message and 'FX' in reply.result().message
    # samples kept coming while the refit ran (at least half the 200 Hz rate)
    assert during >= 0.5 * 200 * refit_s and during >= 50, (during, refit_s)
    count = len(stream.wrenches)
    wait_for(lambda: len(stream.wrenches) >= count + 20, 10.0, 'wrenches after the refit')
    stream.timer.cancel()
    sent = stream.sent
    first = stream.received_sequence()[0]
    # count in = count out: every sample since the link came up has its wrench, in order, none
    # twice
    wait_for(
        lambda: stream.received_sequence() == list(range(first, sent)),
        20.0,
        f'wrenches for samples {first}..{sent - 1}',
    )
    # the refit's calibration replaced calibration_file and is the one in force now
    fitted = load_calibration(calibration_file)
    assert calibration_file.read_text() != before and fitted.fitted_at
    values = np.array(
        [[m.wrench.force.x, m.wrench.force.y, m.wrench.force.z] for m in stream.wrenches]
    )
    assert not np.allclose(values[0], values[-1], rtol=1e-9, atol=0)
    assert node.process.poll() is None


def test_refit_of_a_corrupt_bag_names_it_and_keeps_the_calibration(graph, tmp_path):
    probe, node, calibration_file = graph
    garbage = tmp_path / 'garbage.mcap'
    garbage.write_bytes(b'\x89MCAP0\r\n' + bytes(range(256)) * 4)
    client = AsyncParameterClient(probe.node, 'balance_calibrator')
    assert client.wait_for_services(20.0)
    future = client.set_parameters([Parameter('calibration_bags', value=[str(garbage)])])
    wait_for(future.done, 10.0, 'calibration_bags set')
    before = calibration_file.read_bytes()
    stream = Stream(probe)
    wait_for(lambda: len(stream.wrenches) >= 5, 20.0, 'wrenches before the refit')
    reply = probe.call(Trigger, '/balance_calibrator/refit', timeout_s=60.0)
    assert (
        not reply.success and 'garbage.mcap' in reply.message and 'stays in force' in reply.message
    )
    count = len(stream.wrenches)
    wait_for(lambda: len(stream.wrenches) >= count + 20, 10.0, 'wrenches after the failed refit')
    stream.timer.cancel()
    assert calibration_file.read_bytes() == before and node.process.poll() is None
