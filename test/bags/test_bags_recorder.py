"""balance_recorder end to end: a real node over DDS records what a test node publishes.

The recorder runs as its console script in a subprocess on its own ROS_DOMAIN_ID; the test node
publishes from this process on the same domain. Waits are bounded polls: the publishers' matched
subscription counts (the recorder has subscribed), then wait_for_all_acked (it has every
message), then the process exit.
"""

import os
import re
import signal
import subprocess
import time

from geometry_msgs.msg import Vector3Stamped, WrenchStamped
import numpy as np
import pytest
import rclpy
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
import yaml

from balance_calib.bags.reader import read_bags
from balance_calib.nodes._qos import STREAM_QOS
from balance_calib.nodes.balance_recorder import (
    HOLE_WARNING_PERIOD_S,
    offered_qos_as_dict,
    subscription_qos,
)

SAMPLES = 200
GRAVITY_VECTORS = [
    (0.0, 1.0, 0.0),
    (0.0, 0.0, 1.0),
    (0.0, -0.7071067811865476, 0.7071067811865476),
]


@pytest.fixture
def test_node(ros_domain):
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=ros_domain)
    node = rclpy.create_node('bag_recorder_test_publisher', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    yield node, executor
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown(context=context)


def start_recorder(bag, ros_domain):
    return subprocess.Popen(
        [
            'balance_recorder',
            '--ros-args',
            '-p',
            f'output:={bag}',
            '-p',
            'topics:=[/balance/raw, /calibration/gravity]',
        ],
        env={**os.environ, 'ROS_DOMAIN_ID': str(ros_domain)},
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def wait_until(condition, executor, recorder, timeout_s=30.0):
    deadline = time.monotonic() + timeout_s
    while not condition():
        if recorder.poll() is not None:
            pytest.fail(f'recorder exited early:\n{recorder.communicate()[0]}')
        if time.monotonic() > deadline:
            recorder.kill()
            pytest.fail(f'timed out; recorder said:\n{recorder.communicate()[0]}')
        executor.spin_once(timeout_sec=0.05)


def record_and_stop(tmp_path, ros_domain, test_node, stop_signal):
    node, executor = test_node
    reliable = QoSProfile(depth=SAMPLES, reliability=ReliabilityPolicy.RELIABLE)
    raw_publisher = node.create_publisher(WrenchStamped, '/balance/raw', reliable)
    gravity_publisher = node.create_publisher(Vector3Stamped, '/calibration/gravity', reliable)
    bag = tmp_path / 'campaign'
    recorder = start_recorder(bag, ros_domain)
    try:
        wait_until(
            lambda: (
                raw_publisher.get_subscription_count() > 0
                and gravity_publisher.get_subscription_count() > 0
            ),
            executor,
            recorder,
        )
        sent = []
        for index in range(SAMPLES):
            message = WrenchStamped()
            message.header.stamp.sec, message.header.stamp.nanosec = 1_700_000_000, index
            message.header.frame_id = 'LMC6522'
            six = [index + 0.125 * k for k in range(6)]
            (
                message.wrench.force.x,
                message.wrench.force.y,
                message.wrench.force.z,
                message.wrench.torque.x,
                message.wrench.torque.y,
                message.wrench.torque.z,
            ) = six
            sent.append(six)
            raw_publisher.publish(message)
            if index % 80 == 0:
                vector = Vector3Stamped()
                vector.vector.x, vector.vector.y, vector.vector.z = GRAVITY_VECTORS[index // 80]
                gravity_publisher.publish(vector)
        for publisher in (raw_publisher, gravity_publisher):
            assert publisher.wait_for_all_acked(Duration(seconds=20))
        recorder.send_signal(stop_signal)
        output, _ = recorder.communicate(timeout=30)
    finally:
        if recorder.poll() is None:
            recorder.kill()
            recorder.communicate()
    assert recorder.returncode == 0, output
    return bag, np.array(sent), output


@pytest.mark.ros
@pytest.mark.parametrize('stop_signal', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_recorder_keeps_every_message_in_order_and_closes_the_bag_on(
    tmp_path, ros_domain, test_node, stop_signal
):
    bag, sent, output = record_and_stop(tmp_path, ros_domain, test_node, stop_signal)
    data = read_bags(bag, required=('raw', 'gravity'))
    np.testing.assert_array_equal(data.raw.values, sent)
    assert data.raw.stamps_ns.tolist() == [1_700_000_000 * 10**9 + i for i in range(SAMPLES)]
    assert set(data.raw.frame_ids) == {'LMC6522'}
    np.testing.assert_array_equal(data.gravity.vectors, GRAVITY_VECTORS)
    assert f'/balance/raw: {SAMPLES}' in output and '/calibration/gravity: 3' in output
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['version'] == 9 and info['message_count'] == SAMPLES + 3
    raw = next(
        t['topic_metadata']
        for t in info['topics_with_message_count']
        if t['topic_metadata']['name'] == '/balance/raw'
    )
    assert [q['reliability'] for q in raw['offered_qos_profiles']] == ['reliable']
    assert raw['type_description_hash'].startswith('RIHS01_')
    assert_identical_through_rosbags_and_mcap(bag)


def assert_identical_through_rosbags_and_mcap(bag):
    """The recorder's bag reads back the same through rosbags and through mcap + mcap_ros2."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from message_fields import fields_of
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        by_rosbags = [
            (c.topic, t, fields_of(reader.deserialize(raw, c.msgtype)))
            for c, t, raw in reader.messages()
        ]
    mcap_file = next(bag.glob('*.mcap'))
    with open(mcap_file, 'rb') as stream:
        by_mcap = [
            (channel.topic, message.log_time, fields_of(decoded))
            for _, channel, message, decoded in make_reader(
                stream, decoder_factories=[DecoderFactory()]
            ).iter_decoded_messages(log_time_order=True)
        ]
    assert len(by_rosbags) == SAMPLES + 3
    assert by_rosbags == by_mcap


@pytest.mark.ros
def test_a_bag_being_recorded_is_read_up_to_the_last_flush(tmp_path, ros_domain, test_node):
    """~/refit of the recorder's bag while it still records (no metadata.yaml yet)."""
    from balance_calib.nodes.balance_recorder import FLUSH_PERIOD_S

    node, executor = test_node
    reliable = QoSProfile(depth=SAMPLES, reliability=ReliabilityPolicy.RELIABLE)
    raw_publisher = node.create_publisher(WrenchStamped, '/balance/raw', reliable)
    bag = tmp_path / 'live'
    recorder = start_recorder(bag, ros_domain)
    try:
        wait_until(lambda: raw_publisher.get_subscription_count() > 0, executor, recorder)
        sent = []
        for index in range(SAMPLES):
            message = WrenchStamped()
            message.header.stamp.sec, message.header.stamp.nanosec = 1_700_000_000, index
            message.wrench.force.x, message.wrench.torque.z = float(index), -0.5 * index
            sent.append(index)
            raw_publisher.publish(message)
        assert raw_publisher.wait_for_all_acked(Duration(seconds=20))
        time.sleep(2.5 * FLUSH_PERIOD_S)
        assert recorder.poll() is None and not (bag / 'metadata.yaml').exists()
        data = read_bags(bag)  # the directory as it is, the recorder still at work
    finally:
        recorder.send_signal(signal.SIGINT)
        output, _ = recorder.communicate(timeout=30)
    assert recorder.returncode == 0, output
    np.testing.assert_array_equal(data.raw.values[:, 0], sent)
    np.testing.assert_array_equal(data.raw.values[:, 5], -0.5 * np.array(sent))
    assert (
        len(data.losses) == 1 and f'read the {SAMPLES} messages on disk so far' in data.losses[0]
    )
    closed = read_bags(bag)  # and once stopped: the complete bag, nothing to say
    assert len(closed.raw) == SAMPLES and closed.losses == ()


@pytest.mark.ros
def test_a_recorder_stalled_1_5_s_keeps_a_1_khz_stream_and_says_what_a_shallow_writer_lost(
    tmp_path, ros_domain, test_node
):
    """The CI failure of stop 32: a recorder off the CPU for longer than its writers' history
    (then 1000 samples, one second at 1 kHz) lost 50 of 1700 samples without a word. The
    recorder is stopped (SIGSTOP, DDS threads and all) for 1.5 s in the middle of a 1 kHz
    stream: what the stream QoS publishes arrives whole; a third-party writer at rclpy's default
    depth of 10 cannot repair 1.5 s and the recorder says how many DDS reported lost.
    """
    node, executor = test_node
    raw_publisher = node.create_publisher(WrenchStamped, '/balance/raw', STREAM_QOS)
    shallow = node.create_publisher(
        Vector3Stamped,
        '/calibration/gravity',
        QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE),
    )
    bag, count, stall = tmp_path / 'stalled', 3000, (1000, 2500)  # samples; off the CPU between
    recorder = start_recorder(bag, ros_domain)
    try:
        wait_until(
            lambda: (
                raw_publisher.get_subscription_count() > 0 and shallow.get_subscription_count() > 0
            ),
            executor,
            recorder,
        )
        time.sleep(0.5)  # the recorder's readers match the writers too
        start = time.monotonic()
        for index in range(count):
            if index in stall:
                os.kill(recorder.pid, signal.SIGSTOP if index == stall[0] else signal.SIGCONT)
            message = WrenchStamped()
            message.header.stamp.sec, message.header.stamp.nanosec = 1_700_000_000, index
            message.wrench.force.x = float(index)
            raw_publisher.publish(message)
            vector = Vector3Stamped()
            vector.vector.z = 1.0
            shallow.publish(vector)
            time.sleep(max(0.0, start + (index + 1) * 1e-3 - time.monotonic()))
        stalled_s = (stall[1] - stall[0]) * 1e-3
        # the stall is counted in samples (1500), so a publisher slowed by a busy machine makes
        # it longer, not shorter: only a harness stuck for seconds would void the run
        assert time.monotonic() - start < 2 * count * 1e-3 + 1.0, 'the publisher itself was late'
        assert raw_publisher.wait_for_all_acked(Duration(seconds=30))
        shallow.wait_for_all_acked(Duration(seconds=10))
        recorder.send_signal(signal.SIGINT)
        output, _ = recorder.communicate(timeout=30)
    finally:
        if recorder.poll() is None:
            os.kill(recorder.pid, signal.SIGCONT)
            recorder.kill()
            recorder.communicate()
    assert recorder.returncode == 0, output
    data = read_bags(bag, required=('raw',))
    kept = set((data.raw.stamps_ns - 1_700_000_000 * 10**9).tolist())
    missing = [i for i in range(count) if i not in kept]
    assert not missing, (
        f'{len(kept)} of {count} samples kept through a {stalled_s:g} s stall; missing '
        f'{missing[0]}..{missing[-1]}; the recorder said:\n{output}'
    )
    written = dict(
        re.findall(r'(/[\w/]+): (\d+)', output.split('messages written:')[1].split('\n')[0])
    )
    holes = re.search(
        r'lost before they reached the recorder: /calibration/gravity: (\d+)', output
    )
    assert written['/balance/raw'] == str(count) and holes, output
    # every sample of the shallow writer is in the bag or in the count of the hole
    assert int(written['/calibration/gravity']) + int(holes[1]) == count, output
    said = [line for line in output.splitlines() if 'before they reached the recorder' in line]
    assert all('/calibration/gravity' in line for line in said), output
    assert len(said) <= 2 + stalled_s / HOLE_WARNING_PERIOD_S, output  # not a line a sample


@pytest.mark.ros
def test_recorder_refuses_an_existing_output(tmp_path, ros_domain):
    (tmp_path / 'campaign').mkdir()
    result = subprocess.run(
        ['balance_recorder', '--ros-args', '-p', f'output:={tmp_path / "campaign"}'],
        env={**os.environ, 'ROS_DOMAIN_ID': str(ros_domain)},
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert result.returncode == 1
    assert 'exists already' in result.stderr + result.stdout


def test_subscription_is_reliable_only_if_every_publisher_offers_it():
    reliable = QoSProfile(
        depth=10,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )
    best_effort = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
    assert subscription_qos([reliable]).reliability == ReliabilityPolicy.RELIABLE
    assert subscription_qos([reliable]).durability == DurabilityPolicy.TRANSIENT_LOCAL
    mixed = subscription_qos([reliable, best_effort])
    assert mixed.reliability == ReliabilityPolicy.BEST_EFFORT
    assert mixed.durability == DurabilityPolicy.VOLATILE


def test_offered_qos_is_written_in_rosbag2_v9_words():
    profile = offered_qos_as_dict(
        QoSProfile(
            depth=7,
            reliability=ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
    )
    assert profile['history'] == 'keep_last' and profile['depth'] == 7
    assert profile['reliability'] == 'best_effort'
    assert profile['durability'] == 'transient_local'
    assert profile['liveliness'] == 'system_default'
    assert profile['deadline'] == {'sec': 0, 'nsec': 0}
