"""Fake data acquisition devices on this machine, for balance_daq's tests.

Written from the protocols as the devices describe them, not from balance_daq's decoder:

- PtyDevice: a serial device, a pseudo-terminal (os.openpty) whose slave path the node opens;
  the test writes what a microcontroller would print.
- TcpDevice: a bridge amplifier's TCP server on loopback that accepts the node, streams what
  the test gives it, can drop the connection mid-line and accept the node again.
- refused_tcp_address(): a loopback port where nobody listens (the peer refuses).
- RdtDevice: an ATI Net F/T (or Axia) sensor's Raw Data Transfer over UDP, as ATI's manual
  describes it: the client sends an 8-byte request, big-endian uint16 header 0x1234, uint16
  command (0 stop streaming, 2 start high-speed real-time streaming), uint32 sample count (0:
  until stopped); the sensor answers to the request's source address with 36-byte big-endian
  records: uint32 rdt_sequence, uint32 ft_sequence, uint32 status, int32 Fx Fy Fz Tx Ty Tz
  (counts), one record per datagram normally (several when buffered). It can stay deaf to the
  first requests (a silent device).
"""

from __future__ import annotations

import os
import socket
import struct
import threading
import time
import tty

RDT_HEADER = 0x1234
RDT_STOP, RDT_START = 0x0000, 0x0002
RDT_PORT = 49152


def _wait(predicate, timeout_s: float, what: str):
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f'timed out after {timeout_s:g} s waiting for {what}')
        time.sleep(0.01)


class PtyDevice:
    """A serial device: write() goes to whoever opened `path`."""

    def __init__(self):
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no \r -> \n translation: bytes as the device sent them
        self.path = os.ttyname(self._slave)

    def write(self, data: bytes) -> None:
        os.write(self._master, data)

    def close(self) -> None:
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass


class TcpDevice:
    """A TCP server streaming to one client at a time; `received` is what clients sent."""

    def __init__(self):
        self._server = socket.create_server(('127.0.0.1', 0))
        self.address = '127.0.0.1:%d' % self._server.getsockname()[1]
        self._client: socket.socket | None = None
        self.accepted = 0
        self.received = b''
        self._closed = False
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while not self._closed:
            try:
                client, _ = self._server.accept()
            except OSError:
                return
            self._client = client
            self.accepted += 1
            client.settimeout(0.1)
            while not self._closed and self._client is client:
                try:
                    data = client.recv(4096)
                except TimeoutError:
                    continue
                except OSError:
                    break
                if not data:
                    break
                self.received += data

    def wait_client(self, count: int = 1, timeout_s: float = 20.0) -> None:
        """Until `count` clients have been accepted in all."""
        _wait(lambda: self.accepted >= count and self._client is not None, timeout_s, 'a client')

    def send(self, data: bytes) -> None:
        assert self._client is not None, 'no client connected'
        self._client.sendall(data)

    def drop(self) -> None:
        """Close the client's connection (the server keeps listening)."""
        client, self._client = self._client, None
        if client is not None:
            client.close()

    def close(self) -> None:
        self._closed = True
        self.drop()
        self._server.close()


def refused_tcp_address() -> str:
    """host:port of a loopback port nobody listens on: a connection there is refused."""
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        port = probe.getsockname()[1]
    return f'127.0.0.1:{port}'


def rdt_request(command: int, samples: int = 0) -> bytes:
    """ATI's 8-byte RDT request."""
    return struct.pack('>HHI', RDT_HEADER, command, samples)


def rdt_record(rdt_sequence: int, ft_sequence: int, status: int, counts) -> bytes:
    """ATI's 36-byte RDT record: three uint32 then six int32 counts, big-endian."""
    return struct.pack('>3I6i', rdt_sequence, ft_sequence, status, *counts)


class RdtDevice:
    """An ATI Net F/T sensor's RDT server on a loopback UDP port.

    deaf_requests: how many requests to ignore before answering (a silent device). Requests are
    logged in `requests` as (command, sample count); malformed ones (wrong size or header) are
    ignored, as the sensor does. `send(*datagrams)` sends to the client that asked to stream.
    """

    def __init__(self, deaf_requests: int = 0):
        self._socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._socket.bind(('127.0.0.1', 0))
        self._socket.settimeout(0.1)
        self.address = '127.0.0.1:%d' % self._socket.getsockname()[1]
        self.requests: list[tuple[int, int]] = []
        self._deaf = deaf_requests
        self.client = None
        self.streaming = False
        self._closed = False
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while not self._closed:
            try:
                data, source = self._socket.recvfrom(64)
            except TimeoutError:
                continue
            except OSError:
                return
            if len(data) != 8:
                continue
            header, command, samples = struct.unpack('>HHI', data)
            if header != RDT_HEADER:
                continue
            self.requests.append((command, samples))
            if len(self.requests) <= self._deaf:
                continue
            if command == RDT_START:
                self.client, self.streaming = source, True
            elif command == RDT_STOP:
                self.streaming = False

    def wait_streaming(self, timeout_s: float = 20.0) -> None:
        _wait(lambda: self.streaming, timeout_s, 'an RDT start request answered')

    def send(self, *datagrams: bytes) -> None:
        assert self.client is not None, 'nobody asked to stream'
        for datagram in datagrams:
            self._socket.sendto(datagram, self.client)

    def close(self) -> None:
        self._closed = True
        self._socket.close()


class UdpSender:
    """A device that sends datagrams to a bound node at host:port, unasked."""

    def __init__(self, address: str):
        host, port = address.rsplit(':', 1)
        self._target = (host, int(port))
        self._socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def send(self, *datagrams: bytes) -> None:
        for datagram in datagrams:
            self._socket.sendto(datagram, self._target)

    def close(self) -> None:
        self._socket.close()


def free_udp_address() -> str:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(('127.0.0.1', 0))
        return '127.0.0.1:%d' % probe.getsockname()[1]
