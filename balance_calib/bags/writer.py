"""Write a rosbag2 bag in MCAP storage, file for file as `ros2 bag record -s mcap` (Jazzy) does.

A bag is a directory NAME/ holding NAME_0.mcap and metadata.yaml (rosbag2 metadata version 9).
The MCAP file uses the `ros2` profile, `ros2msg` schemas (the message definition with its
dependencies, as rosbag2 concatenates them), `cdr` message encoding, and chunk compression only
(zstd or lz4; rosbag2's "message" and "file" compression modes are not used, so metadata.yaml says
compression_format: '' and compression_mode: '', as rosbag2 does for MCAP storage compression).
Each channel carries `offered_qos_profiles` (a YAML string) and `topic_type_hash` in its metadata;
metadata.yaml holds the same QoS profiles as a YAML list, the v9 layout that `ros2 bag play` reads.

The writer takes serialized CDR bytes, so it serves a live node (rclpy's raw subscriptions) and
offline tools alike; nothing here imports rclpy.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping, Sequence

from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from rosbags.typesys import get_typestore, Stores
import yaml

from balance_calib import __version__
from balance_calib.bags.errors import BagError

METADATA_VERSION = 9
ROS_DISTRO = 'jazzy'
_COMPRESSION = {'zstd': CompressionType.ZSTD, 'lz4': CompressionType.LZ4}
# rmw's RMW_DURATION_INFINITE, as rosbag2 writes an unset deadline, lifespan or lease duration.
INFINITE_DURATION = {'sec': 9223372036, 'nsec': 854775807}
_QOS_KEYS = (
    'history',
    'depth',
    'reliability',
    'durability',
    'deadline',
    'lifespan',
    'liveliness',
    'liveliness_lease_duration',
    'avoid_ros_namespace_conventions',
)

_typestore = None


class _Dumper(yaml.SafeDumper):
    """Plain YAML as yaml-cpp writes it: repeated values spelled out, no &anchors."""

    def ignore_aliases(self, data):
        return True


def _dump_yaml(data) -> str:
    return yaml.dump(data, Dumper=_Dumper, sort_keys=False, default_flow_style=False)


def _jazzy_typestore():
    global _typestore
    if _typestore is None:
        _typestore = get_typestore(Stores.ROS2_JAZZY)
    return _typestore


def qos_profiles_yaml(profiles: Sequence[Mapping[str, Any]]) -> str:
    """Serialize offered QoS profiles the way rosbag2 (metadata v9) does.

    Each profile maps the keys history, depth, reliability, durability, deadline, lifespan,
    liveliness, liveliness_lease_duration, avoid_ros_namespace_conventions to rmw's lower-case
    policy names ('keep_last', 'reliable', 'transient_local', 'automatic', ...), an int depth,
    {'sec', 'nsec'} durations and a bool. Missing keys take rmw's defaults for a recorded
    publisher (durations infinite). Returns '' for no profiles.
    """
    if not profiles:
        return ''
    defaults = {
        'history': 'unknown',
        'depth': 0,
        'reliability': 'reliable',
        'durability': 'volatile',
        'deadline': INFINITE_DURATION,
        'lifespan': INFINITE_DURATION,
        'liveliness': 'automatic',
        'liveliness_lease_duration': INFINITE_DURATION,
        'avoid_ros_namespace_conventions': False,
    }
    ordered = [{key: profile.get(key, defaults[key]) for key in _QOS_KEYS} for profile in profiles]
    return _dump_yaml(ordered)


class BagWriter:
    """A rosbag2 MCAP bag being written: open(), add_topic(), write() ..., close().

    Also a context manager (closes on exit, even after an exception, so that what was written
    stays readable). Timestamps are int nanoseconds since the epoch (the receive time, as
    rosbag2's log_time); payloads are CDR bytes with their 4-byte encapsulation header.
    Not thread-safe: write from one thread (a node's single-threaded executor does).
    """

    def __init__(
        self,
        path: str | os.PathLike,
        *,
        compression: str = 'zstd',
        chunk_size_bytes: int = 1024 * 1024,
    ):
        if compression not in _COMPRESSION:
            raise BagError(
                f'bag {path}: chunk compression must be one of {sorted(_COMPRESSION)},'
                f' not {compression!r}'
            )
        self.path = Path(path)
        self.mcap_path = self.path / f'{self.path.name}_0.mcap'
        self.compression = compression
        self.chunk_size_bytes = chunk_size_bytes
        self._stream = None
        self._mcap: McapWriter | None = None
        self._schema_ids: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._topics: dict[str, dict[str, Any]] = {}
        self._counts: dict[str, int] = {}
        self._first_ns: int | None = None
        self._last_ns = 0

    # -- lifecycle ------------------------------------------------------------------------------

    def open(self) -> None:
        """Create the bag directory (it must not exist yet) and start the MCAP file."""
        try:
            self.path.mkdir(parents=True)
        except FileExistsError:
            raise BagError(f'bag {self.path} exists already; choose a new output path') from None
        self._stream = open(self.mcap_path, 'xb')
        self._mcap = McapWriter(
            self._stream,
            chunk_size=self.chunk_size_bytes,
            compression=_COMPRESSION[self.compression],
        )
        self._mcap.start(profile='ros2', library=f'balance_calib {__version__} (mcap-python)')

    @property
    def is_open(self) -> bool:
        return self._mcap is not None

    def add_topic(
        self,
        name: str,
        msgtype: str,
        offered_qos_profiles_yaml: str = '',
        *,
        type_description_hash: str | None = None,
        message_definition: str | None = None,
    ) -> None:
        """Declare a topic before writing to it.

        msgtype is 'pkg/msg/Type'. The message definition (ros2msg text with dependencies) and
        RIHS01 type hash default to ROS 2 Jazzy's; pass them for types Jazzy does not ship.
        offered_qos_profiles_yaml is a YAML list of profiles, see qos_profiles_yaml().
        """
        self._require_open()
        if name in self._topics:
            if self._topics[name]['type'] != msgtype:
                raise BagError(
                    f'bag {self.path}: topic {name} already recorded as '
                    f'{self._topics[name]["type"]}, cannot add it as {msgtype}'
                )
            return
        try:
            qos_profiles = yaml.safe_load(offered_qos_profiles_yaml) or []
        except yaml.YAMLError as error:
            raise BagError(
                f'bag {self.path}: offered QoS of topic {name} is not YAML: {error}'
            ) from None
        if not isinstance(qos_profiles, list):
            raise BagError(f'bag {self.path}: offered QoS of topic {name} must be a YAML list')
        if message_definition is None or type_description_hash is None:
            typestore = _jazzy_typestore()
            if msgtype not in typestore.fielddefs:
                raise BagError(
                    f'bag {self.path}: topic {name} has type {msgtype}, which ROS 2 '
                    'Jazzy does not ship; pass its message_definition and '
                    'type_description_hash'
                )
            if message_definition is None:
                message_definition = typestore.generate_msgdef(msgtype, ros_version=2)[0]
            if type_description_hash is None:
                type_description_hash = typestore.hash_rihs01(msgtype)
        if msgtype not in self._schema_ids:
            self._schema_ids[msgtype] = self._mcap.register_schema(
                name=msgtype, encoding='ros2msg', data=message_definition.encode()
            )
        self._channels[name] = self._mcap.register_channel(
            topic=name,
            message_encoding='cdr',
            schema_id=self._schema_ids[msgtype],
            metadata={
                'offered_qos_profiles': offered_qos_profiles_yaml,
                'topic_type_hash': type_description_hash,
            },
        )
        self._topics[name] = {
            'name': name,
            'type': msgtype,
            'serialization_format': 'cdr',
            'offered_qos_profiles': qos_profiles,
            'type_description_hash': type_description_hash,
        }
        self._counts[name] = 0

    def write(
        self, topic: str, timestamp_ns: int, cdr_bytes: bytes, publish_time_ns: int | None = None
    ) -> None:
        """Append one serialized message; timestamp_ns is its receive (log) time, ns."""
        self._require_open()
        channel_id = self._channels.get(topic)
        if channel_id is None:
            raise BagError(f'bag {self.path}: topic {topic} was not added before writing')
        timestamp_ns = int(timestamp_ns)
        self._mcap.add_message(
            channel_id=channel_id,
            log_time=timestamp_ns,
            data=bytes(cdr_bytes),
            publish_time=timestamp_ns if publish_time_ns is None else int(publish_time_ns),
            sequence=self._counts[topic] % 2**32,
        )
        self._counts[topic] += 1
        self._first_ns = (
            timestamp_ns if self._first_ns is None else min(self._first_ns, timestamp_ns)
        )
        self._last_ns = max(self._last_ns, timestamp_ns)

    def flush(self) -> None:
        """Put everything written so far into the file, the chunk in progress included.

        A reader of the bag while it is being recorded (no footer, no metadata.yaml yet) then sees
        every message up to now; each flush ends a chunk, so flushing often costs compression.
        """
        self._require_open()
        self._mcap.flush()
        self._stream.flush()

    @property
    def message_counts(self) -> dict[str, int]:
        """Messages written so far, per topic."""
        return dict(self._counts)

    def close(self) -> dict[str, int]:
        """Finish the MCAP file (summary, indexes) and write metadata.yaml atomically.

        Returns the message count per topic. Closing a closed writer does nothing.
        """
        if self._mcap is None:
            return self.message_counts
        information = self._bag_information()
        mcap, self._mcap = self._mcap, None
        try:
            # rosbag2 repeats its metadata inside the MCAP file: a bare .mcap is self-describing.
            mcap.add_metadata('rosbag2', {'serialized_metadata': _dump_yaml(information)})
            mcap.finish()
            self._stream.flush()
            os.fsync(self._stream.fileno())
        finally:
            self._stream.close()
            self._stream = None
        metadata_path = self.path / 'metadata.yaml'
        partial_path = self.path / 'metadata.yaml.partial'
        with open(partial_path, 'w', encoding='utf-8') as partial:
            partial.write(_dump_yaml({'rosbag2_bagfile_information': information}))
            partial.flush()
            os.fsync(partial.fileno())
        os.replace(partial_path, metadata_path)
        return self.message_counts

    def __enter__(self) -> 'BagWriter':
        if self._mcap is None:
            self.open()
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    # -- internals ------------------------------------------------------------------------------

    def _require_open(self) -> None:
        if self._mcap is None:
            raise BagError(f'bag {self.path} is not open for writing')

    def _bag_information(self) -> dict[str, Any]:
        start_ns = self._first_ns or 0
        duration_ns = self._last_ns - start_ns if self._first_ns is not None else 0
        total = sum(self._counts.values())
        relative_path = self.mcap_path.name
        return {
            'version': METADATA_VERSION,
            'storage_identifier': 'mcap',
            'duration': {'nanoseconds': duration_ns},
            'starting_time': {'nanoseconds_since_epoch': start_ns},
            'message_count': total,
            'topics_with_message_count': [
                {'topic_metadata': topic, 'message_count': self._counts[name]}
                for name, topic in self._topics.items()
            ],
            'compression_format': '',
            'compression_mode': '',
            'relative_file_paths': [relative_path],
            'files': [
                {
                    'path': relative_path,
                    'starting_time': {'nanoseconds_since_epoch': start_ns},
                    'duration': {'nanoseconds': duration_ns},
                    'message_count': total,
                }
            ],
            'custom_data': None,
            'ros_distro': ROS_DISTRO,
        }
