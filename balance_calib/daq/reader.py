"""The device read on a thread of its own: connect, read, decode, hand samples on, reconnect.

`DeviceReader(settings, on_samples, log, now_ns)` reads with blocking reads that time out
(transports.READ_TIMEOUT_S: no busy loop) and calls `on_samples(Samples)` from its thread for each
chunk that gave samples (the node publishes them there: no queue between). It never gives up on
the device: a link that cannot be opened or is lost (or an error of its own while reading: it is
logged) is tried again every reconnect_period_s,
each attempt after the first counted in `reconnects`; a UDP device asked with a start_request
that stays silent that long is asked again, which counts as a reconnect too. Console lines go to
`log(level, text)`, at most one a second per kind of trouble. `snapshot()` gives the counts, the
connection and the last sample's time for /diagnostics, under the lock the thread updates them
with. Pure Python (no rclpy): tests drive it against fake devices.
"""

from __future__ import annotations

import threading
import time
from typing import Callable

from .framing import LineFramer, LineParser, RecordParser, Records
from .parameters import DaqSettings
from .samples import Counts, Samples, SampleStream
from .transports import open_link

LOG_PERIOD_S = 1.0  # one console line a second per kind of trouble at most
NON_DATA_REMEMBERED = 1000  # distinct skipped lines remembered (each is logged once)
COUNTED = (
    ('records_malformed', 'malformed records'),
    ('samples_invalid', 'invalid samples (status flag)'),
    ('samples_saturated', 'saturated samples'),
    ('samples_missing', 'missing samples (sequence gaps)'),
    ('samples_duplicate', 'duplicate or late samples'),
    ('time_jumps', 'device-time jumps (stamps re-fixed)'),
)


class Throttle:
    """At most one line per kind every period_s (monotonic clock)."""

    def __init__(self, log: Callable[[str, str], None], period_s: float = LOG_PERIOD_S):
        self._log, self._period = log, period_s
        self._last: dict[str, float] = {}

    def __call__(self, kind: str, level: str, text: str) -> bool:
        """Log `text` unless this kind was logged less than period_s ago; -> whether it was."""
        now = time.monotonic()
        if now - self._last.get(kind, -float('inf')) < self._period:
            return False
        self._last[kind] = now
        self._log(level, text)
        return True


class DeviceReader:
    def __init__(
        self,
        settings: DaqSettings,
        on_samples: Callable[[Samples], None],
        log: Callable[[str, str], None],
        now_ns: Callable[[], int],
    ):
        self.settings = settings
        self._on_samples = on_samples
        self._say = Throttle(log)
        self._now_ns = now_ns
        self._lock = threading.Lock()
        self._stream = SampleStream(settings)
        self._connected = False
        self._last_sample_s: float | None = None
        self._stop = threading.Event()
        self._framer = LineFramer()
        self._parser: LineParser | RecordParser = (
            RecordParser(settings.record_format, settings.columns)
            if settings.framing == 'binary'
            else LineParser(settings.columns, settings.line_prefix)
        )
        self._non_data_seen: set[str] = set()
        self._reported = Counts()
        self._thread = threading.Thread(target=self._run, name='balance_daq_device', daemon=True)

    def start(self) -> None:
        self._thread.start()

    def close(self, timeout_s: float = 5.0) -> None:
        """Stop the thread (it sends stop_request and closes the link) and wait for it."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout_s)

    def snapshot(self) -> tuple[Counts, bool, float | None]:
        """(counts, connected, monotonic time of the last published sample or None)."""
        with self._lock:
            return self._stream.counts.copy(), self._connected, self._last_sample_s

    # --- the thread --------------------------------------------------------------------------
    def _run(self) -> None:
        settings = self.settings
        attempts = 0
        while not self._stop.is_set():
            if attempts:
                with self._lock:
                    self._stream.counts.reconnects += 1
            attempts += 1
            try:
                link = open_link(settings)
            # serial.SerialException is an OSError; ImportError: pyserial is missing
            except (OSError, ValueError, ImportError) as err:
                self._say(
                    'connect',
                    'warning',
                    f'cannot reach {settings.device} ({settings.transport}): {err}; trying again '
                    f'every {settings.reconnect_period_s:g} s',
                )
                self._stop.wait(settings.reconnect_period_s)
                continue
            self._framer.restart(link.partial_first)
            with self._lock:
                self._stream.restart()
                self._connected = True
            self._say(
                'connected', 'info', f'connected to {settings.device} ({settings.transport})'
            )
            try:
                self._read(link)
            except OSError as err:
                self._say('lost', 'warning', f'lost {settings.device}: {err}; reconnecting')
            except Exception as err:  # noqa: BLE001 (a bug must not end the device's thread)
                if self._stop.is_set():  # shutting down: the publishers may be gone already
                    break
                self._say(
                    'error', 'error', f'unexpected {err!r} reading {settings.device}; reconnecting'
                )
            finally:
                link.close()
                with self._lock:
                    self._connected = False
                    if self._framer.lost_partial():  # a line cut by the loss
                        self._stream.counts.records_malformed += 1
            self._stop.wait(settings.reconnect_period_s)

    def _read(self, link) -> None:
        """Read until stopped (returns) or the link is lost (OSError)."""
        period = self.settings.reconnect_period_s
        heard = time.monotonic()
        while not self._stop.is_set():
            data = link.read()
            if data is None:
                if getattr(link, 'asks', False) and time.monotonic() - heard >= period:
                    self._say(
                        'silent',
                        'warning',
                        f'{self.settings.device} silent for {period:g} s: start_request sent '
                        'again',
                    )
                    link.resend()
                    heard = time.monotonic()
                    with self._lock:
                        self._stream.counts.reconnects += 1
                        self._stream.restart()
                continue
            heard = time.monotonic()
            arrival_ns = self._now_ns()
            records = self._records(link, data)
            with self._lock:
                samples = self._stream.take(records.fields, arrival_ns, records.malformed)
                if len(samples):
                    self._last_sample_s = heard
            if len(samples):
                self._on_samples(samples)
            self._tell(records)

    def _records(self, link, data: bytes) -> Records:
        datagrams = [data] + link.waiting() if link.datagrams else [data]
        if isinstance(self._parser, RecordParser):
            return self._parser.parse(datagrams)
        if link.datagrams:  # a datagram of text ends its line
            data = b''.join(d if d.endswith(b'\n') else d + b'\n' for d in datagrams)
        lines, overlong = self._framer.feed(data)
        records = self._parser.parse(lines)
        records.malformed += overlong
        return records

    def _tell(self, records: Records) -> None:
        """Console lines for what this chunk added to the counts, one a second per kind."""
        for line in records.non_data:  # each distinct one once (when the second allows it)
            if (
                line not in self._non_data_seen
                and len(self._non_data_seen) < NON_DATA_REMEMBERED
                and self._say('non-data', 'info', f'skipped a line that is not data: {line!r}')
            ):
                self._non_data_seen.add(line)
        with self._lock:
            counts = self._stream.counts.copy()
        for key, what in COUNTED:
            if getattr(counts, key) != getattr(self._reported, key):
                self._say(key, 'warning', f'{getattr(counts, key)} {what} so far')
        self._reported = counts
