"""balance_daq's parameter table (parameter_table.Spec) and the settings checked from it.

The table is the contract's (docs/interfaces.md, "Acquisition"); every parameter is read once, at
start-up. `daq_settings(values)` turns the declared values into one frozen DaqSettings or refuses
them with a ParameterError: one line naming the parameter (an unknown transport, framing or unit;
`columns` without each bridge exactly once; a `record_format` that `struct` cannot read or whose
field count differs from `columns`; `binary` other than over `udp`; ...). No rclpy here.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
import struct
from typing import Mapping

from ..parameter_table import check_value, ParameterError, Spec, startup

BRIDGES = (
    'FXV',
    'FYV',
    'FZV',
    'MXV',
    'MYV',
    'MZV',
)  # TM-663's bridge outputs, in /balance/raw order
# the columns a record may name besides the bridges (each at most once; `_` any number of times)
EXTRA_COLUMNS = ('seq', 'status', 'temperature', 'excitation', 'time')
IGNORED = '_'
TRANSPORTS = ('serial', 'tcp', 'udp')
FRAMINGS = ('line', 'binary')
# bridge unit -> mV per unit (the ratiometric ones per volt of excitation)
UNITS = ('mV', 'V', 'mV/V', 'uV/V', 'counts')
MV_PER_UNIT = {'mV': 1.0, 'V': 1000.0, 'mV/V': 1.0, 'uV/V': 1e-3}
RATIOMETRIC = ('mV/V', 'uV/V')

PARAMETERS: dict[str, Spec] = {
    'transport': startup(
        'serial',
        'serial (a tty or pty path), tcp (connects to host:port), udp (with a start_request: '
        'sends it to the device at host:port and reads the replies, resending it every '
        'reconnect_period_s while the device is silent; without: binds host:port)',
        choices=TRANSPORTS,
    ),
    'device': startup('/dev/ttyUSB0', 'the serial path, or host:port'),
    'baud': startup(115200, 'serial only: the baud rate', 1, 100_000_000),
    'framing': startup(
        'line',
        'line: text lines (\\n or \\r\\n); binary: fixed-size records, one or more per '
        'datagram (udp only)',
        choices=FRAMINGS,
    ),
    'record_format': startup('', 'binary only: a Python struct format of one record, e.g. >3I6i'),
    'columns': startup(
        list(BRIDGES),
        'the fields of a record or data line, in order: the six bridges FXV ... MZV (each '
        'exactly once), seq, status, temperature (degC), excitation (V), time (device time, s), '
        '_ (ignored)',
    ),
    'line_prefix': startup(
        '',
        'line only: a data line starts with this token (not a column); other lines are '
        'logged once and skipped',
    ),
    'start_request': startup(
        '', 'hex bytes sent after connecting (ATI Net F/T RDT: 1234000200000000)'
    ),
    'stop_request': startup(
        '', 'hex bytes sent before closing (ATI Net F/T RDT: 1234000000000000)'
    ),
    'units': startup('mV', 'unit of the bridge fields', choices=UNITS),
    'counts_to_mv': startup(
        [1.0], 'units counts: mV per count, one value or one per bridge (FXV ... MZV)'
    ),
    'excitation_v': startup(
        5.0,
        "units mV/V and uV/V: the nominal bridge supply, V; a sample's excitation column "
        'replaces it',
        0.0,
        low_open=True,
    ),
    'saturation': startup(
        [math.inf],
        'a bridge field whose magnitude reaches this (in units; one value or one per bridge) '
        'is saturated',
        inf_allowed=True,
    ),
    'expected_rate_hz': startup(
        1000.0, 'for the rate check in /diagnostics (+-20 %), Hz', 0.0, low_open=True
    ),
    'stale_after_s': startup(
        0.5, 'no valid sample for this long: the input is stale (ERROR), s', 0.0, low_open=True
    ),
    'reconnect_period_s': startup(
        1.0, 'how often a lost device is tried again (udp: the start_request resent), s', 0.01
    ),
    'frame_id': startup('balance', 'header.frame_id of /balance/raw'),
}


@dataclass(frozen=True)
class DaqSettings:
    """What balance_daq does, checked. Columns are indices into a record's fields."""

    transport: str
    device: str
    baud: int
    framing: str
    record_format: str
    columns: tuple[str, ...]
    line_prefix: str
    start_request: bytes
    stop_request: bytes
    units: str
    counts_to_mv: tuple[float, ...]  # six, mV per count
    excitation_v: float
    saturation: tuple[float, ...]  # six, in `units`
    expected_rate_hz: float
    stale_after_s: float
    reconnect_period_s: float
    frame_id: str

    @property
    def bridge_columns(self) -> tuple[int, ...]:
        """Index of FXV ... MZV among the fields."""
        return tuple(self.columns.index(name) for name in BRIDGES)

    def column(self, name: str) -> int | None:
        """Index of an extra column (seq, status, ...) among the fields; None if absent."""
        return self.columns.index(name) if name in self.columns else None

    @property
    def address(self) -> tuple[str, int]:
        """(host, port) of a tcp or udp device."""
        return host_port(self.device)


def host_port(device: str) -> tuple[str, int]:
    """'host:port' -> (host, port); ParameterError naming `device` otherwise."""
    host, colon, port = device.rpartition(':')
    if not colon or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ParameterError(
            f'parameter device must be host:port (port 1-65535) for tcp and udp, not {device!r}'
        )
    return host.strip('[]'), int(port)


def _per_bridge(name: str, values: list[float]) -> tuple[float, ...]:
    if len(values) == 1:
        return (values[0],) * 6
    if len(values) == 6:
        return tuple(values)
    raise ParameterError(
        f'parameter {name} must hold one value or six (one per bridge), not {len(values)}'
    )


def _hex(name: str, text: str) -> bytes:
    try:
        return bytes.fromhex(text)
    except ValueError:
        raise ParameterError(
            f'parameter {name} must be hex bytes such as 1234000200000000, not {text!r}'
        ) from None


def _columns(columns: list[str]) -> tuple[str, ...]:
    for name in columns:
        if name not in BRIDGES + EXTRA_COLUMNS + (IGNORED,):
            raise ParameterError(
                f'parameter columns: unknown column {name!r} (names: '
                f'{", ".join(BRIDGES + EXTRA_COLUMNS)}, _)'
            )
    for name in BRIDGES + EXTRA_COLUMNS:
        count = columns.count(name)
        if count > 1 or (count == 0 and name in BRIDGES):
            raise ParameterError(
                f'parameter columns must name each of {", ".join(BRIDGES)} exactly once and '
                f'every other column at most once ({name} {"missing" if count == 0 else "twice"} '
                f'in {columns})'
            )
    return tuple(columns)


def record_fields(record_format: str) -> int:
    """How many numbers one record of this struct format holds; ParameterError if it cannot be
    read or holds something else (bytes, characters).
    """
    try:
        layout = struct.Struct(record_format)
    except struct.error as err:
        raise ParameterError(
            f'parameter record_format {record_format!r} is not a struct format: {err}'
        ) from None
    fields = layout.unpack(bytes(layout.size))
    if layout.size == 0 or not all(isinstance(f, (int, float)) for f in fields):
        raise ParameterError(
            f'parameter record_format {record_format!r} must describe numbers only '
            '(integer and float codes, x for padding)'
        )
    return len(fields)


def daq_settings(values: Mapping[str, object]) -> DaqSettings:
    """The settings of the declared parameter values (name -> value, missing ones take their
    default); ParameterError, one line naming the parameter, for anything balance_daq refuses.
    """
    held = {
        name: check_value(name, spec, values.get(name, spec.default))
        for name, spec in PARAMETERS.items()
    }
    columns = _columns(list(held['columns']))  # type: ignore[call-overload]
    transport, framing = str(held['transport']), str(held['framing'])
    if framing == 'binary':
        if transport != 'udp':
            raise ParameterError(
                f'parameter framing binary needs transport udp (a datagram holds whole '
                f'records), not {transport}'
            )
        count = record_fields(str(held['record_format']))
        if count != len(columns):
            raise ParameterError(
                f'parameter record_format {held["record_format"]!r} holds {count} fields but '
                f'columns names {len(columns)}'
            )
    device = str(held['device'])
    if transport in ('tcp', 'udp'):
        host_port(device)
    elif not device:
        raise ParameterError('parameter device must be the serial port path, not empty')
    saturation = _per_bridge('saturation', list(held['saturation']))  # type: ignore[call-overload]
    if any(s <= 0 for s in saturation):
        raise ParameterError(f'parameter saturation must be > 0, not {list(saturation)}')
    counts = _per_bridge('counts_to_mv', list(held['counts_to_mv']))  # type: ignore[call-overload]
    if any(c == 0 for c in counts):
        raise ParameterError(f'parameter counts_to_mv must not be 0, not {list(counts)}')
    return DaqSettings(
        transport=transport,
        device=device,
        baud=int(held['baud']),  # type: ignore[call-overload]
        framing=framing,
        record_format=str(held['record_format']),
        columns=columns,
        line_prefix=str(held['line_prefix']).strip(),
        start_request=_hex('start_request', str(held['start_request'])),
        stop_request=_hex('stop_request', str(held['stop_request'])),
        units=str(held['units']),
        counts_to_mv=counts,
        excitation_v=float(held['excitation_v']),  # type: ignore[arg-type]
        saturation=saturation,
        expected_rate_hz=float(held['expected_rate_hz']),  # type: ignore[arg-type]
        stale_after_s=float(held['stale_after_s']),  # type: ignore[arg-type]
        reconnect_period_s=float(held['reconnect_period_s']),  # type: ignore[arg-type]
        frame_id=str(held['frame_id']),
    )
