"""geometry_msgs/msg/WrenchStamped as CDR bytes, a whole batch at a time, with numpy (no rclpy).

The calibrator's fast path takes serialized samples from rclpy (`raw=True`) and publishes bytes:
this skips rclpy's per-message Python conversion (about 20 µs to deserialize and 10 µs to serialize
a message here). Layout (XCDR1 little endian, as rmw_fastrtps writes it; alignment counted from
after the 4-byte encapsulation header): int32 sec, uint32 nanosec, uint32 frame_id length (with its
NUL), the characters, padding to 8, six float64 (force x y z, torque x y z).
"""

from __future__ import annotations

import struct
from typing import Any, Sequence  # Any: rclpy's WrenchStamped objects, duck-typed

import numpy as np

CDR_LE = b'\x00\x01\x00\x00'
_STAMP = struct.Struct('<iI')
_SIX = struct.Struct('<6d')


def _layout(frame_length: int) -> tuple[int, int]:
    """(offset of the six doubles, total size) for a frame_id of frame_length bytes (without
    NUL).
    """
    body = 12 + frame_length + 1
    doubles = 4 + (body + 7) // 8 * 8
    return doubles, doubles + 48


def decode_wrenches(messages: list[bytes]) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """-> stamps (N,) int64 ns, values (N, 6) float64, frame_ids (N,). ValueError on bytes that are
    not a little-endian WrenchStamped (the caller falls back to rclpy's deserializer).
    """
    if not messages:
        return np.zeros(0, np.int64), np.zeros((0, 6)), []
    size = len(messages[0])
    first = messages[0]
    if len(messages) == 1 and first[:4] == CDR_LE and size >= 64:  # the common case at low rates
        frame_length = int.from_bytes(first[12:16], 'little') - 1
        offset, expected = _layout(frame_length)
        if expected == size:
            sec, nanosec = _STAMP.unpack_from(first, 4)
            return (
                np.array([sec * 1_000_000_000 + nanosec]),
                np.array([_SIX.unpack_from(first, offset)]),
                [first[16 : 16 + frame_length].decode('utf-8', 'replace')],
            )
    if first[:4] != CDR_LE or size < 64:
        raise ValueError('not little-endian CDR')
    frame_length = int.from_bytes(first[12:16], 'little') - 1
    offset, expected = _layout(frame_length)
    if expected != size:
        raise ValueError('unexpected WrenchStamped size')
    frame = first[16 : 16 + frame_length]
    if all(len(m) == size for m in messages):
        rows = np.frombuffer(b''.join(messages), dtype=np.uint8).reshape(len(messages), size)
        same_frame = bool(
            np.all(rows[:, 12 : 16 + frame_length] == rows[0, 12 : 16 + frame_length])
        )
        if same_frame and np.all(rows[:, :4] == rows[0, :4]):
            stamps = np.ascontiguousarray(rows[:, 4:12]).view('<i4').astype(np.int64)
            ns = stamps[:, 0] * 1_000_000_000 + (stamps[:, 1] & 0xFFFFFFFF)
            values = np.ascontiguousarray(rows[:, offset : offset + 48]).view('<f8')
            return ns, values, [frame.decode('utf-8', 'replace')] * len(messages)
    parts = [decode_wrenches([m]) for m in messages] if len(messages) > 1 else None
    if parts is None:
        raise ValueError('unexpected WrenchStamped layout')
    return (
        np.concatenate([p[0] for p in parts]),
        np.vstack([p[1] for p in parts]),
        [f for p in parts for f in p[2]],
    )


def wrench_arrays(messages: Sequence[Any]) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """decode_wrenches' result from deserialized WrenchStamped messages (rclpy's, for other
    layouts).
    """
    stamps = np.array(
        [m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in messages], np.int64
    )
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
            for m in messages
        ],
        float,
    ).reshape(-1, 6)
    return stamps, values, [m.header.frame_id for m in messages]


class WrenchEncoder:
    """Serializes WrenchStamped batches with one frame_id (the node's `frame_id` parameter)."""

    def __init__(self, frame_id: str) -> None:
        self.frame_id = frame_id
        encoded = frame_id.encode('utf-8')
        self.offset, self.size = _layout(len(encoded))
        template = np.zeros(self.size, dtype=np.uint8)
        template[:4] = np.frombuffer(CDR_LE, np.uint8)
        template[12:16] = np.frombuffer((len(encoded) + 1).to_bytes(4, 'little'), np.uint8)
        template[16 : 16 + len(encoded)] = np.frombuffer(encoded, np.uint8)
        self.template = template
        self.middle = template[12 : self.offset].tobytes()  # frame_id and padding

    def encode(self, stamps_ns: np.ndarray, values: np.ndarray) -> list[bytes]:
        """Stamps (M,) int64 ns and values (M, 6) -> M serialized messages."""
        m = len(values)
        if m == 1:
            sec, nanosec = divmod(int(stamps_ns[0]), 1_000_000_000)
            return [
                CDR_LE + _STAMP.pack(sec, nanosec) + self.middle + _SIX.pack(*values[0].tolist())
            ]
        rows = np.empty((m, self.size), dtype=np.uint8)
        rows[:] = self.template
        stamps = np.asarray(stamps_ns, dtype=np.int64)
        seconds = np.empty((m, 2), dtype='<i4')
        seconds[:, 0] = stamps // 1_000_000_000
        seconds[:, 1] = (stamps % 1_000_000_000).astype(np.uint32).view(np.int32)
        rows[:, 4:12] = seconds.view(np.uint8).reshape(m, 8)
        rows[:, self.offset :] = (
            np.ascontiguousarray(values, dtype='<f8').view(np.uint8).reshape(m, 48)
        )
        data = rows.tobytes()
        size = self.size
        return [data[k * size : (k + 1) * size] for k in range(m)]
