"""The three ways to a device: a serial port (pyserial), TCP and UDP (the socket module).

A link is opened by `open_link(settings)` (OSError, serial.SerialException being one, when it
cannot be), sends `start_request` once open, and `read()` blocks at most READ_TIMEOUT_S: bytes,
or None when nothing came; OSError when the device is gone (LinkLost for a closed TCP stream).
`close()` sends `stop_request` first. A UDP link with a start_request sends it to host:port and
reads the replies (`resend()` sends it again); without one it binds host:port. Datagram links
read one datagram per call (a datagram is a unit of binary records), and `waiting()` takes those
that arrived meanwhile without blocking.
"""

from __future__ import annotations

import select
import socket

from .parameters import DaqSettings

READ_TIMEOUT_S = 0.2  # a read returns at least this often, so a stop is seen promptly
MAX_DATAGRAM = 65536
MAX_BATCH = 256  # datagrams taken at one wake-up: one decode and one publish loop for them all
RECEIVE_BUFFER_BYTES = 4 << 20  # asked for (the kernel caps it at net.core.rmem_max)
STREAM_CHUNK = 65536


class LinkLost(OSError):
    """The device ended the connection."""


class SerialLink:
    """A tty or pty. Its first line may be a tail (the device was sending before we opened)."""

    partial_first = True
    datagrams = False

    def __init__(self, settings: DaqSettings):
        import serial  # pyserial: only a serial device needs it

        self._port = serial.Serial(settings.device, settings.baud, timeout=READ_TIMEOUT_S)
        self._stop_request = settings.stop_request
        if settings.start_request:
            self._port.write(settings.start_request)

    def read(self) -> bytes | None:
        data = self._port.read(1)  # blocks until a byte or the timeout
        if not data:
            return None
        waiting = self._port.in_waiting
        return data + self._port.read(waiting) if waiting else data

    def resend(self) -> None:
        """Serial devices are not asked again."""

    def close(self) -> None:
        try:
            if self._stop_request:
                self._port.write(self._stop_request)
        except OSError:
            pass
        finally:
            self._port.close()


class TcpLink:
    """A TCP client: a stream that starts at a line boundary."""

    partial_first = False
    datagrams = False

    def __init__(self, settings: DaqSettings):
        self._socket = socket.create_connection(
            settings.address, timeout=min(max(settings.reconnect_period_s, 1.0), 5.0)
        )
        self._socket.settimeout(READ_TIMEOUT_S)
        self._stop_request = settings.stop_request
        if settings.start_request:
            self._socket.sendall(settings.start_request)

    def read(self) -> bytes | None:
        try:
            data = self._socket.recv(STREAM_CHUNK)
        except TimeoutError:
            return None
        if not data:
            raise LinkLost('the device closed the connection')
        return data

    def resend(self) -> None:
        """A TCP device is not asked again."""

    def close(self) -> None:
        try:
            if self._stop_request:
                self._socket.sendall(self._stop_request)
        except OSError:
            pass
        finally:
            self._socket.close()


class UdpLink:
    """UDP: with a start_request, a client of the device at host:port; without, bound to it.

    The socket is non-blocking; read() waits for it with poll(), so that `waiting()` can take
    what else has arrived without a wait of its own.
    """

    partial_first = False
    datagrams = True

    def __init__(self, settings: DaqSettings):
        host, port = settings.address
        family, kind, proto, _, address = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)[0]
        self._socket = socket.socket(family, kind, proto)
        try:
            self._request = settings.start_request
            self._stop_request = settings.stop_request
            if self._request:
                self._socket.connect(address)  # replies from the device only
            else:
                self._socket.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                self._socket.bind(address)
            self._socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
            self._socket.setblocking(False)
            self._poll = select.poll()
            self._poll.register(self._socket, select.POLLIN)
            self.resend()
        except OSError:
            self._socket.close()
            raise

    def read(self) -> bytes | None:
        if not self._poll.poll(READ_TIMEOUT_S * 1000):
            return None
        try:
            return self._socket.recv(MAX_DATAGRAM)
        except (BlockingIOError, InterruptedError, ConnectionRefusedError):
            return None  # nobody there (yet): silence

    def waiting(self, limit: int = MAX_BATCH) -> list[bytes]:
        """The datagrams already waiting (at most `limit`), without blocking: a batch."""
        batch = []
        try:
            for _ in range(limit):
                batch.append(self._socket.recv(MAX_DATAGRAM))
        except (BlockingIOError, InterruptedError, ConnectionRefusedError):
            pass
        return batch

    def resend(self) -> None:
        """Send the start_request (again); nothing for a bound socket."""
        if self._request:
            try:
                self._socket.send(self._request)
            except (BlockingIOError, ConnectionRefusedError):  # found no one: silence
                pass

    @property
    def asks(self) -> bool:
        """True when the device streams only when asked (a start_request)."""
        return bool(self._request)

    def close(self) -> None:
        try:
            if self._request and self._stop_request:
                self._socket.send(self._stop_request)
        except OSError:
            pass
        finally:
            self._socket.close()


def open_link(settings: DaqSettings) -> SerialLink | TcpLink | UdpLink:
    """The link of settings.transport, open; OSError when the device cannot be reached."""
    if settings.transport == 'serial':
        return SerialLink(settings)
    return TcpLink(settings) if settings.transport == 'tcp' else UdpLink(settings)
