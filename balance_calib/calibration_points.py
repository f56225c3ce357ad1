"""The calibration points a calibration is fitted to, whatever they were read from.

One value for what a bag or a table carries: applied loads, bridge outputs,
load series, gravity and times where known, the extra channels with their units and symbols, the
load direction and the order of each point within its series. The table reader's side is
`tables/table_points.points_from_table`, the bag reader's `refit/bag_points.read_bag_points`.
What only one kind of source has rides along: a bag's cut, zero points, tare and integrity
(`BagRecord`), a table's own rows (`table`); `calibrate/path.calibrate` dispatches on them.

The load direction and the returning series follow interfaces.md, "Effects found in table
calibrations": a point's direction is the sign of the change, since the previous point of its
series, of the magnitude of the load that changed most relative to its capacity (0 for a series'
first point and an unchanged point); point order is examined for zero drift only where a series
returns to loads it had earlier.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping, TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .config import BalanceConfig
    from .reduction import LoadPoints, Reduction

TEMPERATURE_UNITS = ('degC', 'degF', 'K')
# a load within this fraction of capacity of an earlier one of its series is that load again, and
# a change below it is none
SAME_LOAD_FRACTION = 1e-3


@dataclass(frozen=True)
class ExtraChannel:
    """A quantity logged with each point besides the bridge outputs (a temperature, a position).

    values: (N,) per point; a temperature in degC whatever the table wrote (its differences are
    kelvins), any other channel in its own unit.
    """

    symbol: str
    unit: str  # as written in the source
    values: np.ndarray

    @property
    def kind(self) -> str:
        """'temperature' for a temperature unit, else 'channel' (interfaces.md)."""
        return 'temperature' if self.unit in TEMPERATURE_UNITS else 'channel'

    @property
    def internal_unit(self) -> str:
        return 'degC' if self.kind == 'temperature' else self.unit

    @property
    def variable(self) -> str:
        """The model variable: d<SYMBOL>, the difference from the mean over the points."""
        return f'd{self.symbol}'

    @property
    def reference(self) -> float:
        """The mean over the calibration points, internal unit."""
        return float(np.mean(self.values))

    def constant_within_series(self, series: np.ndarray) -> bool:
        """True when the channel takes one value in each series (it varies only between them)."""
        scale = max(float(np.ptp(self.values)), 1e-300)
        return all(
            float(np.ptp(self.values[series == s])) <= 1e-9 * scale for s in np.unique(series)
        )


@dataclass(frozen=True)
class CutSummary:
    """What cutting a bag into load points kept and rejected (refit/load_points.py)."""

    points: int
    samples_used: int
    samples_rejected_outliers: int
    samples_rejected_nan: int  # NaN, infinite or beyond 1000x the rated output
    empty_points: int  # applied_load messages with no samples before the next one
    markers_out_of_order: int = 0  # applied_load stamps going back against receive order
    first_marker_out_of_order: int = -1  # its index (0-based, receive order), -1: none
    duplicate_marker_stamps: int = 0
    # raw samples in no point (between points, beyond a point's end)
    samples_outside_points: int = 0
    pauses_s: tuple[float, ...] = ()  # pauses between sessions that were shortened, seconds
    # (bridge, mV, samples, points) flat-topped
    clipped: tuple[tuple[str, float, int, int], ...] = ()
    # per point (same order as the LoadPoints returned): variance of the mean output per bridge,
    # mV² (successive differences, see the module's docstring; NaN with < 2 samples), samples
    # averaged
    point_labels: np.ndarray | None = field(default=None, compare=False, repr=False)  # (P,)
    # (P, n)
    point_variance_mv2: np.ndarray | None = field(default=None, compare=False, repr=False)
    point_samples: np.ndarray | None = field(default=None, compare=False, repr=False)  # (P,)


@dataclass(frozen=True)
class BagRecord:
    """What only a recorded (or simulated) campaign carries beside its corrected points."""

    load_points: LoadPoints  # the cut's points, before zero points and tare
    # zero points and calibration-body tare applied (§5(4), §6-7); None until reduced
    reduction: Reduction | None = None
    cut: CutSummary | None = None  # None: points straight from a simulation, no bag
    files: tuple[str, ...] = ()  # the bags read
    integrity: Mapping[str, Any] | None = None  # report.json's bag_integrity
    clock: str | None = None  # a simulator's clock: the report must not date the campaign by it
    started_s: float | None = None  # time.monotonic() when the refit began (wall_time_s)
    config: BalanceConfig | None = None  # the balance the points were reduced with

    @property
    def orientation(self) -> np.ndarray:
        """(N,) I_g of each load point (Fig. 3), in the order of the points."""
        return np.asarray(self.load_points.orientation)


@dataclass(frozen=True)
class CalibrationPoints:
    """Points of one calibration, SI inside: loads N / N·m, outputs as the fit takes them."""

    source: str
    point_id: tuple[str, ...]
    load_symbols: tuple[str, ...]
    output_symbols: tuple[str, ...]  # the bridge outputs
    capacity: np.ndarray  # (n_loads,) N / N·m
    applied_loads: np.ndarray  # (N, n_loads) N / N·m, without the series' tare
    outputs: np.ndarray  # (N, n_outputs) zero removed
    series: np.ndarray  # (N,) load series (one unknown tare each)
    channels: tuple[ExtraChannel, ...] = ()
    times_s: np.ndarray | None = None  # unknown for a table
    gravity: np.ndarray | None = None  # (N, 3) unknown for a table
    bag: BagRecord | None = field(default=None, compare=False, repr=False)
    # the tables.balfit_reader.CalibrationTable the points were read from
    table: Any = field(default=None, compare=False, repr=False)

    @property
    def points(self) -> int:
        return len(self.point_id)

    @property
    def order_in_series(self) -> np.ndarray:
        """(N,) index of each point within its series, in the order the points were taken."""
        order = np.zeros(self.points)
        for s in np.unique(self.series):
            mask = self.series == s
            order[mask] = np.arange(int(mask.sum()))
        return order

    @property
    def load_direction(self) -> np.ndarray:
        return load_direction(self.applied_loads, self.series, self.capacity)

    @property
    def signed_directions(self) -> np.ndarray:
        return signed_directions(self.applied_loads, self.series, self.capacity)

    @property
    def returning_series(self) -> np.ndarray:
        """(N,) True for the points of a series that returns to a load it had earlier."""
        return returning_series(self.applied_loads, self.series, self.capacity)


def load_direction(applied, series, capacity) -> np.ndarray:
    """(N,) +1 / -1: the magnitude of the load that changed most (relative to its capacity)
    since the previous point of the series grew / shrank; 0 for a first point or no change.
    """
    relative = np.asarray(applied, float) / np.asarray(capacity, float)
    series = np.asarray(series)
    direction = np.zeros(len(relative))
    last: dict[int, int] = {}
    for i, s in enumerate(series):  # points in the order taken: sequential by nature
        previous = last.get(int(s))
        if previous is not None:
            change = relative[i] - relative[previous]
            k = int(np.argmax(np.abs(change)))
            if abs(change[k]) > SAME_LOAD_FRACTION:
                grown = abs(relative[i, k]) - abs(relative[previous, k])
                direction[i] = np.sign(grown)
        last[int(s)] = i
    return direction


def signed_directions(applied, series, capacity) -> np.ndarray:
    """(N, n) per load: +1 where it last rose within its series, -1 where it last fell (kept
    through points where it does not move), 0 before its first move: the bag's load history
    (diagnosis/candidates.load_directions) within each series.
    """
    relative = np.asarray(applied, float) / np.asarray(capacity, float)
    series = np.asarray(series)
    direction = np.zeros_like(relative)
    for s in np.unique(series):
        index = np.flatnonzero(series == s)
        for previous, i in zip(index[:-1], index[1:]):
            step = relative[i] - relative[previous]
            moved = np.abs(step) > SAME_LOAD_FRACTION
            direction[i] = np.where(moved, np.sign(step), direction[previous])
    return direction


def returning_series(applied, series, capacity) -> np.ndarray:
    """(N,) True for every point of a series in which some point repeats an earlier load of it
    (not the one just before): there, point order can be told from the load.
    """
    relative = np.asarray(applied, float) / np.asarray(capacity, float)
    series = np.asarray(series)
    result = np.zeros(len(relative), dtype=bool)
    for s in np.unique(series):
        index = np.flatnonzero(series == s)
        rows = relative[index]
        distance = np.max(np.abs(rows[:, None, :] - rows[None, :, :]), axis=2)
        earlier = np.tril(distance <= SAME_LOAD_FRACTION, k=-2)  # not the point just before
        if earlier.any():
            result[index] = True
    return result


def temperature_in_degc(values, unit: str) -> np.ndarray:
    """A temperature in degC, K or degF as degC."""
    values = np.asarray(values, float)
    if unit == 'degF':
        return (values - 32.0) * 5.0 / 9.0
    if unit == 'K':
        return values - 273.15
    return values
