"""The simulated balance as a data acquisition device: what `balance_daq` reads, encoded.

`balance-calib virtual-daq` plays bridge_publisher's timeline (the same truth, noise and effects)
and hands each raw sample (mV) here, where it becomes what a device of one of config/daq's
presets sends: a text line or a binary record (interfaces.md, "Acquisition"), the inverse of what
balance_daq decodes. The transports are a pty (serial), a listening TCP port that serves lines to
every client, and UDP: answering the ATI Net F/T RDT request (8 bytes big-endian: uint16 0x1234,
uint16 command, uint32 sample count; command 2 starts streaming `count` records, 0 = for ever,
command 0 stops) or, for a preset without a start request, sending datagrams to the address
balance_daq binds. No rclpy here: the device is tested without DDS.
"""

from __future__ import annotations

import bisect
import errno
import fcntl
import os
from pathlib import Path
import re
import select
import socket
import struct
import termios
import tty
from typing import Mapping

import numpy as np
import yaml

from ..daq.parameters import BRIDGES, daq_settings, DaqSettings

RDT_HEADER = 0x1234
RDT_START, RDT_STOP = 2, 0
RDT_REQUEST = struct.Struct('>HHI')
SEQ_MODULUS = 2**32
TRANSPORTS = ('serial', 'tcp', 'udp')
# struct codes that carry an integer, and their ranges (standard sizes, as a '>'/'<' format has)
_INTEGER_RANGES = {
    'b': (-(2**7), 2**7 - 1),
    'B': (0, 2**8 - 1),
    'h': (-(2**15), 2**15 - 1),
    'H': (0, 2**16 - 1),
    'i': (-(2**31), 2**31 - 1),
    'I': (0, 2**32 - 1),
    'l': (-(2**31), 2**31 - 1),
    'L': (0, 2**32 - 1),
    'q': (-(2**63), 2**63 - 1),
    'Q': (0, 2**64 - 1),
}


class DeviceError(ValueError):
    """A format file or device address the virtual device cannot serve; one line saying which."""


def _struct_fields(record_format: str) -> list[str]:
    """The struct code of each field of a record format ('>3I6i' -> ['I']*3 + ['i']*6)."""
    fields = []
    for count, code in re.findall(r'(\d*)([xcbB?hHiIlLqQnNefdspP])', record_format):
        if code == 'x':
            continue
        fields += [code] * (int(count) if count and code not in 'sp' else 1)
    return fields


def device_format(parameters: Mapping[str, object], source: str = 'format') -> DaqSettings:
    """balance_daq's own settings of these parameters (its table and checks: what the node
    accepts, the device can send); DeviceError naming `source` and the parameter otherwise.
    """
    try:
        return daq_settings(parameters)
    except ValueError as err:
        raise DeviceError(f'{source}: {err}') from None


def preset_parameters(path: Path) -> dict:
    """balance_daq's ros__parameters in a params file (section balance_daq, /**, or the only
    one).
    """
    try:
        data = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as err:
        raise DeviceError(f'{path}: cannot read the format file: {err}') from None
    if not isinstance(data, dict):
        raise DeviceError(f'{path}: not a ros__parameters file (no mapping at the top)')
    sections = {
        name: section['ros__parameters']
        for name, section in data.items()
        if isinstance(section, dict) and isinstance(section.get('ros__parameters'), dict)
    }
    for name in ('balance_daq', '/balance_daq', '/**'):
        if name in sections:
            return dict(sections[name])
    if len(sections) == 1:
        return dict(next(iter(sections.values())))
    raise DeviceError(
        f'{path}: no balance_daq ros__parameters section (found {", ".join(sections) or "none"})'
    )


def read_format(path: Path) -> DaqSettings:
    return device_format(preset_parameters(path), str(path))


def bridge_fields(raw_mv: np.ndarray, device: DaqSettings) -> np.ndarray:
    """Bridge outputs (mV, (..., 6)) in the device's units: the inverse of balance_daq's
    conversion (mV = V·1000 = mV/V·excitation = µV/V·excitation/1000 = counts·counts_to_mv).
    Counts are rounded to whole counts (the device's resolution).
    """
    raw_mv = np.asarray(raw_mv, dtype=float)
    if device.units == 'mV':
        return raw_mv
    if device.units == 'V':
        return raw_mv / 1000.0
    if device.units == 'mV/V':
        return raw_mv / device.excitation_v
    if device.units == 'uV/V':
        return raw_mv / device.excitation_v * 1000.0
    return np.rint(raw_mv / np.asarray(device.counts_to_mv))


class Encoder:
    """One sample -> the bytes of one record: a text line (ending CR LF on serial, as a
    microcontroller's println sends) or a struct record. Integer fields are rounded and clipped
    to their type's range (an A/D converter at full scale); the seq column counts samples.
    """

    def __init__(self, device: DaqSettings, line_end: str = '\n'):
        self.device = device
        self.line_end = line_end
        self.seq = 0
        self._fields = _struct_fields(device.record_format) if device.framing == 'binary' else []
        self._struct = struct.Struct(device.record_format) if device.framing == 'binary' else None
        self._bridge_index = {name: i for i, name in enumerate(BRIDGES)}
        self._prefix = f'{device.line_prefix},' if device.line_prefix else ''

    def values(self, raw_mv, time_s: float, temperature_c: float) -> list[float]:
        bridges = bridge_fields(raw_mv, self.device)
        out = []
        for column in self.device.columns:
            if column in self._bridge_index:
                out.append(float(bridges[self._bridge_index[column]]))
            elif column == 'seq':
                out.append(float(self.seq % SEQ_MODULUS))
            elif column == 'temperature':
                out.append(float(temperature_c))
            elif column == 'excitation':
                out.append(self.device.excitation_v)
            elif column == 'time':
                out.append(float(time_s))
            else:  # status (0: valid) and ignored fields
                out.append(0.0)
        return out

    def encode(self, raw_mv, time_s: float = 0.0, temperature_c: float = 20.0) -> bytes:
        values = self.values(raw_mv, time_s, temperature_c)
        self.seq += 1
        if self._struct is not None:
            packed = []
            for code, value in zip(self._fields, values):
                if code in _INTEGER_RANGES:
                    low, high = _INTEGER_RANGES[code]
                    packed.append(int(min(max(round(value), low), high)))
                else:
                    packed.append(value)
            return self._struct.pack(*packed)
        text = ','.join(
            self._text(column, value) for column, value in zip(self.device.columns, values)
        )
        return (self._prefix + text + self.line_end).encode('ascii')

    def _text(self, column: str, value: float) -> str:
        if column in ('seq', 'status', '_') or (
            column in self._bridge_index and self.device.units == 'counts'
        ):
            return str(int(value))
        return f'{value:.9g}'


def split_address(address: str) -> tuple[str, int]:
    host, _, port = str(address).rpartition(':')
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not host or not 0 <= number <= 65535:
        raise DeviceError(f'device {address!r}: expected host:port, e.g. 127.0.0.1:49152')
    return host, number


class PtyDevice:
    """A serial device on a pseudo-terminal: balance_daq opens the slave's path (printed, and
    linked from `link` when given). Like a UART with nobody listening, what nobody reads is lost:
    more than `backlog_bytes` waiting in the pty is flushed before the next write.
    """

    line_end = '\r\n'

    def __init__(self, link: str | None = None, backlog_bytes: int = 1024):
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no line editing: bytes pass as the device sent them
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self._slave)
        self.backlog_bytes = backlog_bytes
        # an empty line before the first record: the line balance_daq drops after opening a port
        # (it may be a tail) is this one, not the first sample (not written now: pyserial
        # empties the input when it opens the port)
        self._lead = self.line_end.encode()
        self.dropped_bytes = 0
        self.link = Path(link) if link else None
        if self.link is not None:
            if self.link.is_symlink():
                self.link.unlink()
            elif self.link.exists():
                os.close(self.master)
                os.close(self._slave)
                raise DeviceError(f'device {link}: exists and is not a link; give a new path')
            self.link.symlink_to(self.path)

    @property
    def address(self) -> str:
        return self.path + (f' (linked from {self.link})' if self.link else '')

    def clients(self) -> int:
        return 1  # a serial line cannot tell whether someone listens

    def send(self, records: list[bytes]) -> None:
        if not records:
            return
        waiting = int.from_bytes(fcntl.ioctl(self._slave, termios.FIONREAD, b'\0\0\0\0'), 'little')
        if waiting > self.backlog_bytes:
            termios.tcflush(self._slave, termios.TCIFLUSH)
            self.dropped_bytes += waiting
        data, self._lead = self._lead + b''.join(records), b''
        try:
            os.write(self.master, data)
        except OSError as err:
            if err.errno not in (errno.EAGAIN, errno.EIO):
                raise
            self.dropped_bytes += len(data)

    def close(self) -> None:
        if self.link is not None and self.link.is_symlink():
            self.link.unlink()
        for fd in (self.master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass


class TcpDevice:
    """A TCP server: every client that connects gets the stream from the next record on (a TCP
    stream starts at a line boundary); a client that stops reading for `send_timeout_s` is
    dropped.
    """

    line_end = '\n'

    def __init__(self, address: str, send_timeout_s: float = 0.5):
        host, port = split_address(address)
        self._server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self._server.bind((host, port))
        except OSError as err:
            self._server.close()
            raise DeviceError(f'device {address}: cannot listen there: {err.strerror}') from None
        self._server.listen(4)
        self._server.setblocking(False)
        self.send_timeout_s = send_timeout_s
        self._clients: list[socket.socket] = []
        self.host, self.port = self._server.getsockname()[:2]

    @property
    def address(self) -> str:
        return f'{self.host}:{self.port}'

    def _accept(self) -> None:
        while select.select([self._server], [], [], 0)[0]:
            try:
                client, _ = self._server.accept()
            except OSError:
                return
            client.setblocking(True)
            client.settimeout(self.send_timeout_s)
            client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._clients.append(client)

    def clients(self) -> int:
        self._accept()
        return len(self._clients)

    def send(self, records: list[bytes]) -> None:
        self._accept()
        if not records:
            return
        data = b''.join(records)
        for client in list(self._clients):
            try:
                client.sendall(data)
            except OSError:  # gone, or not reading
                self._clients.remove(client)
                client.close()

    def close(self) -> None:
        for client in self._clients:
            client.close()
        self._server.close()


class UdpDevice:
    """UDP. With a start request in the format (ATI RDT): binds `address` and streams one record
    per datagram to each peer that asked (command 2, `count` records, 0 = for ever) until it
    sends the stop request (command 0). Without: sends each record to `address`, where
    balance_daq listens.
    """

    line_end = '\n'

    def __init__(self, address: str, device: DaqSettings):
        host, port = split_address(address)
        self.device = device
        self._socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._socket.setblocking(False)
        self.answering = bool(device.start_request)
        self._peers: dict[tuple, int] = {}  # peer -> records still to send (-1: for ever)
        if self.answering:
            try:
                self._socket.bind((host, port))
            except OSError as err:
                self._socket.close()
                raise DeviceError(f'device {address}: cannot bind there: {err.strerror}') from None
            self.host, self.port = self._socket.getsockname()[:2]
        else:
            self.host, self.port = host, port
        self.requests = 0

    @property
    def address(self) -> str:
        return f'{self.host}:{self.port}'

    def _read_requests(self) -> None:
        while True:
            try:
                data, peer = self._socket.recvfrom(64)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # ICMP port unreachable from a peer that went away
                continue
            self.requests += 1
            start, stop = self._request(data)
            if start is not None:
                self._peers[peer] = start
            elif stop:
                self._peers.pop(peer, None)

    def _request(self, data: bytes) -> tuple[int | None, bool]:
        """(records to stream or None, stop?) of one request datagram."""
        if len(data) == RDT_REQUEST.size:
            header, command, count = RDT_REQUEST.unpack(data)
            if header == RDT_HEADER and command == RDT_START:
                return (count if count else -1), False
            if header == RDT_HEADER and command == RDT_STOP:
                return None, True
        if data == self.device.start_request:
            return -1, False
        return None, data == self.device.stop_request

    def clients(self) -> int:
        if not self.answering:
            return 1
        self._read_requests()
        return len(self._peers)

    def send(self, records: list[bytes]) -> None:
        if not self.answering:
            for record in records:
                self._sendto(record, (self.host, self.port))
            return
        self._read_requests()
        for peer, left in list(self._peers.items()):
            chosen = records if left < 0 else records[:left]
            for record in chosen:
                self._sendto(record, peer)
            if left >= 0:
                left -= len(chosen)
                if left == 0:
                    del self._peers[peer]
                else:
                    self._peers[peer] = left

    def _sendto(self, record: bytes, peer) -> None:
        try:
            self._socket.sendto(record, peer)
        except OSError:  # a full buffer or an unreachable peer: that datagram is lost, as on a LAN
            pass

    def close(self) -> None:
        self._socket.close()


def open_device(transport: str, address: str | None, device: DaqSettings, source: str = ''):
    """The transport for `device`: PtyDevice, TcpDevice or UdpDevice; DeviceError if it cannot."""
    if transport not in TRANSPORTS:
        raise DeviceError(f'transport {transport!r} is not one of {", ".join(TRANSPORTS)}')
    if device.framing == 'binary' and transport != 'udp':
        raise DeviceError(
            f'{source or "format"}: binary records go over udp only (interfaces.md), not '
            f'{transport}'
        )
    if transport == 'serial':
        return PtyDevice(address)
    if not address:
        raise DeviceError(f'{transport} needs --device host:port')
    if transport == 'tcp':
        return TcpDevice(address)
    return UdpDevice(address, device)


class VirtualDevice:
    """A transport with its encoder: samples go in as mV, are sent as records at flush()."""

    def __init__(self, transport: str, address: str | None, device: DaqSettings, source: str = ''):
        self.format = device
        self.has_temperature = 'temperature' in device.columns
        self.transport = transport
        self.link = open_device(transport, address, device, source)
        self.encoder = Encoder(device, self.link.line_end)
        self.temperature_c = 20.0
        self._pending: list[bytes] = []
        self.samples_sent = 0

    @property
    def address(self) -> str:
        return self.link.address

    def clients(self) -> int:
        return self.link.clients()

    def add_sample(self, raw_mv, time_s: float) -> None:
        self._pending.append(self.encoder.encode(raw_mv, time_s, self.temperature_c))

    def flush(self) -> None:
        pending, self._pending = self._pending, []
        self.link.send(pending)
        self.samples_sent += len(pending)

    def close(self) -> None:
        self.link.close()


class ReturnedSamples:
    """Which written sample each /balance/raw sample that comes back from balance_daq is, and so
    the stamp balance_daq gave the last sample before any point of the run.

    Written samples are numbered in order; a returned one is matched by its values (the bridge
    outputs in mV, within the device's resolution: half a count, or 1e-6 relative for text and
    floats -- far below the noise between two samples) against the next `lookahead` written
    ones, so a sample lost on the way (a UDP datagram, the line balance_daq drops after opening
    a port) is skipped instead of shifting every later match. A written sample is resolved once
    it or a later one came back (then a lost one is known lost).
    """

    def __init__(self, device: DaqSettings, lookahead: int = 200):
        counts = device.units == 'counts'
        self._absolute = 0.5 * np.abs(np.asarray(device.counts_to_mv)) if counts else np.zeros(6)
        self._lookahead = lookahead
        self._pending: list[np.ndarray] = []  # written, not yet resolved (from _first)
        self._first = 0  # index of _pending[0]
        self._matched: list[tuple[int, int]] = []  # (index, stamp ns), increasing
        self.lost = 0

    def written(self, raw_mv) -> None:
        self._pending.append(np.asarray(raw_mv, dtype=float))

    def returned(self, raw_mv, stamp_ns: int) -> bool:
        """Match one returned sample; False if it matches none of the next written ones."""
        values = np.asarray(raw_mv, dtype=float)
        for offset, expected in enumerate(self._pending[: self._lookahead]):
            tolerance = self._absolute + 1e-6 * np.abs(expected) + 1e-12
            if np.all(np.abs(values - expected) <= tolerance):
                self.lost += offset
                self._matched.append((self._first + offset, stamp_ns))
                del self._pending[: offset + 1]
                self._first += offset + 1
                return True
        return False

    def marker_stamp(self, k: int) -> int | None:
        """The stamp of a message that came after the first k written samples: 1 ns after the
        last of them that came back (1 ns before the next that did, when none of them did);
        None until all k are resolved.
        """
        if k > self._first:
            return None
        at = bisect.bisect_left(self._matched, (k, -1))  # matched indices < k end here
        if at:
            return self._matched[at - 1][1] + 1
        return self._matched[at][1] - 1 if at < len(self._matched) else None
