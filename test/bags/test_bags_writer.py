"""BagWriter writes bags that other tools read as `ros2 bag record -s mcap` bags.

Each message is checked through two independent readers (rosbags' AnyReader, and the mcap
package with mcap_ros2's decoder), and the file layout against what rosbag2 (Jazzy) writes:
metadata version 9 with offered QoS, ros2msg schemas, cdr channels, compressed chunks.
"""

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from message_fields import fields_of
import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import get_typestore, Stores
import yaml

from balance_calib.bags.errors import BagError
from balance_calib.bags.writer import BagWriter, qos_profiles_yaml

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
T = TYPESTORE.types
WRENCH = 'geometry_msgs/msg/WrenchStamped'
GRAVITY = 'geometry_msgs/msg/Vector3Stamped'
DIAGNOSTICS = 'diagnostic_msgs/msg/DiagnosticArray'
RELIABLE = qos_profiles_yaml(
    [{'history': 'keep_last', 'depth': 10, 'reliability': 'reliable', 'durability': 'volatile'}]
)
BEST_EFFORT = qos_profiles_yaml([{'reliability': 'best_effort'}, {'reliability': 'reliable'}])


def header(stamp_ns, frame_id):
    return T['std_msgs/msg/Header'](
        T['builtin_interfaces/msg/Time'](stamp_ns // 10**9, stamp_ns % 10**9), frame_id
    )


def wrench(stamp_ns, frame_id, six):
    vector = T['geometry_msgs/msg/Vector3']
    return T[WRENCH](
        header(stamp_ns, frame_id),
        T['geometry_msgs/msg/Wrench'](vector(*six[:3]), vector(*six[3:])),
    )


def gravity(stamp_ns, three):
    return T[GRAVITY](header(stamp_ns, 'balance'), T['geometry_msgs/msg/Vector3'](*three))


def diagnostics(stamp_ns, level):
    status = T['diagnostic_msgs/msg/DiagnosticStatus'](
        level=level,
        name='balance_calibrator: input',
        message='rate ok',
        hardware_id='LMC6522',
        values=[T['diagnostic_msgs/msg/KeyValue']('rate_hz', '1000.0')],
    )
    return T[DIAGNOSTICS](header(stamp_ns, ''), [status])


def campaign_messages():
    """(topic, receive time ns, message) for a small campaign, deliberately not time-sorted."""
    rng = np.random.default_rng(7)
    t0 = 1_700_000_000_123_456_789
    messages = [
        (
            '/balance/raw',
            t0 + 1000 * i + 17,
            wrench(t0 + 1000 * i, 'LMC6522', rng.normal(size=6) * 5.0),
        )
        for i in range(300)
    ]
    messages += [
        ('/calibration/gravity', t0 + 5, gravity(t0, (0.0, 1.0, 0.0))),
        ('/calibration/gravity', t0 + 150_003, gravity(t0 + 150_000, (0.0, 0.0, -1.0))),
    ]
    messages += [
        ('/diagnostics', t0 + 10_000 * i + 3, diagnostics(t0 + 10_000 * i, i % 3))
        for i in range(30)
    ]
    return messages[::-1]


def write_campaign(path, compression='zstd', chunk_size_bytes=4096):
    messages = campaign_messages()
    with BagWriter(path, compression=compression, chunk_size_bytes=chunk_size_bytes) as writer:
        writer.add_topic('/balance/raw', WRENCH, RELIABLE)
        writer.add_topic('/calibration/gravity', GRAVITY, BEST_EFFORT)
        writer.add_topic('/diagnostics', DIAGNOSTICS, RELIABLE)
        for topic, time_ns, message in messages:
            writer.write(topic, time_ns, TYPESTORE.serialize_cdr(message, message.__msgtype__))
    return messages


def expected_in_log_time_order(messages):
    ordered = sorted(messages, key=lambda m: m[1])
    return [(topic, time_ns, fields_of(message)) for topic, time_ns, message in ordered]


def test_rosbags_anyreader_reads_back_every_message_field_and_timestamp(tmp_path):
    messages = write_campaign(tmp_path / 'campaign')
    with AnyReader([tmp_path / 'campaign']) as reader:
        read = [
            (connection.topic, time_ns, fields_of(reader.deserialize(raw, connection.msgtype)))
            for connection, time_ns, raw in reader.messages()
        ]
        assert {c.topic: c.msgtype for c in reader.connections} == {
            '/balance/raw': WRENCH,
            '/calibration/gravity': GRAVITY,
            '/diagnostics': DIAGNOSTICS,
        }
    assert read == expected_in_log_time_order(messages)


def test_mcap_with_mcap_ros2_decoder_reads_back_every_message_field_and_timestamp(tmp_path):
    messages = write_campaign(tmp_path / 'campaign')
    with open(tmp_path / 'campaign' / 'campaign_0.mcap', 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        read = [
            (channel.topic, message.log_time, fields_of(decoded))
            for schema, channel, message, decoded in reader.iter_decoded_messages(
                log_time_order=True
            )
        ]
        schemas = {s.name: s.encoding for s in reader.get_summary().schemas.values()}
    assert read == expected_in_log_time_order(messages)
    assert schemas == {WRENCH: 'ros2msg', GRAVITY: 'ros2msg', DIAGNOSTICS: 'ros2msg'}


@pytest.mark.parametrize('compression', ['zstd', 'lz4'])
def test_messages_live_only_in_compressed_chunks(tmp_path, compression):
    messages = write_campaign(tmp_path / 'campaign', compression=compression)
    mcap_path = tmp_path / 'campaign' / 'campaign_0.mcap'
    assert mcap_path.read_bytes()[:8] == b'\x89MCAP0\r\n'  # not a file-compressed bag
    with open(mcap_path, 'rb') as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        header = reader.get_header()
    assert header.profile == 'ros2'
    assert len(summary.chunk_indexes) > 1
    assert {index.compression for index in summary.chunk_indexes} == {compression}
    assert sum(i.compressed_size for i in summary.chunk_indexes) < sum(
        i.uncompressed_size for i in summary.chunk_indexes
    )
    assert summary.statistics.message_count == len(messages)
    assert {c.message_encoding for c in summary.channels.values()} == {'cdr'}


def test_metadata_is_rosbag2_version_9_with_offered_qos_and_counts(tmp_path):
    messages = write_campaign(tmp_path / 'campaign')
    metadata = yaml.safe_load((tmp_path / 'campaign' / 'metadata.yaml').read_text())
    info = metadata['rosbag2_bagfile_information']
    times = [m[1] for m in messages]
    assert info['version'] == 9
    assert info['storage_identifier'] == 'mcap'
    assert info['relative_file_paths'] == ['campaign_0.mcap']
    assert info['compression_mode'] == '' and info['compression_format'] == ''
    assert info['message_count'] == len(messages)
    assert info['starting_time']['nanoseconds_since_epoch'] == min(times)
    assert info['duration']['nanoseconds'] == max(times) - min(times)
    assert info['files'] == [
        {
            'path': 'campaign_0.mcap',
            'starting_time': {'nanoseconds_since_epoch': min(times)},
            'duration': {'nanoseconds': max(times) - min(times)},
            'message_count': len(messages),
        }
    ]
    topics = {t['topic_metadata']['name']: t for t in info['topics_with_message_count']}
    assert {name: t['message_count'] for name, t in topics.items()} == {
        '/balance/raw': 300,
        '/calibration/gravity': 2,
        '/diagnostics': 30,
    }
    raw = topics['/balance/raw']['topic_metadata']
    assert raw['type'] == WRENCH and raw['serialization_format'] == 'cdr'
    assert raw['type_description_hash'] == TYPESTORE.hash_rihs01(WRENCH)
    # v9 holds the profiles as a YAML list with rmw's policy names
    assert raw['offered_qos_profiles'] == yaml.safe_load(RELIABLE)
    assert raw['offered_qos_profiles'][0]['reliability'] == 'reliable'
    assert raw['offered_qos_profiles'][0]['deadline'] == {'sec': 9223372036, 'nsec': 854775807}
    gravity_qos = topics['/calibration/gravity']['topic_metadata']['offered_qos_profiles']
    assert [q['reliability'] for q in gravity_qos] == ['best_effort', 'reliable']
    assert not list((tmp_path / 'campaign').glob('*.partial'))


def test_channels_carry_qos_yaml_and_type_hash_as_rosbag2_mcap_storage_does(tmp_path):
    write_campaign(tmp_path / 'campaign')
    with open(tmp_path / 'campaign' / 'campaign_0.mcap', 'rb') as stream:
        reader = make_reader(stream)
        channels = {c.topic: c for c in reader.get_summary().channels.values()}
        embedded = {m.name: m.metadata for m in reader.iter_metadata()}
    raw = channels['/balance/raw'].metadata
    assert yaml.safe_load(raw['offered_qos_profiles']) == yaml.safe_load(RELIABLE)
    assert raw['topic_type_hash'] == TYPESTORE.hash_rihs01(WRENCH)
    inner = yaml.safe_load(embedded['rosbag2']['serialized_metadata'])
    assert inner['version'] == 9 and inner['message_count'] == 332


def test_rosbags_reports_the_offered_qos_profiles(tmp_path):
    write_campaign(tmp_path / 'campaign')
    with AnyReader([tmp_path / 'campaign']) as reader:
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
    assert [q.reliability.name for q in qos['/calibration/gravity']] == ['BEST_EFFORT', 'RELIABLE']
    assert qos['/balance/raw'][0].depth == 10


def test_refuses_to_overwrite_an_existing_bag(tmp_path):
    (tmp_path / 'campaign').mkdir()
    with pytest.raises(BagError, match='exists already'):
        BagWriter(tmp_path / 'campaign').open()


def test_writing_an_undeclared_topic_names_bag_and_topic(tmp_path):
    with BagWriter(tmp_path / 'campaign') as writer:
        with pytest.raises(BagError, match=r'campaign.*/balance/raw'):
            writer.write('/balance/raw', 1, b'\x00\x01\x00\x00')


def test_an_empty_bag_is_still_complete(tmp_path):
    with BagWriter(tmp_path / 'empty') as writer:
        writer.add_topic('/balance/raw', WRENCH, RELIABLE)
    with AnyReader([tmp_path / 'empty']) as reader:
        assert reader.message_count == 0
        assert [c.topic for c in reader.connections] == ['/balance/raw']
