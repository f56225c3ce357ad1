"""Held attitudes in a stream of samples, and the data point averaged at each.

A tunnel run moves the support from attitude to attitude and holds each while the data are taken.
A hold is a maximal run of consecutive samples in which neither the support angles nor q∞ move:
a new hold starts where any support angle changes by more than `attitude_tolerance_rad` from the
previous sample, or q∞ by more than max(q_tolerance_pa, q_tolerance_fraction·q∞), or where q∞
crosses the wind-off threshold (interfaces.md: wind-off is q∞ < 1 Pa). The rule looks only at
consecutive samples, so the same function runs offline over a whole bag (vectorised) and live one
sample at a time (`HoldTracker`) with identical results.

The data point of a hold averages its samples after the first `settle_samples`: all of them
(`point_samples` = 0), or the first `point_samples` (holds shorter than that give no point).
Holds with fewer than `min_samples` such samples are transients and give no point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class HoldSettings:
    attitude_tolerance_rad: float = 1e-4
    q_tolerance_pa: float = 1.0
    q_tolerance_fraction: float = 0.01
    wind_off_q_pa: float = 1.0
    settle_samples: int = 0
    point_samples: int = 0  # 0: the whole hold after settling
    min_samples: int = 5

    def __post_init__(self):
        for name in (
            'attitude_tolerance_rad',
            'q_tolerance_pa',
            'q_tolerance_fraction',
            'wind_off_q_pa',
        ):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f'{name} must be a non-negative number, not {value}')
        for name in ('settle_samples', 'point_samples', 'min_samples'):
            if int(getattr(self, name)) < 0:
                raise ValueError(f'{name} must not be negative')
        if self.min_samples < 1:
            raise ValueError('min_samples must be at least 1')

    def wind_off(self, q_pa) -> np.ndarray:
        return np.asarray(q_pa, float) < self.wind_off_q_pa

    def new_hold(self, attitude, q_pa, previous_attitude, previous_q_pa) -> np.ndarray:
        """Whether each sample starts a new hold, given the sample before it (vectorised)."""
        attitude, previous_attitude = (
            np.asarray(attitude, float),
            np.asarray(previous_attitude, float),
        )
        q, previous_q = np.asarray(q_pa, float), np.asarray(previous_q_pa, float)
        moved = np.any(np.abs(attitude - previous_attitude) > self.attitude_tolerance_rad, axis=-1)
        q_moved = np.abs(q - previous_q) > np.maximum(
            self.q_tolerance_pa, self.q_tolerance_fraction * np.abs(previous_q)
        )
        return moved | q_moved | (self.wind_off(q) != self.wind_off(previous_q))

    def point_range(self, start: int, stop: int) -> tuple[int, int] | None:
        """The samples [a, b) of hold [start, stop) that make its point, or None (no point)."""
        a = start + int(self.settle_samples)
        b = a + int(self.point_samples) if self.point_samples > 0 else stop
        if b > stop or b - a < max(int(self.min_samples), 1):
            return None
        return a, b


def find_holds(support_attitude, q_pa, settings: HoldSettings) -> np.ndarray:
    """(H, 2) [start, stop) sample indices of each hold, in time order."""
    attitude = np.asarray(support_attitude, float)
    q = np.asarray(q_pa, float)
    if len(q) == 0:
        return np.zeros((0, 2), dtype=int)
    starts = np.concatenate(
        [[0], 1 + np.flatnonzero(settings.new_hold(attitude[1:], q[1:], attitude[:-1], q[:-1]))]
    )
    stops = np.concatenate([starts[1:], [len(q)]])
    return np.column_stack([starts, stops])


@dataclass
class HoldTracker:
    """The live form of `find_holds`: feed samples one by one.

    `add` returns (new_hold, ready): new_hold when this sample starts a hold (the previous one is
    over), ready when the current hold has just reached `point_samples` settled samples
    (`point_samples` > 0: its point can be taken now, it gets no more samples).
    """

    settings: HoldSettings
    previous_attitude: np.ndarray | None = None
    previous_q: float | None = None
    count: int = 0  # samples in the current hold

    def add(self, attitude, q_pa: float) -> tuple[bool, bool]:
        attitude = np.asarray(attitude, float)
        new = self.previous_attitude is None or bool(
            self.settings.new_hold(attitude, q_pa, self.previous_attitude, self.previous_q)
        )
        self.count = 1 if new else self.count + 1
        self.previous_attitude, self.previous_q = attitude, float(q_pa)
        n = int(self.settings.point_samples)
        ready = n > 0 and self.count == int(self.settings.settle_samples) + n
        return new, ready
