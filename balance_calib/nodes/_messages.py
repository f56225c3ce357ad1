"""Message fields filled from plain values, as more than one node fills them."""

from typing import Any, Iterable, Protocol

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Wrench


def set_wrench(wrench: Wrench, values: Iterable[float]) -> None:
    """Set force x, y, z and torque x, y, z of `wrench` from six values (as floats); returns
    nothing.
    """
    (
        wrench.force.x,
        wrench.force.y,
        wrench.force.z,
        wrench.torque.x,
        wrench.torque.y,
        wrench.torque.z,
    ) = (float(v) for v in values)


class PlainStatus(Protocol):
    """One DiagnosticStatus as plain data (live/diagnostics_status.py, daq/health.py)."""

    @property
    def level(self) -> int: ...
    @property
    def name(self) -> str: ...
    @property
    def message(self) -> str: ...
    @property
    def hardware_id(self) -> str: ...
    @property
    def values(self) -> Iterable[tuple[str, str]]: ...


def diagnostic_array(stamp: Any, reports: Iterable[PlainStatus]) -> DiagnosticArray:
    """Returns a DiagnosticArray stamped `stamp` (a builtin_interfaces/Time: clock.now().to_msg())
    with one DiagnosticStatus per report, in order: its level, name, message, hardware_id and
    (key, value) pairs.
    """
    array = DiagnosticArray()
    array.header.stamp = stamp
    array.status = [
        DiagnosticStatus(
            level=bytes([r.level]),
            name=r.name,
            message=r.message,
            hardware_id=r.hardware_id,
            values=[KeyValue(key=k, value=v) for k, v in r.values],
        )
        for r in reports
    ]
    return array
