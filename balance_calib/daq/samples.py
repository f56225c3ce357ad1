"""Records -> the samples balance_daq publishes: checked, counted, converted to mV and stamped.

A record's fields are checked in this order, each dropped record counted once, in the first
count it meets (docs/interfaces.md, "Acquisition"):

1. malformed: a used field (every column but `_`) that is not a finite number, a `seq` that is
   not an integer in [0, 2**32), an `excitation` that is not > 0 (its fields are not used);
2. duplicate: its `seq` repeats the last one or goes back by less than 1000 (a late sample);
   a `seq` that skips counts the samples missing, one further back (or the first after a
   reconnect) starts the count afresh; invalid and saturated records move the count on too;
3. invalid: a non-zero `status`;
4. saturated: a bridge field whose magnitude reaches `saturation` (in `units`).

What is left is published: the six bridges in mV, `header.stamp` the host's time at arrival, or,
with a `time` column, the device time carried onto the host clock by one offset, fixed at the
first sample and again after a reconnect or a device-time jump (back, or forward by more than
JUMP_S); stamps strictly increase. Vectorised over a chunk; the sequence walks its records only
when a chunk's steps are not all one.
"""

from __future__ import annotations

from dataclasses import dataclass
from dataclasses import fields as dataclass_fields

import numpy as np

from .parameters import DaqSettings, MV_PER_UNIT, RATIOMETRIC

SEQ_MODULUS = 2**32  # seq wraps here
LATE_WINDOW = 1000  # a seq back by less than this is a duplicate or a late sample
JUMP_S = 1.0  # device time forward by more than this between samples: a jump


@dataclass
class Counts:
    """The contract's counters (the /diagnostics keys of the same names)."""

    samples_published: int = 0
    records_malformed: int = 0
    samples_invalid: int = 0
    samples_saturated: int = 0
    samples_missing: int = 0
    samples_duplicate: int = 0
    reconnects: int = 0
    time_jumps: int = 0  # device-time jumps that re-fixed the offset (console, not a key)

    def copy(self) -> Counts:
        return Counts(**{f.name: getattr(self, f.name) for f in dataclass_fields(self)})

    @property
    def dropped(self) -> int:
        """Records and samples lost for any reason but saturation."""
        return (
            self.records_malformed
            + self.samples_invalid
            + self.samples_missing
            + self.samples_duplicate
        )


@dataclass(frozen=True)
class Samples:
    """Published samples of one chunk: stamps (M,) int64 ns (host clock), bridges (M, 6) mV in
    FXV ... MZV order, temperature (M,) degC or None when the device sends none.
    """

    stamps_ns: np.ndarray
    bridges_mv: np.ndarray
    temperature_c: np.ndarray | None

    def __len__(self) -> int:
        return len(self.stamps_ns)


EMPTY = Samples(np.zeros(0, np.int64), np.zeros((0, 6)), None)


class SampleStream:
    """The state between chunks (last seq, time offset, last stamp) and the counts."""

    def __init__(self, settings: DaqSettings):
        self.counts = Counts()
        first = settings.bridge_columns[0]  # FXV ... MZV side by side: a view, not a copy
        side_by_side = settings.bridge_columns == tuple(range(first, first + 6))
        self._bridges: slice | np.ndarray = (
            slice(first, first + 6) if side_by_side else np.array(settings.bridge_columns)
        )
        used = [i for i, name in enumerate(settings.columns) if name != '_']
        self._used = np.array(used, dtype=int)
        self._all_used = len(used) == len(settings.columns)
        self._seq = settings.column('seq')
        self._status = settings.column('status')
        self._temperature = settings.column('temperature')
        self._excitation = settings.column('excitation')
        self._time = settings.column('time')
        self._saturation = np.array(settings.saturation)
        self._saturable = bool(np.isfinite(self._saturation).any())
        self._ratiometric = settings.units in RATIOMETRIC
        # mV per unit of each bridge field (mV/V and uV/V: per volt of excitation too)
        self._mv_per_unit = (
            np.array(settings.counts_to_mv)
            if settings.units == 'counts'
            else np.full(6, MV_PER_UNIT[settings.units])
        )
        self._excitation_v = settings.excitation_v
        self._last_stamp_ns = -1
        self.restart()

    def restart(self) -> None:
        """After a (re)connection: the seq count starts afresh, the time offset is fixed again."""
        self._last_seq: int | None = None
        self._last_time_s: float | None = None
        self._offset_ns = 0

    def take(self, fields: np.ndarray, arrival_ns: int, malformed: int = 0) -> Samples:
        """The samples to publish of fields (N, columns): whole records in arrival order, arrived
        at arrival_ns (host clock); malformed: records the framing already dropped.
        """
        self.counts.records_malformed += malformed
        if not len(fields):
            return EMPTY
        if self._plain(fields):  # the usual chunk: every record good, seq stepping by one
            if self._seq is not None:
                self._last_seq = int(fields[-1, self._seq])
            time_ns = (
                None
                if self._time is None
                else self._device_time(fields[:, self._time], arrival_ns)
            )
        else:
            fields, time_ns = self._checked(fields, arrival_ns)
            if not len(fields):
                return EMPTY
        bridges_mv = fields[:, self._bridges] * self._mv_per_unit
        if self._ratiometric:
            excitation = (
                fields[:, self._excitation, None]
                if self._excitation is not None
                else self._excitation_v
            )
            bridges_mv = bridges_mv * excitation
        stamps = self._stamps(time_ns, arrival_ns, len(bridges_mv))
        self.counts.samples_published += len(stamps)
        temperature = fields[:, self._temperature] if self._temperature is not None else None
        return Samples(stamps, bridges_mv, temperature)

    def _plain(self, fields: np.ndarray) -> bool:
        """True when every record is usable, fresh, unflagged and unsaturated, its seq (if any)
        following the last one by one each: what _checked would pass whole, in a few operations.
        """
        if not np.isfinite(fields if self._all_used else fields[:, self._used]).all():
            return False
        if self._seq is not None:
            seq = fields[:, self._seq]
            if self._last_seq is None or seq[0] != self._last_seq + 1:
                return False
            if len(seq) > 1 and not (seq[1:] - seq[:-1] == 1).all():
                return False
            if seq[-1] >= SEQ_MODULUS:
                return False
        if self._status is not None and fields[:, self._status].any():
            return False
        if self._excitation is not None and not (fields[:, self._excitation] > 0).all():
            return False
        return not (
            self._saturable and (np.abs(fields[:, self._bridges]) >= self._saturation).any()
        )

    def _checked(
        self, fields: np.ndarray, arrival_ns: int
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """Record by record as the module says: -> the records to publish and their device time
        carried onto the host clock (ns; None without a time column); counts the others.
        """
        counts = self.counts
        fields = fields[self._usable(fields)]
        if not len(fields):
            return fields, None
        if self._seq is not None:
            fresh = self._sequence(fields[:, self._seq])
            if not fresh.all():
                fields = fields[fresh]
        time_ns = (
            self._device_time(fields[:, self._time], arrival_ns)
            if self._time is not None and len(fields)
            else None
        )
        good = np.ones(len(fields), bool)
        if self._status is not None:
            good &= fields[:, self._status] == 0
            counts.samples_invalid += int(len(good) - good.sum())
        saturated = good & (np.abs(fields[:, self._bridges]) >= self._saturation).any(axis=1)
        counts.samples_saturated += int(saturated.sum())
        good &= ~saturated
        if not good.all():
            fields = fields[good]
            time_ns = time_ns[good] if time_ns is not None else None
        return fields, time_ns

    def _usable(self, fields: np.ndarray) -> np.ndarray:
        """Mask of the records whose used fields are all finite numbers (and seq an integer of
        32 bits, excitation > 0); counts the others as malformed.
        """
        ok = np.isfinite(fields[:, self._used]).all(axis=1)
        if self._seq is not None:
            seq = fields[:, self._seq]
            with np.errstate(invalid='ignore'):
                ok &= (seq >= 0) & (seq < SEQ_MODULUS) & (seq == np.floor(seq))
        if self._excitation is not None:
            with np.errstate(invalid='ignore'):
                ok &= fields[:, self._excitation] > 0
        self.counts.records_malformed += int(len(ok) - ok.sum())
        return ok

    def _sequence(self, seq_values: np.ndarray) -> np.ndarray:
        """Mask of the records that are not duplicates; counts missing and duplicate samples."""
        seq = seq_values.astype(np.int64)
        fresh = np.ones(len(seq), bool)
        last = self._last_seq
        if last is not None and np.all(np.diff(seq, prepend=last) == 1):  # the usual chunk
            self._last_seq = int(seq[-1])
            return fresh
        half = SEQ_MODULUS // 2
        for i, value in enumerate(seq.tolist()):
            if last is None:
                last = value
                continue
            step = (value - last + half) % SEQ_MODULUS - half  # signed, modulo 2**32
            if step >= 1:
                self.counts.samples_missing += step - 1
                last = value
            elif step > -LATE_WINDOW:  # repeated, or back by less than LATE_WINDOW
                self.counts.samples_duplicate += 1
                fresh[i] = False
            else:  # further back: the device started counting again
                last = value
        self._last_seq = last
        return fresh

    def _device_time(self, time_s: np.ndarray, arrival_ns: int) -> np.ndarray:
        """Device time (s) of each record carried onto the host clock, ns."""
        if len(time_s) == 1:  # one record a read, the usual case of a line device: no arrays
            return np.array([self._one_device_time(float(time_s[0]), arrival_ns)], np.int64)
        previous = np.nan if self._last_time_s is None else self._last_time_s
        steps = np.diff(time_s, prepend=previous)
        refix = ~((steps >= 0) & (steps <= JUMP_S))  # NaN (first sample) included
        self.counts.time_jumps += int(refix.sum()) - int(self._last_time_s is None)
        device_ns = np.round(time_s * 1e9).astype(np.int64)
        index = np.arange(len(time_s))
        last_refix = np.maximum.accumulate(np.where(refix, index, -1))
        offsets = np.where(
            last_refix >= 0, arrival_ns - device_ns[np.maximum(last_refix, 0)], self._offset_ns
        )
        self._offset_ns = int(offsets[-1])
        self._last_time_s = float(time_s[-1])
        return device_ns + offsets

    def _one_device_time(self, time_s: float, arrival_ns: int) -> int:
        """_device_time of a single record, in scalars (same rule: re-fixed at the first record,
        a step back or forward by more than JUMP_S).
        """
        last = self._last_time_s
        device_ns = round(time_s * 1e9)
        if last is None or not 0.0 <= time_s - last <= JUMP_S:
            self.counts.time_jumps += int(last is not None)
            self._offset_ns = arrival_ns - device_ns
        self._last_time_s = time_s
        return device_ns + self._offset_ns

    def _stamps(self, time_ns: np.ndarray | None, arrival_ns: int, count: int) -> np.ndarray:
        """Strictly increasing stamps: the device's carried time, or the arrival time."""
        if count == 0:
            return np.zeros(0, np.int64)
        if count == 1:  # one sample a read: the usual case at high rates
            one = arrival_ns if time_ns is None else int(time_ns[0])
            self._last_stamp_ns = max(one, self._last_stamp_ns + 1)
            return np.array([self._last_stamp_ns], np.int64)
        index = np.arange(count, dtype=np.int64)
        wanted = np.full(count, arrival_ns, np.int64) if time_ns is None else time_ns
        # s_i strictly increasing <=> s_i - i non-decreasing
        stamps = np.maximum.accumulate(np.maximum(wanted - index, self._last_stamp_ns + 1)) + index
        self._last_stamp_ns = int(stamps[-1])
        return stamps
