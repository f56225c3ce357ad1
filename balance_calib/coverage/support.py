"""The support of a calibration schedule: where its points put loads, alone and together.

A load of a run is outside the support for component k when

1. its k load lies outside the range the schedule's points covered (total loads on the balance,
   applied + calibration-body weight), widened by RANGE_TOLERANCE_FS of full scale; or
2. the load as a whole combines the components beyond anything the schedule applied together:
   its leverage in the calibration's base model, h = x (XᵀX)⁻¹ xᵀ (x the model's design row at
   the load's bridge outputs, XᵀX over the calibration points), exceeds the largest leverage of
   any calibration point by more than LEVERAGE_TOLERANCE (the points' own noise moves it).

A load of case 2 lies outside the hull of the schedule in the space of the model's terms
("hidden extrapolation" of Montgomery, Peck & Vining's regression text): every component is then
extrapolated, even when each load alone and each pair was calibrated. That is what a tunnel load
(six components at once) does to a schedule of one or two components at a time.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from ..model.leverage import leverage_of_rows

RANGE_TOLERANCE_FS = 0.02  # 2 % FS beyond the calibrated range still counts as inside
LEVERAGE_TOLERANCE = 1.1  # and 10 % beyond the largest leverage of a calibration point


@dataclass(frozen=True)
class ScheduleSupport:
    """Range per component and the largest leverage of the calibration points."""

    components: tuple[str, ...]
    capacity: np.ndarray  # (n,) N / N·m
    load_min: np.ndarray  # (n,) N / N·m, total loads
    load_max: np.ndarray  # (n,)
    leverage_max: float  # largest x (XᵀX)⁻¹ xᵀ of a calibration point
    model: str  # the model whose terms the leverage is of

    def to_dict(self) -> dict[str, Any]:
        """Plain data for calibration.yaml (`extra.support`)."""
        return {
            'definition': 'outside for a component: its load beyond the calibrated range '
            "(+2 % FS), or the load's leverage in the base model beyond 1.1 x the "
            'largest of a calibration point',
            'load_min': {c: float(v) for c, v in zip(self.components, self.load_min)},
            'load_max': {c: float(v) for c, v in zip(self.components, self.load_max)},
            'leverage_max': float(self.leverage_max),
            'model': self.model,
        }

    @classmethod
    def from_dict(
        cls, data: Mapping[str, Any], components: Sequence[str], capacity
    ) -> 'ScheduleSupport':
        """Inverse of to_dict; KeyError/ValueError/TypeError on a malformed mapping."""
        names = tuple(components)
        return cls(
            names,
            np.asarray(capacity, float),
            np.array([float(data['load_min'][c]) for c in names]),
            np.array([float(data['load_max'][c]) for c in names]),
            float(data['leverage_max']),
            str(data['model']),
        )


def support_of_points(
    total_loads, design_rows, covariance_unscaled, capacity, components: Sequence[str], model: str
) -> ScheduleSupport:
    """The support of calibration points with these total loads (P, n), N / N·m, and design
    rows (P, p) of `model`, whose fit has this unscaled covariance (p, p).
    """
    loads = np.atleast_2d(np.asarray(total_loads, dtype=float))
    return ScheduleSupport(
        tuple(components),
        np.asarray(capacity, float),
        loads.min(axis=0),
        loads.max(axis=0),
        float(np.max(leverage_of_rows(design_rows, covariance_unscaled))),
        str(model),
    )


def outside_support(support: ScheduleSupport, loads, load_leverage) -> np.ndarray:
    """(N, n) True where a load (N, n), of leverage (N,) in the support's model, is outside the
    support for that component (module doc). Loads or leverages that are not finite are
    outside.
    """
    loads = np.atleast_2d(np.asarray(loads, dtype=float))
    margin = RANGE_TOLERANCE_FS * support.capacity
    limit = LEVERAGE_TOLERANCE * support.leverage_max
    with np.errstate(invalid='ignore'):
        outside = ~((loads >= support.load_min - margin) & (loads <= support.load_max + margin))
        combined = ~(np.asarray(load_leverage, dtype=float) <= limit)
    return outside | combined[:, None]
