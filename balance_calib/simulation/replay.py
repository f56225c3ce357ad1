"""Messages of bags for `bridge_publisher`'s replay mode, as `ros2 bag play` would send them.

Every topic of the bags, serialized CDR untouched (so header stamps stay as recorded), in
receive-time order. Bags are rosbag2 MCAP directories or bare .mcap files, any number of them,
opened by bags/opening.py and read by the package's checked MCAP scanner (bags/mcap_scan.py), as
`read_bags` reads them.
"""

from __future__ import annotations

from dataclasses import dataclass
import os
from pathlib import Path
from typing import Sequence

import numpy as np

from ..bags.errors import BagError
from ..bags.mcap_scan import McapDamage, scan_mcap
from ..bags.opening import open_bag


@dataclass(frozen=True)
class RecordedMessages:
    times_s: np.ndarray  # (M,) receive time from the first message, s
    topics: tuple[str, ...]  # (M,)
    payloads: tuple[bytes, ...]  # (M,) CDR
    msgtypes: dict  # topic -> 'pkg/msg/Type'

    def __len__(self) -> int:
        return len(self.times_s)


def read_recorded_messages(
    paths: Sequence[str | os.PathLike], topics: Sequence[str] = ()
) -> RecordedMessages:
    """All messages (or those of `topics`) of the bags, merged by receive time (a stable sort:
    messages of one time stay in topic order). BagError names the file.
    """
    sources = [Path(p) for p in paths]
    if not sources:
        raise BagError('no bag given')
    times, names, payloads, msgtypes = [], [], [], {}
    for source in sources:
        bag = open_bag(source)
        for path in bag.files:
            try:
                scan = scan_mcap(path, set(topics) or None, unfinished=bag.unfinished)
            except McapDamage as error:
                raise BagError(str(error)) from None
            for channel in scan.channels.values():
                if topics and channel.topic not in topics:
                    continue
                known = msgtypes.setdefault(channel.topic, channel.schema_name)
                if known != channel.schema_name:
                    raise BagError(
                        f'{source}: topic {channel.topic} is {channel.schema_name} here '
                        f'but {known} in another bag'
                    )
            for topic, (stamps, data) in scan.messages.items():
                times += stamps
                names += [topic] * len(stamps)
                payloads += data
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
