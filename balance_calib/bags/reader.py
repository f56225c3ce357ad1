"""Read calibration bags into one array per topic.

A campaign may be one bag or several (rosbag2 directories with metadata.yaml + *.mcap, or bare
.mcap files, in any mix); all their messages are merged and sorted by receive time. The topics of
docs/interfaces.md come back as arrays:

    raw            /balance/raw                WrenchStamped   values (N, 6) mV:
                                                               F_XV, F_YV, F_ZV, M_XV, M_YV, M_ZV
    applied_load   /calibration/applied_load   WrenchStamped   values (M, 6) N, N*m (NaN rows
                                                               kept: "between points")
    gravity        /calibration/gravity        Vector3Stamped  vectors (K, 3), unit, balance axes
    temperature    /balance/temperature        Temperature     values (L,) degC

The messages of these four types are decoded straight from their CDR bytes, all at once with
numpy (a header and a row of float64, see _decode_header_and_doubles); any other topic asked for
comes back as deserialized messages (rosbags). The MCAP files are walked record by record and
checked against their own summary and index (bags/mcap_scan.py); the one Python loop left is the
per-message append.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
import os
from pathlib import Path
from typing import Any, Callable, Collection, Iterable, Mapping, Sequence

import numpy as np
from rosbags.typesys import get_types_from_msg, get_typestore, Stores

from balance_calib.bags.errors import BagError
from balance_calib.bags.mcap_scan import McapDamage, Scan, scan_mcap, STILL_RECORDING
from balance_calib.bags.opening import open_bag

ProgressCallback = Callable[[int, int], None]
BagPath = str | os.PathLike

_PROGRESS_EVERY = 10_000


@dataclass(frozen=True)
class TopicNames:
    """Where each stream lives (defaults: docs/interfaces.md; topics are remappable)."""

    raw: str = '/balance/raw'
    applied_load: str = '/calibration/applied_load'
    gravity: str = '/calibration/gravity'
    temperature: str = '/balance/temperature'


# TopicNames field -> (message type, float64 fields after its header, how many of them we keep)
_LAYOUTS: dict[str, tuple[str, int, int]] = {
    'raw': ('geometry_msgs/msg/WrenchStamped', 6, 6),
    'applied_load': ('geometry_msgs/msg/WrenchStamped', 6, 6),
    'gravity': ('geometry_msgs/msg/Vector3Stamped', 3, 3),
    'temperature': ('sensor_msgs/msg/Temperature', 2, 1),  # temperature, variance
}


def _frozen(array: np.ndarray) -> np.ndarray:
    array.flags.writeable = False
    return array


@dataclass(frozen=True)
class StampedSeries:
    """One topic of stamped numbers, sorted by receive time.

    times_ns (N,) int64: receive (bag log) time, ns since the epoch.
    stamps_ns (N,) int64: header.stamp, ns since the epoch.
    values (N, k) or (N,) float64: the payload, units as the topic defines them.
    frame_ids (N,) str: header.frame_id.
    """

    times_ns: np.ndarray
    stamps_ns: np.ndarray
    values: np.ndarray
    frame_ids: np.ndarray

    def __len__(self) -> int:
        return len(self.times_ns)

    @classmethod
    def empty(cls, width: int) -> 'StampedSeries':
        shape = (0, width) if width > 1 else (0,)
        return cls(
            *(
                _frozen(a)
                for a in (
                    np.zeros(0, np.int64),
                    np.zeros(0, np.int64),
                    np.zeros(shape),
                    np.zeros(0, dtype=str),
                )
            )
        )


@dataclass(frozen=True)
class GravitySeries(StampedSeries):
    """/calibration/gravity: values (K, 3) are unit gravity vectors in balance axes."""

    @property
    def vectors(self) -> np.ndarray:
        return self.values


@dataclass(frozen=True)
class TopicMessages:
    """A topic without an array form: its deserialized messages (rosbags dataclasses)."""

    msgtype: str
    times_ns: np.ndarray
    messages: tuple[Any, ...]

    def __len__(self) -> int:
        return len(self.times_ns)


@dataclass(frozen=True)
class BagData:
    """Everything read from the bags of one campaign, merged and sorted by receive time."""

    sources: tuple[Path, ...]
    topics: TopicNames
    raw: StampedSeries
    applied_load: StampedSeries
    gravity: GravitySeries
    temperature: StampedSeries
    extra: Mapping[str, TopicMessages] = field(default_factory=dict)
    losses: tuple[str, ...] = ()  # with salvage: what could not be read, one line each
    message_counts: Mapping[str, int] = field(default_factory=dict)  # read per topic (wanted ones)


def read_bags(
    paths: BagPath | Sequence[BagPath],
    *,
    topics: TopicNames = TopicNames(),
    required: Collection[str] = ('raw',),
    extra_topics: Iterable[str] = (),
    progress: ProgressCallback | None = None,
    salvage: bool = False,
) -> BagData:
    """Read one or more bags (rosbag2 directories or bare .mcap files) of one campaign.

    required names TopicNames fields ('raw', 'applied_load', 'gravity', 'temperature') that must
    have at least one message across all the bags; the others may be absent (empty series).
    extra_topics are returned in BagData.extra, deserialized. progress(done, total) is called
    every few thousand messages and at the end.

    Every file is checked against its own summary and index (bags/mcap_scan.py): a damaged or
    missing chunk, a CRC failure, fewer messages than the summary counts, or a gap in a topic's
    sequence numbers is a BagError naming the file and the byte offset. With salvage, what is
    intact is read and BagData.losses says, one line each, what was lost.

    Raises BagError naming the file (and topic) for: a missing path, a path that is not a bag (a
    FIFO or device is refused before it is opened), a truncated or corrupt file, a topic of the
    wrong message type, a required topic without messages.
    """
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    sources = tuple(Path(p) for p in paths)
    if not sources:
        raise BagError('no bag given')
    unknown = set(required) - {f.name for f in fields(TopicNames)}
    if unknown:
        raise ValueError(
            f'required names unknown streams {sorted(unknown)}; '
            f'choose from {[f.name for f in fields(TopicNames)]}'
        )
    extra_topics = tuple(extra_topics)
    by_topic = {getattr(topics, name): name for name in _LAYOUTS}
    wanted = set(by_topic) | set(extra_topics)

    bags = [open_bag(source) for source in sources]
    scans: list[tuple[Path, Scan]] = []
    losses: list[str] = []
    for bag in bags:
        for mcap_file in bag.files:
            try:
                scan = scan_mcap(mcap_file, wanted, salvage=salvage, unfinished=bag.unfinished)
            except McapDamage as error:
                raise BagError(str(error)) from None
            _check_types(mcap_file, scan, topics)
            losses += scan.losses + _sequence_gaps(mcap_file, scan, salvage)
            scans.append((mcap_file, scan))
    recorded_topics = sorted({c.topic for _, scan in scans for c in scan.channels.values()})
    counts = {t: sum(scan.counts.get(t, 0) for _, scan in scans) for t in wanted}
    still_recording = [line for line in losses if f': {STILL_RECORDING}' in line]
    for name in required:
        if counts[getattr(topics, name)] == 0:
            raise BagError(
                _no_messages(sources, getattr(topics, name), recorded_topics)
                + (
                    '; the bag is still being recorded and holds none on disk yet (its '
                    'recorder writes them in chunks and metadata.yaml when it stops)'
                    if still_recording
                    else ''
                )
            )
    total = sum(counts.values())
    # topic -> one (receive times, CDR payloads, source) per file
    collected: dict[str, list[tuple[list[int], list[bytes], Path]]] = {t: [] for t in wanted}
    msgtypes: dict[str, str] = {}
    done = 0
    for mcap_file, scan in scans:
        for channel in scan.channels.values():
            if channel.topic in wanted:
                msgtypes.setdefault(channel.topic, channel.schema_name)
        for topic, (times, payloads) in scan.messages.items():
            collected[topic].append((times, payloads, mcap_file))
            done += len(times)
            if progress is not None:
                progress(min(done, total), total)
    if progress is not None:
        progress(done, total)
    typestore = _typestore_for(
        [c for _, scan in scans for c in scan.channels.values() if c.topic in extra_topics]
    )

    series = {}
    for topic, name in by_topic.items():
        _, doubles, kept = _LAYOUTS[name]
        kind = GravitySeries if name == 'gravity' else StampedSeries
        if not any(len(times) for times, _, _ in collected[topic]):
            if name in required:
                raise BagError(_no_messages(sources, topic, recorded_topics))
            series[name] = kind.empty(kept)
            continue
        series[name] = _stamped_series(topic, collected[topic], doubles, kept, kind)
    extra = {}
    for topic in extra_topics:
        if topic in by_topic:
            continue
        times = np.array([t for ts, _, _ in collected[topic] for t in ts], dtype=np.int64)
        order = np.argsort(times, kind='stable')
        payloads = [p for _, ps, _ in collected[topic] for p in ps]
        msgtype = msgtypes.get(topic, '')
        try:
            messages = tuple(typestore.deserialize_cdr(payloads[i], msgtype) for i in order)
        except Exception as error:  # rosbags raises assorted errors on bad CDR
            files = ', '.join(str(s) for _, _, s in collected[topic])
            raise BagError(
                f'{files}: cannot decode {topic} messages as {msgtype} ({error})'
            ) from None
        extra[topic] = TopicMessages(msgtype, _frozen(times[order]), messages)
    return BagData(
        sources=sources,
        topics=topics,
        extra=extra,
        losses=tuple(losses),
        message_counts={t: n for t, n in counts.items() if n},
        **series,
    )


# -- checking -------------------------------------------------------------------------------------


def _check_types(source: Path, scan: Scan, topics: TopicNames) -> None:
    for name, (msgtype, _, _) in _LAYOUTS.items():
        topic = getattr(topics, name)
        for channel in scan.channels.values():
            if channel.topic == topic and channel.schema_name != msgtype:
                raise BagError(
                    f'{source}: topic {topic} has type {channel.schema_name}, expected {msgtype}'
                )


def _sequence_gaps(source: Path, scan: Scan, salvage: bool) -> list[str]:
    """Messages missing from a topic whose writer numbers them consecutively (rosbag2, ours)."""
    lost = []
    for topic, sequence in scan.sequences.items():
        numbers = np.asarray(sequence, dtype=np.int64)
        if len(numbers) < 3:
            continue
        steps = np.diff(numbers)
        if np.count_nonzero(steps == 1) < 0.9 * len(steps):
            continue  # not a per-topic counter (all zero, or the publisher's own numbering)
        gaps = np.flatnonzero(steps > 1)
        if not len(gaps):
            continue
        missing = int(np.sum(steps[gaps] - 1))
        first = int(gaps[0])
        problem = (
            f'{source}: {topic}: {missing} message(s) missing (sequence jumps from '
            f'{int(numbers[first])} to {int(numbers[first + 1])} at log time '
            f'{scan.messages[topic][0][first + 1]} ns; {len(gaps)} gap(s))'
        )
        if not salvage:
            raise BagError(problem + ' (--salvage reads what is intact)')
        lost.append(problem)
    return lost


def _no_messages(sources: Sequence[Path], topic: str, recorded: Sequence[str]) -> str:
    where = ', '.join(str(s) for s in sources)
    return (
        f'{where}: no messages on {topic}, which is required '
        f'(topics in the bag: {", ".join(recorded) or "none"})'
    )


def _typestore_for(connections):
    """A typestore knowing Jazzy's types plus the definitions stored in the bags."""
    typestore = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for channel in connections:
        if channel.schema_name not in typestore.fielddefs and channel.schema_encoding == 'ros2msg':
            try:
                types.update(
                    get_types_from_msg(channel.schema_data.decode('utf-8'), channel.schema_name)
                )
            except Exception:  # a definition rosbags cannot parse: decoding fails by name below
                pass
    if types:
        typestore.register(types)
    return typestore


# -- decoding -------------------------------------------------------------------------------------


def _stamped_series(topic: str, parts, doubles: int, kept: int, kind) -> StampedSeries:
    """Decode and merge one topic's messages from all sources, sorted by receive time."""
    times, stamps, values, frame_ids = [], [], [], []
    for part_times, payloads, source in parts:
        if not part_times:
            continue
        try:
            decoded = _decode_header_and_doubles(payloads, doubles)
        except ValueError as error:
            raise BagError(f'{source}: topic {topic}: {error}') from None
        times.append(np.asarray(part_times, dtype=np.int64))
        stamps.append(decoded[0])
        values.append(decoded[1][:, :kept])
        frame_ids.append(decoded[2])
    times = np.concatenate(times)
    order = np.argsort(times, kind='stable')
    values = np.concatenate(values)[order]
    if kept == 1:
        values = values[:, 0]
    return kind(
        _frozen(times[order]),
        _frozen(np.concatenate(stamps)[order]),
        _frozen(np.ascontiguousarray(values)),
        _frozen(np.concatenate(frame_ids)[order]),
    )


def _gather(buffer: np.ndarray, starts: np.ndarray, width: int) -> np.ndarray:
    """Rows of `width` bytes starting at each offset: (N, width) uint8."""
    return buffer[starts[:, None] + np.arange(width)]


def _decode_header_and_doubles(payloads: Sequence[bytes], doubles: int):
    """Decode CDR messages laid out as std_msgs/Header followed by `doubles` float64.

    That is WrenchStamped (6), Vector3Stamped (3) and Temperature (2). CDR (XCDR1): a 4-byte
    encapsulation header (byte 1: 1 little endian, 0 big endian), then int32 sec, uint32 nanosec,
    uint32 string length including its NUL, the string, padding to 8 bytes (counted from after
    the encapsulation header), the doubles.
    Returns stamps_ns (N,) int64, values (N, doubles) float64, frame_ids (N,) str.
    """
    lengths = np.fromiter(map(len, payloads), dtype=np.int64, count=len(payloads))
    buffer = np.frombuffer(b''.join(payloads), dtype=np.uint8)
    starts = np.cumsum(lengths) - lengths
    if np.any(lengths < 16):
        raise ValueError(f'message {int(np.argmax(lengths < 16))} is too short for its type')
    encapsulation = buffer[starts + 1]
    if np.any(encapsulation > 1) or np.any(buffer[starts] != 0):
        raise ValueError('messages are not plain CDR')
    stamps_ns = np.empty(len(payloads), np.int64)
    values = np.empty((len(payloads), doubles))
    string_lengths = np.empty(len(payloads), np.int64)
    for little_endian in (True, False):
        rows = np.flatnonzero(encapsulation == (1 if little_endian else 0))
        if not len(rows):
            continue
        order = '<' if little_endian else '>'
        head = _gather(buffer, starts[rows] + 4, 12)
        sec = head[:, 0:4].copy().view(f'{order}i4')[:, 0].astype(np.int64)
        nanosec = head[:, 4:8].copy().view(f'{order}u4')[:, 0].astype(np.int64)
        string_lengths[rows] = head[:, 8:12].copy().view(f'{order}u4')[:, 0]
        stamps_ns[rows] = sec * 1_000_000_000 + nanosec
        doubles_at = 4 + ((12 + string_lengths[rows] + 7) // 8) * 8
        if np.any(doubles_at + 8 * doubles > lengths[rows]):
            bad = rows[np.argmax(doubles_at + 8 * doubles > lengths[rows])]
            raise ValueError(f'message {int(bad)} is shorter than its type requires')
        raw = _gather(buffer, starts[rows] + doubles_at, 8 * doubles)
        values[rows] = raw.view(f'{order}f8').astype(np.float64)
    return stamps_ns, values, _frame_ids(buffer, starts + 16, string_lengths)


def _frame_ids(buffer: np.ndarray, starts: np.ndarray, lengths_with_nul: np.ndarray) -> np.ndarray:
    """Decode the header strings, one numpy pass per distinct length (usually one)."""
    frame_ids = np.empty(len(starts), dtype=object)
    text_lengths = np.maximum(lengths_with_nul - 1, 0)
    for length in np.unique(text_lengths):
        rows = np.flatnonzero(text_lengths == length)
        if length == 0:
            frame_ids[rows] = ''
            continue
        # void, not 'S': numpy's bytes type drops trailing NULs that belong to the string
        raw = np.ascontiguousarray(_gather(buffer, starts[rows], int(length))).view(f'V{length}')
        unique, inverse = np.unique(raw[:, 0], return_inverse=True)
        names = np.array(
            [bytes(u).decode('utf-8', errors='replace') for u in unique], dtype=object
        )
        frame_ids[rows] = names[inverse.ravel()]
    # object, not numpy's str type, which would drop trailing NULs too
    return frame_ids
