"""Across hosts: publisher, calibrator and recorder in three network namespaces
joined by a bridge, as on a tunnel's DAQ, compute and storage machines. Addresses from
198.18.0.0/15 (the benchmarking range), discovery over that subnet
(ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET, UDPv4 only: no shared memory between the "hosts"); every
namespace, link and bridge is made and removed here. Skipped, with the reason, where network
namespaces cannot be created (no CAP_NET_ADMIN).
"""

import json
import os
import signal
import subprocess
import sys
import time

import pytest
from ros_harness import new_domain_id

from balance_calib.calibration_file import load_calibration, save_calibration
from balance_calib.config import CONFIG_DIR, load_balance_config
from balance_calib.launchless.processes import ros_args
from balance_calib.simulation.wind_on import aoa_sweep_profile
from balance_calib.tunnel_axes import UPRIGHT

pytestmark = [pytest.mark.ros, pytest.mark.slow]
HOSTS = ('daq', 'cal', 'rec')  # publisher, calibrator, recorder (and the checker)


def ip(*args, namespace=None):
    command = (['ip', 'netns', 'exec', namespace] if namespace else []) + ['ip', *args]
    return subprocess.run(command, check=True, capture_output=True, text=True, timeout=20)


class Network:
    """Three namespaces with a veth each into a fourth that holds the bridge: the host's own
    network is not touched.
    """

    def __init__(self):
        self.prefix = f'bc{os.getpid() % 100000}'
        self.made = []

    def __enter__(self):
        bridge = f'{self.prefix}br'
        try:
            ip('netns', 'add', bridge)
        except (OSError, subprocess.CalledProcessError) as err:
            reason = getattr(err, 'stderr', '') or err
            pytest.skip(f'cannot create network namespaces here: {reason}'.strip())
        self.made.append(bridge)
        ip('link', 'add', 'br0', 'type', 'bridge', namespace=bridge)
        for link in ('br0', 'lo'):
            ip('link', 'set', link, 'up', namespace=bridge)
        for k, host in enumerate(HOSTS, start=1):
            namespace, inside, outside = (
                f'{self.prefix}{host}',
                f'{self.prefix}v{host}',
                f'{self.prefix}b{host}',
            )
            ip('netns', 'add', namespace)
            self.made.append(namespace)
            ip('link', 'add', inside, 'type', 'veth', 'peer', 'name', outside)
            ip('link', 'set', inside, 'netns', namespace)
            ip('link', 'set', outside, 'netns', bridge)
            ip('link', 'set', outside, 'master', 'br0', namespace=bridge)
            ip('link', 'set', outside, 'up', namespace=bridge)
            ip('addr', 'add', f'198.18.0.{k}/24', 'dev', inside, namespace=namespace)
            for link in (inside, 'lo'):
                ip('link', 'set', link, 'up', namespace=namespace)
            # DDS discovery multicast
            ip('route', 'add', '224.0.0.0/4', 'dev', inside, namespace=namespace)
        return self

    def namespace(self, host):
        return f'{self.prefix}{host}'

    def __exit__(self, *exc):
        for namespace in reversed(self.made):  # deleting a namespace removes its links
            subprocess.run(['ip', 'netns', 'del', namespace], capture_output=True, timeout=20)


class HostProcess:
    """A command in a namespace; SIGINT to stop, output in a log file."""

    def __init__(self, network, host, command, env, log):
        self.log = open(log, 'w')
        self.process = subprocess.Popen(
            ['ip', 'netns', 'exec', network.namespace(host)] + command,
            env=env,
            stdout=self.log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )

    def stop(self, timeout_s=10.0):
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGINT)
            try:
                self.process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                os.killpg(self.process.pid, signal.SIGKILL)
                self.process.wait(timeout_s)
        self.log.close()
        return self.process.returncode


def _wait_for_line(log, text: str, timeout_s: float) -> None:
    """Wait until the log file holds `text` (a node's line saying it is ready), or fail."""
    deadline = time.monotonic() + timeout_s
    while text not in log.read_text():
        assert time.monotonic() < deadline, f'no "{text}" in {log} after {timeout_s:g} s'
        time.sleep(0.1)


CHECKER = r"""
import json, sys, time
import rclpy
from geometry_msgs.msg import WrenchStamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_srvs.srv import Trigger
expected, deadline = int(sys.argv[1]), time.monotonic() + float(sys.argv[2])
rclpy.init()
node = rclpy.create_node('netns_checker')
qos = QoSProfile(depth=20000, reliability=ReliabilityPolicy.RELIABLE)
stamps = {'raw': set(), 'wrench': set()}
def keep(kind):
    return lambda m: stamps[kind].add((m.header.stamp.sec, m.header.stamp.nanosec))
wrench = node.create_subscription(WrenchStamped, '/balance/wrench', keep('wrench'), qos)
while wrench.get_publisher_count() < 1 and time.monotonic() < deadline:     # the calibrator, first
    rclpy.spin_once(node, timeout_sec=0.05)
# then the publisher may start
node.create_subscription(WrenchStamped, '/balance/raw', keep('raw'), qos)
while min(len(s) for s in stamps.values()) < expected and time.monotonic() < deadline:
    rclpy.spin_once(node, timeout_sec=0.05)
client = node.create_client(Trigger, '/balance_calibrator/refit')
client.wait_for_service(timeout_sec=max(1.0, deadline - time.monotonic()))
future = client.call_async(Trigger.Request())
while not future.done() and time.monotonic() < deadline:
    rclpy.spin_once(node, timeout_sec=0.05)
reply = future.result() if future.done() else None
print(json.dumps({'raw': len(stamps['raw']), 'wrench': len(stamps['wrench']),
                  'same_stamps': stamps['raw'] == stamps['wrench'],
                  'refit': None if reply is None else [reply.success, reply.message]}), flush=True)
"""


def test_three_hosts_over_a_bridge_lose_nothing_at_1_khz_and_refit_through_the_service(
    tmp_path, campaigns
):
    config = load_balance_config('lmc6522')
    bag = campaigns.bag(seed=5, recipe='dds', noise=None)
    calibration_file = tmp_path / 'calibration.yaml'
    save_calibration(calibration_file, load_calibration(CONFIG_DIR / 'lmc6522.yaml'))
    rate, hold_s, wind_off_s, alphas = 1000.0, 0.3, 0.5, (-2.0, 6.0, 14.0, 22.0)
    expected = len(
        aoa_sweep_profile(
            config.capacity, UPRIGHT, rate, alphas_deg=alphas, hold_s=hold_s, wind_off_s=wind_off_s
        ).times_s
    )
    env = dict(
        os.environ,
        ROS_DOMAIN_ID=str(new_domain_id()),
        ROS_AUTOMATIC_DISCOVERY_RANGE='SUBNET',
        FASTDDS_BUILTIN_TRANSPORTS='UDPv4',
        PYTHONUNBUFFERED='1',
    )
    processes = {}
    with Network() as network:
        try:
            processes['calibrator'] = HostProcess(
                network,
                'cal',
                ['balance_calibrator']
                + ros_args(
                    {
                        'calibration_file': str(calibration_file),
                        'calibration_bags': [str(bag)],
                        'report_dir': str(tmp_path / 'reports'),
                    }
                ),
                env,
                tmp_path / 'calibrator.log',
            )
            processes['recorder'] = HostProcess(
                network,
                'rec',
                ['balance_recorder']
                + ros_args(
                    {
                        'topics': ['/balance/raw', '/balance/wrench'],
                        'output': str(tmp_path / 'recorded'),
                    }
                ),
                env,
                tmp_path / 'recorder.log',
            )
            checker = subprocess.Popen(
                [
                    'ip',
                    'netns',
                    'exec',
                    network.namespace('rec'),
                    sys.executable,
                    '-c',
                    CHECKER,
                    str(expected),
                    '150',
                ],
                env=env,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
                start_new_session=True,
            )
            # the recorder subscribes to a topic once it has discovered its publisher: the
            # wind-on run starts only when it records the calibrator's wrench (discovery across
            # the bridge can take seconds on a busy machine)
            _wait_for_line(tmp_path / 'recorder.log', 'recording /balance/wrench', timeout_s=60.0)
            processes['publisher'] = HostProcess(
                network,
                'daq',
                ['bridge_publisher']
                + ros_args(
                    {
                        'mode': 'wind_on',
                        'rate_hz': rate,
                        'hold_s': hold_s,
                        'wind_off_s': wind_off_s,
                        'alpha_start_deg': alphas[0],
                        'alpha_end_deg': alphas[-1],
                        'alpha_step_deg': 8.0,
                        'noise_sigma_pct_fs': 0.005,
                        'exit_when_done': True,
                        'wait_for_subscribers': 3,
                    }
                ),
                env,
                tmp_path / 'publisher.log',
            )
            out, err = checker.communicate(timeout=200)
            assert processes['publisher'].process.wait(60) == 0, (
                tmp_path / 'publisher.log'
            ).read_text()
        finally:
            for name in ('publisher', 'recorder', 'calibrator'):
                if name in processes:
                    processes[name].stop()
    result = json.loads(out.strip().splitlines()[-1]) if out.strip() else {'error': err[-2000:]}
    assert (
        result.get('raw') == expected
        and result.get('wrench') == expected
        and result['same_stamps']
    ), result
    assert result['refit'][0] and result['refit'][1].startswith('refit OK'), result['refit']
    from mcap.reader import make_reader

    counts = {}
    for path in sorted((tmp_path / 'recorded').glob('*.mcap')):
        with open(path, 'rb') as handle:
            for _, channel, _ in make_reader(handle).iter_messages():
                counts[channel.topic] = counts.get(channel.topic, 0) + 1
    assert counts.get('/balance/raw') == expected, counts
    assert counts.get('/balance/wrench') == expected, counts
