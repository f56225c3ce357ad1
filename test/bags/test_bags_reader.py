"""read_bags: campaign bags to arrays, and errors a person can act on."""

import shutil
import struct

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as RosbagsWriter
from rosbags.typesys import get_typestore, Stores

from balance_calib.bags.errors import BagError
from balance_calib.bags.reader import _decode_header_and_doubles, read_bags, TopicNames
from balance_calib.bags.writer import BagWriter

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
T = TYPESTORE.types
WRENCH = 'geometry_msgs/msg/WrenchStamped'
GRAVITY = 'geometry_msgs/msg/Vector3Stamped'
TEMPERATURE = 'sensor_msgs/msg/Temperature'
NAN6 = [float('nan')] * 6


def header(stamp_ns, frame_id='LMC6522'):
    return T['std_msgs/msg/Header'](
        T['builtin_interfaces/msg/Time'](stamp_ns // 10**9, stamp_ns % 10**9), frame_id
    )


def cdr(message, little_endian=True):
    return TYPESTORE.serialize_cdr(message, message.__msgtype__, little_endian=little_endian)


def wrench(stamp_ns, six, frame_id='LMC6522'):
    vector = T['geometry_msgs/msg/Vector3']
    return T[WRENCH](
        header(stamp_ns, frame_id),
        T['geometry_msgs/msg/Wrench'](vector(*six[:3]), vector(*six[3:])),
    )


def gravity(stamp_ns, three):
    return T[GRAVITY](header(stamp_ns), T['geometry_msgs/msg/Vector3'](*three))


def temperature(stamp_ns, celsius):
    return T[TEMPERATURE](header(stamp_ns), celsius, 0.01)


def write_bag(path, records, types=None):
    """records: (topic, receive time ns, message); a rosbag2 directory via BagWriter."""
    with BagWriter(path) as writer:
        for topic, _, message in records:
            writer.add_topic(topic, (types or {}).get(topic, message.__msgtype__))
        for topic, time_ns, message in records:
            writer.write(topic, time_ns, cdr(message))
    return path


def campaign(t0, points, rng):
    """A small calibration sequence: gravity, then per point a load and ten raw samples."""
    records = [
        ('/calibration/gravity', t0, gravity(t0 - 1, (0.0, 1.0, 0.0))),
        ('/balance/temperature', t0 + 1, temperature(t0, 21.5)),
    ]
    for point in range(points):
        start = t0 + 1_000_000 * (point + 1)
        load = NAN6 if point == 1 else list(rng.normal(size=6) * 100)
        records.append(('/calibration/applied_load', start, wrench(start - 10, load, '')))
        records += [
            (
                '/balance/raw',
                start + 1000 * k + 7,
                wrench(start + 1000 * k, list(rng.normal(size=6))),
            )
            for k in range(1, 11)
        ]
    return records


def expected_raw(records):
    raw = sorted((r for r in records if r[0] == '/balance/raw'), key=lambda r: r[1])
    values = np.array(
        [
            [
                m.wrench.force.x,
                m.wrench.force.y,
                m.wrench.force.z,
                m.wrench.torque.x,
                m.wrench.torque.y,
                m.wrench.torque.z,
            ]
            for _, _, m in raw
        ]
    )
    return np.array([r[1] for r in raw]), values


def test_arrays_hold_every_topic_in_interface_order_and_units(tmp_path):
    records = campaign(1_700_000_000_000_000_000, 4, np.random.default_rng(1))
    data = read_bags(
        write_bag(tmp_path / 'bag', records),
        required=('raw', 'applied_load', 'gravity', 'temperature'),
    )
    times, values = expected_raw(records)
    np.testing.assert_array_equal(data.raw.times_ns, times)
    np.testing.assert_array_equal(data.raw.stamps_ns, times - 7)
    np.testing.assert_array_equal(data.raw.values, values)
    assert data.raw.values.shape == (40, 6) and set(data.raw.frame_ids) == {'LMC6522'}
    assert data.applied_load.values.shape == (4, 6)
    assert np.isnan(data.applied_load.values[1]).all()  # "between points" row kept
    assert not np.isnan(data.applied_load.values[[0, 2, 3]]).any()
    np.testing.assert_array_equal(data.gravity.vectors, [[0.0, 1.0, 0.0]])
    np.testing.assert_array_equal(data.temperature.values, [21.5])
    assert data.temperature.stamps_ns.tolist() == [1_700_000_000_000_000_000]
    with pytest.raises(ValueError):
        data.raw.values[0, 0] = 1.0  # the result is immutable


def test_several_bags_of_both_kinds_merge_in_time_order(tmp_path):
    rng = np.random.default_rng(2)
    first = campaign(1_700_000_000_000_000_000, 3, rng)
    second = campaign(1_700_000_000_000_000_000 + 500_000, 3, rng)  # interleaves with first
    write_bag(tmp_path / 'first', first)
    write_bag(tmp_path / 'second', second)
    bare = tmp_path / 'second.mcap'
    shutil.move(tmp_path / 'second' / 'second_0.mcap', bare)
    data = read_bags([bare, tmp_path / 'first'])
    times, values = expected_raw(first + second)
    np.testing.assert_array_equal(data.raw.times_ns, times)
    np.testing.assert_array_equal(data.raw.values, values)
    assert np.all(np.diff(data.applied_load.times_ns) > 0)
    assert len(data.gravity) == 2
    assert data.sources == (bare, tmp_path / 'first')


def test_remapped_topics_and_extra_topics(tmp_path):
    records = [
        ('/rig/raw', 10, wrench(5, [1, 2, 3, 4, 5, 6])),
        ('/rig/raw', 20, wrench(15, [6, 5, 4, 3, 2, 1])),
        ('/rig/note', 15, T['std_msgs/msg/String']('zero point')),
    ]
    data = read_bags(
        write_bag(tmp_path / 'bag', records),
        topics=TopicNames(raw='/rig/raw'),
        extra_topics=['/rig/note'],
    )
    np.testing.assert_array_equal(data.raw.values[:, 0], [1, 6])
    assert data.extra['/rig/note'].messages[0].data == 'zero point'
    assert data.extra['/rig/note'].times_ns.tolist() == [15]
    assert len(data.applied_load) == 0 and data.applied_load.values.shape == (0, 6)


def test_bags_written_by_other_tools_are_read(tmp_path):
    """Rosbags' own writer stands in for `ros2 bag record` (different file names, no chunk CRC)."""
    with RosbagsWriter(tmp_path / 'other', version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connection = writer.add_connection('/balance/raw', WRENCH, typestore=TYPESTORE)
        for i in range(5):
            writer.write(connection, 100 + i, cdr(wrench(i, [i] * 6)))
    data = read_bags(tmp_path / 'other')
    np.testing.assert_array_equal(data.raw.values[:, 5], np.arange(5.0))


def test_progress_is_reported_up_to_the_total(tmp_path):
    records = [('/balance/raw', i, wrench(i, [i] * 6)) for i in range(25_000)]
    calls = []
    read_bags(
        write_bag(tmp_path / 'bag', records),
        progress=lambda done, total: calls.append((done, total)),
    )
    assert calls[-1] == (25_000, 25_000)
    assert [done for done, _ in calls] == sorted(done for done, _ in calls) and len(calls) > 1


@settings(max_examples=60, deadline=None)
@given(
    frame_ids=st.lists(st.text(max_size=12), min_size=1, max_size=8),
    values=st.lists(
        st.floats(allow_nan=True, allow_infinity=True, width=64), min_size=6, max_size=6
    ),
    stamp_ns=st.integers(min_value=0, max_value=2**31 * 10**9 - 1 - 16),  # + index below
    little_endian=st.booleans(),
)
def test_vectorised_cdr_decoding_equals_rosbags_deserialisation(
    frame_ids, values, stamp_ns, little_endian
):
    payloads = [
        cdr(wrench(stamp_ns + i, values, frame_id), little_endian)
        for i, frame_id in enumerate(frame_ids)
    ]
    payloads.append(cdr(wrench(stamp_ns, values[::-1], 'x'), not little_endian))
    stamps_ns, decoded, decoded_frame_ids = _decode_header_and_doubles(payloads, 6)
    for i, payload in enumerate(payloads):
        message = TYPESTORE.deserialize_cdr(payload, WRENCH)
        force, torque = message.wrench.force, message.wrench.torque
        np.testing.assert_array_equal(
            decoded[i], [force.x, force.y, force.z, torque.x, torque.y, torque.z]
        )
        assert decoded_frame_ids[i] == message.header.frame_id
        assert stamps_ns[i] == message.header.stamp.sec * 10**9 + message.header.stamp.nanosec


# -- errors ---------------------------------------------------------------------------------------


def test_missing_path_names_it(tmp_path):
    with pytest.raises(
        BagError, match=f'{tmp_path / "nowhere"}: no such bag directory or .mcap file'
    ):
        read_bags([tmp_path / 'nowhere'])


def test_a_directory_without_metadata_or_a_foreign_file_is_not_a_bag(tmp_path):
    (tmp_path / 'empty').mkdir()
    with pytest.raises(BagError, match=f'{tmp_path / "empty"}: not a rosbag2 bag'):
        read_bags(tmp_path / 'empty')
    (tmp_path / 'notes.txt').write_text('hello')
    with pytest.raises(BagError, match='notes.txt: not a bag'):
        read_bags(tmp_path / 'notes.txt')


def _recording_in_progress(tmp_path, name, content):
    """A bag directory as a recorder leaves it while it writes: the file so far, no metadata."""
    bag = tmp_path / name
    bag.mkdir()
    (bag / f'{name}_0.mcap').write_bytes(content)
    return bag


def test_a_bag_still_being_recorded_is_read_up_to_what_is_on_disk(tmp_path):
    records = [
        ('/balance/raw', i, wrench(i, [i, -i, 2 * i, 0.5, i * i, 3.0])) for i in range(3000)
    ]
    with BagWriter(tmp_path / 'done', chunk_size_bytes=8192) as writer:
        writer.add_topic('/balance/raw', WRENCH)
        for topic, time_ns, message in records:
            writer.write(topic, time_ns, cdr(message))
    finished = (tmp_path / 'done' / 'done_0.mcap').read_bytes()
    chunks, counts = _chunks_and_counts(tmp_path / 'done' / 'done_0.mcap')
    assert len(chunks) > 6 and counts == {'/balance/raw': 3000}
    # a writer only appends: the file being recorded is a prefix of the finished one
    for k, into in [(1, 20), (3, 0), (5, chunks[5].chunk_length // 2), (len(chunks) - 1, 9)]:
        cut = chunks[k].chunk_start_offset + into
        bag = _recording_in_progress(tmp_path, f'live{k}_{into}', finished[:cut])
        data = read_bags(bag)
        on_disk = chunks[k - 1].message_end_time + 1  # log times are 0, 1, 2, ...: whole chunks
        np.testing.assert_array_equal(data.raw.values, expected_raw(records[:on_disk])[1])
        assert len(data.losses) == 1 and 'still being recorded' in data.losses[0]
        assert f'read the {on_disk} messages on disk so far' in data.losses[0]
    # nothing flushed yet: the required topic is missing, and the reason is said
    early = _recording_in_progress(
        tmp_path, 'early', finished[: chunks[0].chunk_start_offset + 30]
    )
    with pytest.raises(
        BagError, match=r'early: no messages on /balance/raw.*still being recorded'
    ):
        read_bags(early)
    # the recording closed its file but not (yet) metadata.yaml: the whole file, nothing said
    whole = read_bags(_recording_in_progress(tmp_path, 'whole', finished))
    assert len(whole.raw) == 3000 and whole.losses == ()
    # damage inside a complete chunk of a file being recorded is still damage
    damaged = bytearray(finished[: chunks[4].chunk_start_offset])
    middle = chunks[2].chunk_start_offset + chunks[2].chunk_length // 2
    damaged[middle : middle + 8] = bytes(b ^ 0xA5 for b in damaged[middle : middle + 8])
    with pytest.raises(
        BagError, match=f'damaged data at byte offset {chunks[2].chunk_start_offset}'
    ):
        read_bags(_recording_in_progress(tmp_path, 'damaged', bytes(damaged)))


@pytest.mark.parametrize('bare', [True, False])
def test_truncated_mcap_names_the_file(tmp_path, bare):
    records = [('/balance/raw', i, wrench(i, [i] * 6)) for i in range(2000)]
    bag = write_bag(tmp_path / 'bag', records)
    mcap_path = bag / 'bag_0.mcap'
    content = mcap_path.read_bytes()
    mcap_path.write_bytes(content[: len(content) // 2])
    target = mcap_path if bare else bag
    with pytest.raises(BagError, match=f'{mcap_path}: truncated or damaged: no valid footer'):
        read_bags(target)


def test_wrong_message_type_names_file_topic_and_types(tmp_path):
    array = T['std_msgs/msg/Float64MultiArray'](
        T['std_msgs/msg/MultiArrayLayout']([], 0), np.zeros(6)
    )
    bag = write_bag(tmp_path / 'bag', [('/balance/raw', 1, array)])
    with pytest.raises(BagError) as error:
        read_bags(bag)
    assert str(error.value) == (
        f'{bag / "bag_0.mcap"}: topic /balance/raw has type '
        f'std_msgs/msg/Float64MultiArray, expected {WRENCH}'
    )


def test_required_topic_without_messages_names_bag_and_topic(tmp_path):
    bag = write_bag(tmp_path / 'bag', [('/balance/raw', 1, wrench(1, [0] * 6))])
    read_bags(bag)  # applied_load is optional by default
    with pytest.raises(
        BagError,
        match=f'{bag}: no messages on /calibration/applied_load, '
        'which is required .topics in the bag: /balance/raw',
    ):
        read_bags(bag, required=('raw', 'applied_load'))


def test_corrupt_payload_names_file_and_topic(tmp_path):
    bag = tmp_path / 'bag'
    with BagWriter(bag) as writer:
        writer.add_topic('/balance/raw', WRENCH)
        writer.write('/balance/raw', 1, cdr(wrench(1, [0] * 6))[:30])
    with pytest.raises(
        BagError, match=f'{bag / "bag_0.mcap"}: topic /balance/raw: message 0 is shorter'
    ):
        read_bags(bag)


def test_damaged_chunk_names_the_file(tmp_path):
    bag = write_bag(
        tmp_path / 'bag', [('/balance/raw', i, wrench(i, [i] * 6)) for i in range(20_000)]
    )
    mcap_path = bag / 'bag_0.mcap'
    content = bytearray(mcap_path.read_bytes())
    content[1000:1100] = bytes(b ^ 0x55 for b in content[1000:1100])
    mcap_path.write_bytes(bytes(content))
    with pytest.raises(BagError, match=f'{mcap_path}: damaged data at byte offset \\d+: '):
        read_bags(bag)


# -- integrity: counted against the file's own summary and index ---------------------------------


def _campaign_mcap(path, *, crcs, compression='zstd'):
    from balance_calib.benchmarks.refit_reliability import (
        campaign_events,
        small_campaign,
        write_mcap,
    )

    return write_mcap(
        campaign_events(small_campaign('lmc6522', seed=1)),
        path,
        crcs=crcs,
        compression=compression,
    )


def _chunks_and_counts(path):
    """Chunk offsets and per-topic message counts, as the mcap package reads the summary."""
    from mcap.reader import make_reader

    with open(path, 'rb') as stream:
        summary = make_reader(stream).get_summary()
    topics = {c.id: c.topic for c in summary.channels.values()}
    counts = {}
    for channel_id, count in summary.statistics.channel_message_counts.items():
        counts[topics[channel_id]] = counts.get(topics[channel_id], 0) + count
    return sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset), counts


@pytest.mark.parametrize('crcs', [True, False], ids=['chunk CRCs', 'no CRCs'])
def test_a_damaged_chunk_is_an_error_at_its_offset_and_salvage_says_what_was_lost(tmp_path, crcs):
    path = _campaign_mcap(tmp_path / 'campaign.mcap', crcs=crcs)
    chunks, counts = _chunks_and_counts(path)
    victim = chunks[len(chunks) // 2]
    data = bytearray(path.read_bytes())
    if crcs:
        # flip bytes in the compressed records, well inside the chunk (its header is ~60 bytes)
        where = victim.chunk_start_offset + victim.chunk_length // 2
    else:
        # without a CRC, bytes flipped among zstd's literals decompress into wrong message bytes
        # that only the counts catch, and where the literals lie depends on the simulated floats
        # (the middle of the chunk was a decoding error on the CI machine of 2026-12-02 morning,
        # a literal on this one, same pins); damaged, the frame header cannot decompress
        # opcode, length, start and end time, uncompressed size and CRC
        start = victim.chunk_start_offset + 1 + 8 + 8 + 8 + 8 + 4
        (name_length,) = struct.unpack_from('<I', data, start)
        where = start + 4 + name_length + 8  # compression name, then the records' length
    data[where : where + 8] = bytes(b ^ 0xA5 for b in data[where : where + 8])
    path.write_bytes(bytes(data))
    with pytest.raises(
        BagError, match=f'{path}: damaged data at byte offset {victim.chunk_start_offset}: '
    ):
        read_bags(path)
    salvaged = read_bags(path, salvage=True, required=('raw', 'applied_load', 'gravity'))
    assert f'byte offset {victim.chunk_start_offset}' in salvaged.losses[0]
    shortfall = {t: n - salvaged.message_counts.get(t, 0) for t, n in counts.items()}
    assert any('do not match the summary' in line for line in salvaged.losses)
    # the per-topic sequence gaps account for exactly the messages the summary says are missing
    import re

    gaps = {
        m.group(1): int(m.group(2))
        for line in salvaged.losses
        for m in [re.search(r': (/\S+): (\d+) message\(s\) missing', line)]
        if m
    }
    assert gaps == {t: n for t, n in shortfall.items() if n}
    assert sum(gaps.values()) > 0
    assert all(len(line.splitlines()) == 1 for line in salvaged.losses)


def test_a_chunk_skipped_by_a_lenient_reader_is_counted_missing(tmp_path):
    """A chunk whose opcode is damaged looks like a record a reader may skip; the counts catch
    it.
    """
    path = _campaign_mcap(tmp_path / 'campaign.mcap', crcs=False)
    chunks, counts = _chunks_and_counts(path)
    data = bytearray(path.read_bytes())
    data[chunks[1].chunk_start_offset] = 0x07  # now a "message index" record
    path.write_bytes(bytes(data))
    with pytest.raises(
        BagError, match=f'{path}: .*chunk at byte offset {chunks[1].chunk_start_offset}'
    ):
        read_bags(path)
    salvaged = read_bags(path, salvage=True)
    assert any(
        f'/balance/raw {salvaged.message_counts["/balance/raw"]} of {counts["/balance/raw"]}'
        in line
        for line in salvaged.losses
    )


def test_messages_missing_from_a_topic_sequence_are_an_error(tmp_path):
    from mcap.writer import Writer

    path = tmp_path / 'gap.mcap'
    with open(path, 'wb') as stream:
        writer = Writer(stream)
        writer.start(profile='ros2', library='test')
        schema = writer.register_schema(
            name=WRENCH,
            encoding='ros2msg',
            data=TYPESTORE.generate_msgdef(WRENCH, ros_version=2)[0].encode(),
        )
        channel = writer.register_channel(
            topic='/balance/raw', message_encoding='cdr', schema_id=schema
        )
        for sequence in [*range(0, 50), *range(53, 100)]:  # 3 lost by the recorder
            writer.add_message(
                channel_id=channel,
                log_time=sequence * 1000,
                publish_time=sequence * 1000,
                sequence=sequence,
                data=cdr(wrench(sequence * 1000, [1.0] * 6)),
            )
        writer.finish()
    with pytest.raises(
        BagError,
        match=r'gap.mcap: /balance/raw: 3 message\(s\) missing \(sequence jumps '
        r'from 49 to 53 at log time 53000 ns',
    ):
        read_bags(path)
    assert len(read_bags(path, salvage=True).raw) == 97


def test_a_truncated_file_salvages_its_complete_chunks(tmp_path):
    path = _campaign_mcap(tmp_path / 'campaign.mcap', crcs=True)
    chunks, counts = _chunks_and_counts(path)
    cut = chunks[3].chunk_start_offset + 20  # inside the fourth chunk
    path.write_bytes(path.read_bytes()[:cut])
    with pytest.raises(BagError, match=f'{path}: truncated or damaged: no valid footer'):
        read_bags(path)
    salvaged = read_bags(path, salvage=True)
    assert any(f'byte offset {chunks[3].chunk_start_offset}' in line for line in salvaged.losses)
    assert 0 < sum(salvaged.message_counts.values()) < sum(counts.values())


@pytest.mark.parametrize(
    'content',
    [b'', b'\x89MCAP0\r\n', b'\x89MCAP0\r\n' * 3 + b'\x00' * 5],
    ids=['empty', 'magic only', 'magic and zeros'],
)
def test_tiny_files_name_the_file(tmp_path, content):
    path = tmp_path / 'tiny.mcap'
    path.write_bytes(content)
    with pytest.raises(BagError, match=f'{path}: '):
        read_bags(path)


def test_a_fifo_is_refused_without_opening_it(tmp_path):
    import os

    fifo = tmp_path / 'campaign.mcap'
    os.mkfifo(fifo)
    # opening a FIFO for reading blocks until a writer comes: the check must come first
    with pytest.raises(BagError, match=f'{fifo}: is a FIFO, not an MCAP file'):
        read_bags(fifo)
