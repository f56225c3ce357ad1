"""What `bridge_publisher` publishes and when, as arrays: a timeline of events in simulated time.

Each event has a time (s from the start of the run), a kind (which topic) and up to six values.
The node walks the timeline in real time (times x `speed`) and only turns events into messages.
Events at the same time are published in kind order (gravity, applied load, raw sample, ...),
then in the order they were added, and share one header stamp.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import LoadSchedule
from .balance_sim import Campaign

GRAVITY, APPLIED_LOAD, RAW, TRUTH, TEMPERATURE, CHAMBER_PRESSURE, AMBIENT_PRESSURE = range(7)
KIND_NAMES = (
    'gravity',
    'applied_load',
    'raw',
    'truth',
    'temperature',
    'chamber_pressure',
    'ambient_pressure',
)


@dataclass(frozen=True)
class Timeline:
    times_s: np.ndarray  # (E,) non-decreasing
    kinds: np.ndarray  # (E,) one of the kinds above
    values: np.ndarray  # (E, 6) payload: 6 loads or outputs, 3 gravity components, 1 scalar

    def __len__(self) -> int:
        return len(self.times_s)

    @property
    def duration_s(self) -> float:
        return float(self.times_s[-1]) if len(self) else 0.0

    def due(self, start: int, time_s: float) -> int:
        """Index after the last event at or before time_s (events start..result are due)."""
        return max(start, int(np.searchsorted(self.times_s, time_s, side='right')))

    def count(self, kind: int) -> int:
        return int(np.count_nonzero(self.kinds == kind))


def events(times_s, kind: int, values) -> Timeline:
    times = np.asarray(times_s, dtype=float).ravel()
    payload = np.zeros((len(times), 6))
    values = np.asarray(values, dtype=float)
    if values.ndim <= 1:
        payload[:, 0] = np.broadcast_to(values, times.shape)
    else:
        payload[:, : values.shape[1]] = values
    return Timeline(times, np.full(len(times), kind), payload)


def merge(*parts: Timeline) -> Timeline:
    """One timeline ordered by time, then kind, then the order of `parts` and within them."""
    times = np.concatenate([p.times_s for p in parts])
    kinds = np.concatenate([p.kinds for p in parts])
    values = np.vstack([p.values for p in parts])
    order = np.lexsort((np.arange(len(times)), kinds, times))
    return Timeline(times[order], kinds[order], values[order])


def decimate(times_s, every: int) -> np.ndarray:
    """Indices of every `every`-th sample (at least one sample per call)."""
    return np.arange(0, len(times_s), max(int(every), 1))


def campaign_timeline(
    campaign: Campaign, transition_s: float, temperature_every: int = 1
) -> Timeline:
    """A calibration campaign as interfaces.md has it on the wire.

    Per point p: when the body is rotated (orientation differs from the previous point, or first
    point), /calibration/gravity at the start of the transition; an all-NaN applied_load there
    ("weights being changed", only when there is a transition); the applied_load when the point
    settles (start_s); the raw samples at their times; temperature every `temperature_every`
    samples.
    """
    n = len(campaign.point)
    changes = np.ones(n, dtype=bool)
    changes[1:] = campaign.orientation[1:] != campaign.orientation[:-1]
    begin = np.maximum(campaign.start_s - transition_s, 0.0)
    parts = [events(begin[changes], GRAVITY, campaign.gravity[changes])]
    if transition_s > 0:
        parts.append(events(begin, APPLIED_LOAD, np.full((n, 6), np.nan)))
    parts.append(events(campaign.start_s, APPLIED_LOAD, campaign.applied_loads))
    parts.append(events(campaign.times_s, RAW, campaign.raw_mv))
    keep = decimate(campaign.times_s, temperature_every)
    parts.append(events(campaign.times_s[keep], TEMPERATURE, campaign.temperature_c[keep]))
    return merge(*parts)


def wind_on_timeline(
    times_s, raw_mv, truth_tunnel, temperature_c: float, temperature_every: int = 1
) -> Timeline:
    """Raw samples with the true aerodynamic load (tunnel axes) at the same time, and
    temperature.
    """
    keep = decimate(times_s, temperature_every)
    return merge(
        events(times_s, RAW, raw_mv),
        events(times_s, TRUTH, truth_tunnel),
        events(np.asarray(times_s)[keep], TEMPERATURE, temperature_c),
    )


def thrust_stand_timeline(
    times_s, strain_mv, chamber_gauge_pa, ambient_pa, pressure_every: int = 1
) -> Timeline:
    """The thrust stand's one strain channel on /balance/raw force.x, and its two pressures."""
    times = np.asarray(times_s, dtype=float)
    raw = np.zeros((len(times), 6))
    raw[:, 0] = np.asarray(strain_mv, dtype=float)
    keep = decimate(times, pressure_every)
    return merge(
        events(times, RAW, raw),
        events(
            times[keep], CHAMBER_PRESSURE, np.broadcast_to(chamber_gauge_pa, times.shape)[keep]
        ),
        events(times[keep], AMBIENT_PRESSURE, np.broadcast_to(ambient_pa, times.shape)[keep]),
    )


def parse_point_ranges(spec: str) -> list[tuple[int, int]]:
    """'1-60, 100, 200-210' -> [(1, 60), (100, 100), (200, 210)] (point numbers as printed)."""
    ranges = []
    for part in (p.strip() for p in str(spec).split(',')):
        if not part:
            continue
        low, dash, high = part.partition('-')
        try:
            ranges.append((int(low), int(high)) if dash else (int(low), int(low)))
        except ValueError:
            raise ValueError(
                f'points {spec!r}: {part!r} is not a point number or a range like 1-60'
            ) from None
    return ranges


def select_points(schedule: LoadSchedule, spec: str) -> LoadSchedule:
    """The rows of a load schedule whose point numbers fall in `spec` ('' = all)."""
    ranges = parse_point_ranges(spec)
    if not ranges:
        return schedule
    mask = np.zeros(len(schedule), dtype=bool)
    for low, high in ranges:
        mask |= (schedule.point >= low) & (schedule.point <= high)
    if not mask.any():
        raise ValueError(
            f'points {spec!r}: no point of the schedule (points {schedule.point.min()}'
            f'-{schedule.point.max()}) is in that range'
        )
    return LoadSchedule(
        schedule.point[mask],
        schedule.orientation[mask],
        schedule.loads[mask],
        tuple(b for b, m in zip(schedule.byproduct, mask) if m),
    )
