"""Read an MCAP file record by record, checking it against its own summary and index.

Every record of the data section is walked in file order; each chunk is checked against its
chunk index (offset, length, compressed and uncompressed size), its CRC (when the writer stored
one), and its records must parse exactly to its end. The messages read are then counted per
channel against the summary's Statistics record. Any mismatch is an error naming the file and
the byte offset. With salvage, a damaged chunk is skipped (the scan resumes at the next chunk the
index knows) and the losses are returned as one line each: what was lost, where, and how many
messages per topic the summary says are missing.

Memory: the file is mapped, not read; the payloads kept are the messages asked for; a chunk is
copied and decompressed one at a time.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import mmap
import os
from pathlib import Path
import stat
import struct
from typing import Collection
import zlib

MAGIC = b'\x89MCAP0\r\n'
_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE = 0x01, 0x02, 0x03, 0x04, 0x05
_OP_CHUNK, _OP_MESSAGE_INDEX, _OP_CHUNK_INDEX, _OP_STATISTICS, _OP_DATA_END = (
    0x06,
    0x07,
    0x08,
    0x0B,
    0x0F,
)
_RECORD_HEAD = struct.Struct('<BQ')
_MESSAGE_HEAD = struct.Struct('<HIQQ')
_FOOTER = struct.Struct('<BQQQI')  # opcode, length, summary_start, summary_offset_start, crc
_MAX_RECORD = 1 << 34  # a longer record length is damage, not data
STILL_RECORDING = 'still being recorded'  # the loss line of a file read while it is written


class McapDamage(ValueError):
    """The file is not intact; the message names the file and the offset."""


@dataclass
class Channel:
    id: int
    topic: str
    schema_name: str
    schema_encoding: str
    schema_data: bytes
    message_encoding: str


@dataclass
class ChunkIndex:
    start: int
    length: int
    compressed_size: int
    uncompressed_size: int


@dataclass
class Scan:
    """What one file holds: channels, the wanted messages and what was lost."""

    path: Path
    channels: dict[int, Channel] = field(default_factory=dict)
    # topic -> (log times ns, payloads)
    messages: dict[str, tuple[list[int], list[bytes]]] = field(default_factory=dict)
    sequences: dict[str, list[int]] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)  # messages read per topic
    expected: dict[str, int] | None = None  # per topic from the summary
    losses: list[str] = field(default_factory=list)


def check_regular_file(path: Path) -> None:
    """A FIFO, device or socket would block or never end: refuse it before opening."""
    try:
        mode = path.stat().st_mode
    except OSError as error:
        raise McapDamage(f'{path}: cannot read ({error.strerror})') from None
    if not stat.S_ISREG(mode):
        kind = (
            'a FIFO'
            if stat.S_ISFIFO(mode)
            else 'a device'
            if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
            else 'a socket'
            if stat.S_ISSOCK(mode)
            else 'a directory'
            if stat.S_ISDIR(mode)
            else 'not a regular file'
        )
        raise McapDamage(f'{path}: is {kind}, not an MCAP file')


def _string(buffer, at: int) -> tuple[str, int]:
    (length,) = struct.unpack_from('<I', buffer, at)
    end = at + 4 + length
    if end > len(buffer):
        raise ValueError('string runs past its record')
    return bytes(buffer[at + 4 : end]).decode('utf-8'), end


def _bytes(buffer, at: int, width: str = '<I') -> tuple[bytes, int]:
    (length,) = struct.unpack_from(width, buffer, at)
    start = at + struct.calcsize(width)
    if start + length > len(buffer):
        raise ValueError('byte array runs past its record')
    return bytes(buffer[start : start + length]), start + length


class _Reader:
    def __init__(
        self, path: Path, wanted: Collection[str] | None, salvage: bool, unfinished: bool = False
    ):
        self.path, self.wanted, self.salvage, self.unfinished = path, wanted, salvage, unfinished
        self.scan = Scan(path)
        self.schemas: dict[int, tuple[str, str, bytes]] = {}
        self.pending_channels: dict[int, tuple[int, str, str]] = {}

    # -- records ----------------------------------------------------------------------------------

    def _schema(self, content) -> None:
        (schema_id,) = struct.unpack_from('<H', content, 0)
        name, at = _string(content, 2)
        encoding, at = _string(content, at)
        data, _ = _bytes(content, at)
        self.schemas[schema_id] = (name, encoding, data)

    def _channel(self, content) -> None:
        channel_id, schema_id = struct.unpack_from('<HH', content, 0)
        topic, at = _string(content, 4)
        encoding, _ = _string(content, at)
        name, schema_encoding, data = self.schemas.get(schema_id, ('', '', b''))
        if channel_id not in self.scan.channels:
            self.scan.channels[channel_id] = Channel(
                channel_id, topic, name, schema_encoding, data, encoding
            )

    def _message(self, content, offset: int) -> None:
        if len(content) < _MESSAGE_HEAD.size:
            raise ValueError('message record too short')
        channel_id, sequence, log_time, _ = _MESSAGE_HEAD.unpack_from(content, 0)
        channel = self.scan.channels.get(channel_id)
        if channel is None:
            raise ValueError(f'message on channel {channel_id}, which no channel record declared')
        topic = channel.topic
        self.scan.counts[topic] = self.scan.counts.get(topic, 0) + 1
        if self.wanted is None or topic in self.wanted:
            times, payloads = self.scan.messages.setdefault(topic, ([], []))
            times.append(log_time)
            payloads.append(bytes(content[_MESSAGE_HEAD.size :]))
            self.scan.sequences.setdefault(topic, []).append(sequence)

    def _records(self, buffer: bytes, base_offset: int) -> None:
        """Walk records of a chunk's data (or nothing else); they must end exactly at its end.

        The messages are what _message would keep, one at a time; the loop is _message inlined
        (a campaign bag holds ~10^5 of them): each channel's lists looked up once, the counts
        added per channel when the chunk has been walked whole.
        """
        record_head, message_head = _RECORD_HEAD.unpack_from, _MESSAGE_HEAD.unpack_from
        head_size = _MESSAGE_HEAD.size
        # channel id -> (times.append, payloads.append, sequences.append), None if not wanted
        sinks: dict[int, tuple | None] = {}
        counted: dict[int, int] = {}  # messages per channel in this chunk
        at, end = 0, len(buffer)
        while at < end:
            if at + 9 > end:
                raise ValueError(f'record header cut at byte {base_offset + at}')
            opcode, length = record_head(buffer, at)
            start = at + 9
            at = start + length
            if at > end:
                raise ValueError(
                    f'record at byte {base_offset + start - 9} runs past the chunk end'
                )
            if opcode == _OP_MESSAGE:
                if length < head_size:
                    raise ValueError('message record too short')
                channel_id, sequence, log_time, _ = message_head(buffer, start)
                if channel_id in sinks:
                    counted[channel_id] += 1
                else:
                    sinks[channel_id] = self._sink(channel_id)
                    counted[channel_id] = 1
                sink = sinks[channel_id]
                if sink is not None:
                    sink[0](log_time)
                    sink[1](buffer[start + head_size : at])
                    sink[2](sequence)
            elif opcode == _OP_SCHEMA:
                self._schema(memoryview(buffer)[start:at])
            elif opcode == _OP_CHANNEL:
                self._channel(memoryview(buffer)[start:at])
        counts = self.scan.counts
        for channel_id, count in counted.items():
            topic = self.scan.channels[channel_id].topic
            counts[topic] = counts.get(topic, 0) + count

    def _sink(self, channel_id: int) -> tuple | None:
        """The appends of channel_id's times, payloads and sequence numbers (None: a topic not
        wanted); ValueError for a channel no channel record declared.
        """
        channel = self.scan.channels.get(channel_id)
        if channel is None:
            raise ValueError(f'message on channel {channel_id}, which no channel record declared')
        topic = channel.topic
        if self.wanted is not None and topic not in self.wanted:
            return None
        times, payloads = self.scan.messages.setdefault(topic, ([], []))
        return times.append, payloads.append, self.scan.sequences.setdefault(topic, []).append

    def _chunk(self, content, offset: int, index: ChunkIndex | None) -> None:
        start_time, end_time, uncompressed_size, crc = struct.unpack_from('<QQQI', content, 0)
        compression, at = _string(content, 28)
        data, _ = _bytes(content, at, '<Q')
        if index is not None and index.compressed_size != len(data):
            raise ValueError(
                f'compressed size {len(data)} where the chunk index says {index.compressed_size}'
            )
        if compression == 'zstd':
            import zstandard

            try:
                records = zstandard.ZstdDecompressor().decompress(
                    data, max_output_size=uncompressed_size
                )
            except zstandard.ZstdError as error:
                raise ValueError(f'zstd: {error}') from None
        elif compression == 'lz4':
            import lz4.frame

            try:
                records = lz4.frame.decompress(data)
            except RuntimeError as error:
                raise ValueError(f'lz4: {error}') from None
        elif compression == '':
            records = data
        else:
            raise ValueError(f'unknown chunk compression {compression!r}')
        if len(records) != uncompressed_size:
            raise ValueError(
                f'decompressed to {len(records)} bytes where the chunk says {uncompressed_size}'
            )
        if crc and zlib.crc32(records) != crc:
            raise ValueError('CRC mismatch')
        # a chunk failing half-way adds nothing: its messages are cut off again (the counts are
        # added only once it has been walked whole)
        kept = {t: len(v[0]) for t, v in self.scan.messages.items()}
        try:
            self._records(bytes(records), offset)
        except (ValueError, struct.error, UnicodeDecodeError):
            self._cut_back(kept)
            raise

    def _cut_back(self, kept: dict[str, int]) -> None:
        """Drop the messages after the first kept[topic] of each topic (all of a topic not in
        kept).
        """
        for topic in list(self.scan.messages):
            if topic not in kept:
                del self.scan.messages[topic], self.scan.sequences[topic]
                continue
            times, payloads = self.scan.messages[topic]
            n = kept[topic]
            del times[n:], payloads[n:], self.scan.sequences[topic][n:]

    # -- the file ---------------------------------------------------------------------------------

    def read(self) -> Scan:
        path = self.path
        check_regular_file(path)
        with open(path, 'rb') as stream:
            if os.fstat(stream.fileno()).st_size == 0:
                raise McapDamage(f'{path}: not an MCAP file (0 bytes)')
            # mapped, not read: one chunk at a time is in memory, whatever the file's size
            with mmap.mmap(stream.fileno(), 0, access=mmap.ACCESS_READ) as data:
                return self._read(data)

    def _read(self, data) -> Scan:
        path = self.path
        size = len(data)
        if size < len(MAGIC) or data[: len(MAGIC)] != MAGIC:
            raise McapDamage(f'{path}: not an MCAP file ({size} bytes, no MCAP magic at offset 0)')
        summary = self._summary(data)
        indexes = summary['chunks'] if summary else {}
        data_end = summary['summary_start'] if summary and summary['summary_start'] else size
        # a file still being written (its bag has no metadata.yaml yet) ends at the last record
        # flushed so far, maybe half-way through one: that end is where its writer is, not damage
        open_end = summary is None and self.unfinished
        if summary is None and not open_end:
            problem = (
                f'{path}: truncated or damaged: no valid footer and summary at the end '
                f'(file is {size} bytes); the messages it should hold cannot be counted'
            )
            if not self.salvage:
                raise McapDamage(problem + ' (--salvage reads what is intact)')
            self.scan.losses.append(problem)
        resume = sorted(indexes)
        at = len(MAGIC)
        seen_chunks = set()
        while at < data_end:
            try:
                if open_end and (
                    at + 9 > size or at + 9 + _RECORD_HEAD.unpack_from(data, at)[1] > size
                ):
                    break
                if at + 9 > size:
                    raise ValueError('record header cut by the end of the file')
                opcode, length = _RECORD_HEAD.unpack_from(data, at)
                if length > _MAX_RECORD or at + 9 + length > size:
                    raise ValueError(f'record length {length} runs past the end of the file')
                content = data[at + 9 : at + 9 + length]
                if opcode == _OP_DATA_END:
                    break
                if opcode == _OP_CHUNK:
                    index = indexes.get(at)
                    if summary is not None and index is None:
                        raise ValueError("a chunk the summary's chunk index does not list")
                    if index is not None and index.length != 9 + length:
                        raise ValueError(
                            f'chunk length {9 + length} where the chunk index says {index.length}'
                        )
                    self._chunk(content, at, index)
                    seen_chunks.add(at)
                elif opcode == _OP_MESSAGE:
                    self._message(content, at)
                elif opcode == _OP_SCHEMA:
                    self._schema(content)
                elif opcode == _OP_CHANNEL:
                    self._channel(content)
                elif opcode not in (_OP_HEADER, _OP_MESSAGE_INDEX, 0x09, 0x0C):
                    raise ValueError(
                        f'unexpected record opcode 0x{opcode:02x} in the data section'
                    )
                at += 9 + length
            except (ValueError, struct.error, UnicodeDecodeError) as error:
                problem = f'{path}: damaged data at byte offset {at}: {error}'
                if not self.salvage:
                    raise McapDamage(problem + ' (--salvage reads what is intact)') from None
                following = [offset for offset in resume if offset > at]
                if at in indexes:
                    seen_chunks.add(at)
                self.scan.losses.append(
                    problem
                    + (
                        f'; skipped to the next chunk at byte {following[0]}'
                        if following
                        else '; nothing after it could be read'
                    )
                )
                if not following:
                    break
                at = following[0]
        if summary is not None:
            self._compare(summary, seen_chunks)
        if open_end:
            read = sum(self.scan.counts.values())
            self.scan.losses.append(
                f'{path}: {STILL_RECORDING}, or its recorder was stopped without closing it '
                f'(no MCAP summary, no metadata.yaml yet): read the {read} messages on disk so '
                f'far ({at} of {size} bytes); what its writer still buffers is not in it yet'
            )
        return self.scan

    def _summary(self, data: bytes) -> dict | None:
        """Channels, chunk indexes and per-topic counts from the summary; None if it is
        unusable.
        """
        size = len(data)
        footer_at = size - len(MAGIC) - _FOOTER.size
        if footer_at < len(MAGIC) or data[-len(MAGIC) :] != MAGIC:
            return None
        opcode, length, summary_start, _, crc = _FOOTER.unpack_from(data, footer_at)
        if opcode != _OP_FOOTER or length != 20 or summary_start >= footer_at:
            return None
        if summary_start == 0:
            return {'summary_start': 0, 'chunks': {}, 'counts': None}
        if crc and zlib.crc32(data[summary_start : footer_at + _FOOTER.size - 4]) != crc:
            raise McapDamage(
                f'{self.path}: summary section (byte offset {summary_start}) fails its CRC'
            )
        chunks, counts, channel_topics = {}, None, {}
        at = summary_start
        try:
            while at < footer_at:
                opcode, length = _RECORD_HEAD.unpack_from(data, at)
                content = data[at + 9 : at + 9 + length]
                if at + 9 + length > footer_at:
                    raise ValueError('summary record runs into the footer')
                if opcode == _OP_SCHEMA:
                    self._schema(content)
                elif opcode == _OP_CHANNEL:
                    self._channel(content)
                    channel_id = struct.unpack_from('<H', content, 0)[0]
                    channel_topics[channel_id] = self.scan.channels[channel_id].topic
                elif opcode == _OP_CHUNK_INDEX:
                    (
                        _,
                        _,
                        start,
                        length_,
                    ) = struct.unpack_from('<QQQQ', content, 0)
                    (map_length,) = struct.unpack_from('<I', content, 32)
                    after = 36 + map_length + 8
                    (compression_length,) = struct.unpack_from('<I', content, after)
                    compressed, uncompressed = struct.unpack_from(
                        '<QQ', content, after + 4 + compression_length
                    )
                    chunks[start] = ChunkIndex(start, length_, compressed, uncompressed)
                elif opcode == _OP_STATISTICS:
                    (map_length,) = struct.unpack_from('<I', content, 42)
                    counts = {}
                    for k in range(map_length // 10):
                        channel_id, count = struct.unpack_from('<HQ', content, 46 + 10 * k)
                        counts[channel_id] = count
                at += 9 + length
        except (ValueError, struct.error, UnicodeDecodeError, KeyError) as error:
            raise McapDamage(
                f'{self.path}: summary section damaged at byte offset {at} ({error})'
            ) from None
        by_topic = None
        if counts is not None:
            by_topic = {}
            for channel_id, count in counts.items():
                topic = channel_topics.get(channel_id, f'channel {channel_id}')
                by_topic[topic] = by_topic.get(topic, 0) + count
        return {'summary_start': summary_start, 'chunks': chunks, 'counts': by_topic}

    def _compare(self, summary: dict, seen_chunks: set) -> None:
        missing_chunks = sorted(set(summary['chunks']) - seen_chunks)
        if missing_chunks and not self.salvage:
            raise McapDamage(
                f'{self.path}: chunk at byte offset {missing_chunks[0]} listed in the index was '
                f'not found in the data section ({len(missing_chunks)} chunk(s) missing)'
            )
        expected = summary['counts']
        self.scan.expected = expected
        if expected is None:
            return
        short = {
            t: n - self.scan.counts.get(t, 0)
            for t, n in expected.items()
            if self.scan.counts.get(t, 0) != n
        }
        if not short:
            return
        text = ', '.join(
            f'{t} {self.scan.counts.get(t, 0)} of {n}' for t, n in expected.items() if t in short
        )
        problem = f"{self.path}: messages read do not match the summary's counts ({text})"
        if not self.salvage:
            raise McapDamage(problem + ' (--salvage reads what is intact)')
        self.scan.losses.append(problem)


def scan_mcap(
    path: str | Path,
    wanted: Collection[str] | None = None,
    *,
    salvage: bool = False,
    unfinished: bool = False,
) -> Scan:
    """Read one MCAP file, checked; wanted topics keep their payloads (None: all).

    unfinished: the file may still be being written (a bag directory without metadata.yaml yet):
    without a footer and summary it is read up to its last complete record, and Scan.losses says
    so in one line; with a footer it is checked as any other file.
    """
    return _Reader(Path(path), wanted, salvage, unfinished).read()
