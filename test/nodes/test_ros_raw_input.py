"""The calibrator's reader (nodes/_raw_input.py) over real DDS: a subscription read by its own
thread in batches of what is waiting, never by the node's executor, stopped cleanly, not stopped by
a bad batch.
"""

import threading

from geometry_msgs.msg import WrenchStamped
import pytest
from rclpy.node import Node
from rclpy.serialization import deserialize_message, serialize_message
from ros_harness import new_domain_id, Probe, RELIABLE, wait_for
from std_srvs.srv import Trigger

from balance_calib.nodes._raw_input import RawInput

pytestmark = pytest.mark.ros


@pytest.fixture
def probe():
    probe = Probe(new_domain_id())
    yield probe
    probe.close()


def message(k: int) -> bytes:
    msg = WrenchStamped()
    msg.header.stamp.sec, msg.header.frame_id = k, 'LMC6522'
    msg.wrench.force.x = float(k)
    return serialize_message(msg)


def test_a_burst_arrives_whole_in_order_in_batches_while_the_executor_serves_a_service(probe):
    node = Node('reader_under_test', context=probe.context)
    batches, threads = [], set()
    gate = threading.Event()

    def on_batch(batch):
        gate.wait(10.0)  # hold the first wake-up so that the rest of the burst queues behind it
        threads.add(threading.get_ident())
        batches.append(batch)

    reader = RawInput(node, WrenchStamped, 'burst', RELIABLE, on_batch, max_batch=64)
    node.create_service(
        Trigger, '~/ping', lambda request, response: setattr(response, 'success', True) or response
    )
    probe.add_node(node)
    reader.start()
    publisher = probe.node.create_publisher(WrenchStamped, 'burst', RELIABLE)
    wait_for(lambda: publisher.get_subscription_count() >= 1, 10.0, 'the reader to connect')
    for k in range(500):
        publisher.publish(message(k))
    assert probe.call(Trigger, '/reader_under_test/ping').success  # the executor is free meanwhile
    gate.set()
    wait_for(lambda: sum(map(len, batches)) >= 500, 20.0, 'all 500 samples')
    values = [
        deserialize_message(data, WrenchStamped).wrench.force.x
        for batch in batches
        for data in batch
    ]
    assert values == [float(k) for k in range(500)]
    assert max(map(len, batches)) == 64 and len(batches) < 100  # drained in batches, capped
    assert threads == {reader._thread.ident} and reader._thread.ident != threading.get_ident()
    reader.close()
    assert not reader._thread.is_alive()
    node.destroy_node()


def test_an_exception_in_one_batch_is_logged_and_the_stream_goes_on(probe):
    node = Node('reader_with_a_bad_batch', context=probe.context)
    seen, raised = [], threading.Event()

    def on_batch(batch):
        for data in batch:
            value = deserialize_message(data, WrenchStamped).wrench.force.x
            if value == 3.0:
                raised.set()
                raise ValueError('a batch the node cannot process')
            seen.append(value)

    reader = RawInput(node, WrenchStamped, 'stream', RELIABLE, on_batch)
    reader.start()
    publisher = probe.node.create_publisher(WrenchStamped, 'stream', RELIABLE)
    wait_for(lambda: publisher.get_subscription_count() >= 1, 10.0, 'the reader to connect')
    for k in range(10):
        publisher.publish(message(k))
        if k == 2:
            wait_for(lambda: len(seen) >= 3, 10.0, 'the first three')
        if k == 3:
            wait_for(raised.is_set, 10.0, 'the bad batch')
    wait_for(lambda: len(seen) >= 9, 10.0, 'the samples after the bad batch')
    assert seen == [0.0, 1.0, 2.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]
    assert reader._thread.is_alive()
    reader.close()
    node.destroy_node()


def test_a_second_topic_is_read_by_the_same_thread_and_each_batch_reaches_its_own_callback(probe):
    node = Node('reader_of_two', context=probe.context)
    first, second, threads = [], [], set()

    def into(seen):
        def on_batch(batch):
            threads.add(threading.get_ident())
            seen.extend(deserialize_message(data, WrenchStamped).wrench.force.x for data in batch)

        return on_batch

    reader = RawInput(node, WrenchStamped, 'one', RELIABLE, into(first))
    also = reader.also_read('two', into(second), RELIABLE)
    assert also.topic_name == '/two' and reader.subscription.topic_name == '/one'
    reader.start()
    with pytest.raises(RuntimeError, match="also_read\\('three'\\) after start"):
        reader.also_read('three', into([]), RELIABLE)
    one = probe.node.create_publisher(WrenchStamped, 'one', RELIABLE)
    two = probe.node.create_publisher(WrenchStamped, 'two', RELIABLE)
    wait_for(
        lambda: one.get_subscription_count() >= 1 and two.get_subscription_count() >= 1,
        10.0,
        'the reader to connect to both topics',
    )
    for k in range(200):
        one.publish(message(k))
        two.publish(message(1000 + k))
    wait_for(lambda: len(first) >= 200 and len(second) >= 200, 20.0, 'both streams')
    assert first == [float(k) for k in range(200)]
    assert second == [float(1000 + k) for k in range(200)]
    assert threads == {reader._thread.ident}
    reader.close()
    assert not reader._thread.is_alive()
    node.destroy_node()
