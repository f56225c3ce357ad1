"""What arrives from a device, cut into records: text lines, or fixed-size binary records.

Both give an array of fields (N, len(columns)) float64 per chunk read, and how many records were
malformed: the wrong number of fields, a field that is not a number, bytes that are not ASCII,
a datagram that is not whole records. Whether a number is finite is the sample stream's check
(samples.py), which needs the column names. Contract: docs/interfaces.md, "Acquisition".
"""

from __future__ import annotations

from dataclasses import dataclass, field
import re
import struct

import numpy as np

# a field separator: a comma or a semicolon (with the spaces around it), or a run of spaces/tabs
SEPARATOR = re.compile(rb'[ \t]*[,;][ \t]*|[ \t]+')
MAX_LINE_BYTES = 4096  # a longer line is malformed, and its bytes are dropped as they come
NON_DATA_SHOWN = 120  # characters of a skipped line shown in the log


@dataclass
class Records:
    """Records of one chunk: fields (N, columns) float64 (NaN where a column is ignored),
    `malformed` records dropped, and the text of the lines that were not data (line_prefix).
    """

    fields: np.ndarray
    malformed: int = 0
    non_data: list[str] = field(default_factory=list)


class LineFramer:
    """Text lines out of a byte stream: complete lines only, LF or CR LF ends one.

    restart(partial_first) after a (re)connection: a serial port's first line may be a tail and
    is dropped uncounted; a TCP stream starts at a line boundary. `lost_partial()` at a loss
    says whether a line was cut (the reader counts it malformed).
    """

    def __init__(self, max_line_bytes: int = MAX_LINE_BYTES):
        self._max = max_line_bytes
        self._pending = b''
        self._skip_first = False
        self._overlong = False  # dropping the rest of a line longer than max_line_bytes

    def restart(self, partial_first: bool) -> None:
        self._pending, self._skip_first, self._overlong = b'', partial_first, False

    def lost_partial(self) -> bool:
        cut = bool(self._pending.strip()) and not (self._skip_first or self._overlong)
        self._pending = b''
        return cut

    def feed(self, data: bytes) -> tuple[list[bytes], int]:
        """-> (complete lines without their end, overlong lines dropped)."""
        lines = (self._pending + data).split(b'\n')
        self._pending = lines.pop()
        overlong = 0
        if lines and (self._skip_first or self._overlong):
            lines.pop(0)  # the tail of a partial first line, or of an overlong one
            self._skip_first = self._overlong = False
        if len(self._pending) > self._max:
            # counted once, when it first overflows (a partial first line is never counted)
            overlong = int(not (self._skip_first or self._overlong))
            self._pending, self._skip_first, self._overlong = b'', False, True
        return lines, overlong


class LineParser:
    """Data lines -> Records, for `columns` fields after an optional `line_prefix` token."""

    def __init__(self, columns: tuple[str, ...], line_prefix: str = '', ignored: str = '_'):
        self._count = len(columns)
        self._used = np.array([name != ignored for name in columns])
        self._prefix = line_prefix.encode('ascii', 'replace')
        self._all_used = bool(self._used.all())

    def parse(self, lines: list[bytes]) -> Records:
        rows: list[list[bytes]] = []
        malformed = 0
        non_data: list[str] = []
        for raw in lines:
            line = raw.strip()
            if not line:
                continue
            fields = SEPARATOR.split(line)
            if self._prefix:
                if fields[0] != self._prefix:
                    non_data.append(raw.decode('utf-8', 'replace').strip()[:NON_DATA_SHOWN])
                    continue
                fields = fields[1:]
            if len(fields) != self._count or not line.isascii():
                malformed += 1
                continue
            rows.append(fields)
        if not rows:
            return Records(np.zeros((0, self._count)), malformed, non_data)
        if not self._all_used:
            rows = [[f if use else b'nan' for f, use in zip(row, self._used)] for row in rows]
        try:
            values = np.array(rows, dtype=np.float64)
        except ValueError:  # one of them is not a number: find which, line by line
            good = []
            for row in rows:
                try:
                    good.append([float(f) for f in row])
                except ValueError:
                    malformed += 1
            values = np.array(good, dtype=np.float64).reshape(-1, self._count)
        if not self._all_used:
            values[:, ~self._used] = np.nan
        return Records(values, malformed, non_data)


class RecordParser:
    """Datagrams of fixed-size binary records (a struct format) -> Records.

    A datagram that is not a whole number of records cannot be cut into them: it is one
    malformed record, and none of its bytes are used.
    """

    def __init__(self, record_format: str, columns: tuple[str, ...], ignored: str = '_'):
        self._layout = struct.Struct(record_format)
        self._count = len(columns)
        self._ignored = np.array([name == ignored for name in columns])

    def parse(self, datagrams: list[bytes]) -> Records:
        size = self._layout.size
        whole = [d for d in datagrams if d and len(d) % size == 0]
        malformed = len(datagrams) - len(whole)
        if not whole:
            return Records(np.zeros((0, self._count)), malformed)
        values = np.array(
            [fields for d in whole for fields in self._layout.iter_unpack(d)], dtype=np.float64
        ).reshape(-1, self._count)
        values[:, self._ignored] = np.nan
        return Records(values, malformed)
