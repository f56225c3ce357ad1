"""bridge_publisher's replay reads bags through the one opener (bags/opening.py) and the package's
MCAP scanner: every message of every topic, CDR bytes untouched, merged by receive time; a wrong
path is the same one-line error read_bags gives.
"""

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as RosbagsWriter
from rosbags.typesys import get_typestore, Stores

from balance_calib.bags.errors import BagError
from balance_calib.bags.opening import open_bag
from balance_calib.bags.reader import read_bags
from balance_calib.simulation.replay import read_recorded_messages

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
T = TYPESTORE.types
STRING = 'std_msgs/msg/String'
WRENCH = 'geometry_msgs/msg/WrenchStamped'


def text(value: str) -> bytes:
    return TYPESTORE.serialize_cdr(T[STRING](value), STRING)


def wrench(stamp_ns: int, value: float) -> bytes:
    vector = T['geometry_msgs/msg/Vector3']
    message = T[WRENCH](
        T['std_msgs/msg/Header'](T['builtin_interfaces/msg/Time'](0, stamp_ns), 'B'),
        T['geometry_msgs/msg/Wrench'](vector(value, 0, 0), vector(0, 0, value)),
    )
    return TYPESTORE.serialize_cdr(message, WRENCH)


def rosbags_bag(path, records):
    """records: (topic, type, receive time ns, CDR), written by rosbags (not our writer)."""
    with RosbagsWriter(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {}
        for topic, msgtype, _, _ in records:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=TYPESTORE)
        for topic, _, time_ns, data in records:
            writer.write(connections[topic], time_ns, data)
    return path


def test_every_topic_comes_back_byte_for_byte_in_receive_time_order(tmp_path):
    # written out of time order across topics: 5 wrenches at 1000, 3000, ...; notes at 2000, ...
    wrenches = [('/balance/raw', WRENCH, 1000 + 2000 * i, wrench(i, 0.5 * i)) for i in range(5)]
    notes = [('/notes', STRING, 2000 + 2000 * i, text(f'note {i}')) for i in range(3)]
    bag = rosbags_bag(tmp_path / 'run', wrenches + notes)
    recorded = read_recorded_messages([bag])
    assert recorded.msgtypes == {'/balance/raw': WRENCH, '/notes': STRING}
    assert len(recorded) == 8
    # 1000 W0, 2000 N0, 3000 W1, 4000 N1, 5000 W2, 6000 N2, 7000 W3, 9000 W4
    np.testing.assert_allclose(
        recorded.times_s, np.array([0, 1, 2, 3, 4, 5, 6, 8]) * 1000 * 1e-9, rtol=0, atol=1e-15
    )
    assert recorded.topics == ('/balance/raw', '/notes') * 3 + ('/balance/raw',) * 2
    expected = [wrenches[0], notes[0], wrenches[1], notes[1], wrenches[2], notes[2]]
    expected += wrenches[3:]
    assert recorded.payloads == tuple(data for *_, data in expected)
    only = read_recorded_messages([bag], topics=['/notes'])
    assert only.payloads == tuple(data for *_, data in notes) and only.msgtypes == {
        '/notes': STRING
    }


def test_a_topic_of_two_types_in_two_bags_is_refused(tmp_path):
    first = rosbags_bag(tmp_path / 'a', [('/x', STRING, 1, text('a'))])
    second = rosbags_bag(tmp_path / 'b', [('/x', WRENCH, 2, wrench(0, 1.0))])
    with pytest.raises(BagError, match=f'{tmp_path / "b"}: topic /x is {WRENCH} here'):
        read_recorded_messages([first, second])


def test_replay_and_read_bags_say_the_same_about_a_wrong_path(tmp_path):
    (tmp_path / 'empty').mkdir()
    (tmp_path / 'notes.txt').write_text('not a bag')
    for path, message in (
        (tmp_path / 'nowhere', 'nowhere: no such bag directory or .mcap file'),
        (tmp_path / 'empty', 'empty: not a rosbag2 bag (no metadata.yaml and no .mcap file)'),
        (tmp_path / 'notes.txt', 'notes.txt: not a bag (expected a rosbag2 directory'),
    ):
        for reader in (read_recorded_messages, read_bags, open_bag):
            with pytest.raises(BagError) as caught:
                reader([path]) if reader is not open_bag else reader(path)
            assert str(caught.value).startswith(f'{path.parent}/{message}'), (reader, caught.value)


def test_a_bag_whose_recorder_has_not_closed_it_is_opened_as_unfinished(tmp_path):
    bag = rosbags_bag(tmp_path / 'run', [('/notes', STRING, 5, text('only'))])
    assert open_bag(bag).unfinished is False and len(open_bag(bag).files) == 1
    (bag / 'metadata.yaml').unlink()
    opened = open_bag(bag)
    assert opened.unfinished is True and opened.files == tuple(sorted(bag.glob('*.mcap')))
    assert read_recorded_messages([bag]).payloads == (text('only'),)
