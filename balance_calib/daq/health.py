"""balance_daq's /diagnostics status: the contract's keys and levels, from the counts.

One status a period (1 Hz), named `balance_daq: ` + device. Level ERROR while disconnected,
stale (no valid sample for stale_after_s) or saturated (a saturated sample in the period); WARN
while the rate is off expected_rate_hz by more than RATE_TOLERANCE or samples were dropped in the
period (malformed, invalid, missing, duplicate); OK otherwise. docs/interfaces.md, "Acquisition".
A device-time jump (the stamps' offset fixed again) is said in the message, at no level of its own.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

from .samples import Counts

OK, WARN, ERROR = 0, 1, 2  # diagnostic_msgs/DiagnosticStatus levels
RATE_TOLERANCE = 0.2
NAME_PREFIX = 'balance_daq: '
COUNTER_KEYS = (
    'samples_published',
    'records_malformed',
    'samples_invalid',
    'samples_saturated',
    'samples_missing',
    'samples_duplicate',
    'reconnects',
)


@dataclass(frozen=True)
class DaqStatus:
    """One DiagnosticStatus: level, name, message, hardware_id, (key, value) pairs."""

    level: int
    name: str
    message: str
    hardware_id: str
    values: tuple[tuple[str, str], ...]


class Health:
    """The status of each period, from the counts at its end and those at the last one."""

    def __init__(self, device: str, expected_rate_hz: float, stale_after_s: float, start_s: float):
        self._device = device
        self._expected = expected_rate_hz
        self._stale_after = stale_after_s
        self._start_s = start_s
        self._last = Counts()
        self._last_s = start_s

    def status(
        self, counts: Counts, connected: bool, now_s: float, last_sample_s: float | None
    ) -> DaqStatus:
        """counts: cumulative; now_s and last_sample_s (the last published sample's arrival, or
        None) on one monotonic clock, s.
        """
        period = max(now_s - self._last_s, 1e-9)
        rate = (counts.samples_published - self._last.samples_published) / period
        dropped = counts.dropped - self._last.dropped
        saturated = counts.samples_saturated - self._last.samples_saturated
        age = now_s - (self._start_s if last_sample_s is None else last_sample_s)
        errors, warnings = [], []
        if not connected:
            errors.append('disconnected')
        if age > self._stale_after:
            errors.append(f'stale: no valid sample for {age:.1f} s')
        if saturated:
            errors.append(f'{saturated} saturated')
        if abs(rate - self._expected) > RATE_TOLERANCE * self._expected:
            warnings.append(f'rate {rate:.1f} Hz, expected {self._expected:g} Hz')
        if dropped:
            warnings.append(f'{dropped} dropped (malformed, invalid, missing or duplicate)')
        jumps = counts.time_jumps - self._last.time_jumps  # said, but no level of its own
        notes = [f'device time jumped {jumps} time(s): stamps re-fixed'] if jumps else []
        level = ERROR if errors else WARN if warnings else OK
        values = tuple((key, str(getattr(counts, key))) for key in COUNTER_KEYS)
        values = (
            (('rate_hz', f'{rate:.1f}'),)
            + values
            + (
                ('last_sample_age_s', f'{age:.3f}' if math.isfinite(age) else 'inf'),
                ('connected', 'true' if connected else 'false'),
            )
        )
        self._last, self._last_s = counts.copy(), now_s
        return DaqStatus(
            level,
            NAME_PREFIX + self._device,
            '; '.join((errors + warnings or ['ok']) + notes),
            self._device,
            values,
        )
