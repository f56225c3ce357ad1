"""Messages of bags for `bridge_publisher`'s replay mode, as `ros2 bag play` would send them.

Every topic of the bags, serialized CDR untouched (so header stamps stay as recorded), in
receive-time order. Bags are rosbag2 MCAP directories or bare .mcap files, any number of them.
"""

from __future__ import annotations

from dataclasses import dataclass
import os
from pathlib import Path
from typing import Sequence

import numpy as np
from rosbags.rosbag2 import Reader, ReaderError

from ..bags.errors import BagError


@dataclass(frozen=True)
class RecordedMessages:
    times_s: np.ndarray  # (M,) receive time from the first message, s
    topics: tuple[str, ...]  # (M,)
    payloads: tuple[bytes, ...]  # (M,) CDR
    msgtypes: dict  # topic -> 'pkg/msg/Type'

    def __len__(self) -> int:
        return len(self.times_s)


def _open(source: Path) -> Reader:
    if not source.exists():
        raise BagError(f'{source}: no such file or directory')
    if source.is_dir() and not (source / 'metadata.yaml').is_file():
        raise BagError(f'{source}: not a rosbag2 bag (no metadata.yaml)')
    if not source.is_dir() and source.suffix != '.mcap':
        raise BagError(f'{source}: not a bag (expected a rosbag2 directory or an .mcap file)')
    try:
        reader = Reader(source)
        reader.open()
    except (ReaderError, OSError, ValueError, KeyError, EOFError) as error:
        raise BagError(
            f'{source}: cannot open bag, the file is truncated or corrupt ({error})'
        ) from None
    return reader


def read_recorded_messages(
    paths: Sequence[str | os.PathLike], topics: Sequence[str] = ()
) -> RecordedMessages:
    """All messages (or those of `topics`) of the bags, merged by receive time. BagError names
    the file.
    """
    sources = [Path(p) for p in paths]
    if not sources:
        raise BagError('no bag given')
    times, names, payloads, msgtypes = [], [], [], {}
    for source in sources:
        reader = _open(source)
        try:
            connections = [c for c in reader.connections if not topics or c.topic in topics]
            for connection in connections:
                known = msgtypes.setdefault(connection.topic, connection.msgtype)
                if known != connection.msgtype:
                    raise BagError(
                        f'{source}: topic {connection.topic} is {connection.msgtype} here '
                        f'but {known} in another bag'
                    )
            try:
                for connection, timestamp, data in reader.messages(connections):
                    times.append(timestamp)
                    names.append(connection.topic)
                    payloads.append(bytes(data))
            except Exception as error:  # a damaged chunk fails in the decompressor or parser
                raise BagError(
                    f'{source}: cannot read messages, the file is corrupt '
                    f'({type(error).__name__}: {error})'
                ) from None
        finally:
            reader.close()
    if not times:
        raise BagError(
            f'{", ".join(map(str, sources))}: no messages'
            + (f' on {", ".join(topics)}' if topics else '')
        )
    stamp = np.array(times, dtype=np.int64)
    order = np.argsort(stamp, kind='stable')
    return RecordedMessages(
        (stamp[order] - stamp[order[0]]) * 1e-9,
        tuple(names[i] for i in order),
        tuple(payloads[i] for i in order),
        msgtypes,
    )
