"""A run reduced held point by held point: the same steps offline (`balance-calib reduce`) and live
(node `aero_coefficients`).

Samples are (calibrated reading (6,) in the tunnel axes of §10.2, support attitude (3,), q∞) in
time order. Holds (held_points.py) with q∞ below the wind-off threshold are wind-off points; they
collect into the current wind-off sweep. At the first wind-on sample after a sweep the weight tare
is fitted from that sweep (`TareTracker`), and it serves every wind-on sample until the next sweep
is over. A sweep too short to fit keeps the previous tare (with a warning); without any tare the
wind-on samples cannot be reduced (their coefficients are NaN, and the reason is given).

The uncertainty of a point (k = 1) propagates the calibration's own σ (the scatter of a load point
about the fitted model, TM-663 eqs. (44)-(49), in N and N·m) of the point's loads and the
covariance of the weight-tare parameters through the whole reduction, by central differences.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .coefficients import reduce_loads, Reduced
from .held_points import find_holds, HoldSettings
from .model_file import ModelDescription
from .weight_tare import (
    declared_weight_contradiction,
    fit_weight_tare,
    WeightTare,
    WeightTareError,
)

FALLBACK_SIGMA_PCT_FS = 0.1  # weights of the tare fit when the calibration states no σ


def sigma_loads_tunnel(sigma_pct_fs, capacity, installation) -> np.ndarray:
    """(6,) σ of a point's load per component, N / N·m, in tunnel axes: % FS × capacity, moved by
    the installation's permutation (signs do not matter for a σ).
    """
    sigma_balance = np.asarray(sigma_pct_fs, float) / 100.0 * np.asarray(capacity, float)
    return np.abs(installation.to_tunnel(sigma_balance))


class TareTracker:
    """The weight tare in force: fitted from the latest wind-off sweep when the wind comes on."""

    def __init__(self, model: ModelDescription, sigma_loads):
        self.model = model
        self.sigma_loads = np.asarray(sigma_loads, float)
        self.tare: WeightTare | None = None
        self.warnings: list[str] = []
        self._readings: list[np.ndarray] = []
        self._attitudes: list[np.ndarray] = []
        self.fits = 0
        self._contradiction_said = False

    def add_wind_off(self, readings_mean, support_attitude_mean) -> None:
        self._readings.append(np.asarray(readings_mean, float))
        self._attitudes.append(np.asarray(support_attitude_mean, float))

    def current(self) -> WeightTare | None:
        """The tare for a wind-on sample now; a pending wind-off sweep is fitted (once) first."""
        if self._readings:
            readings, attitudes = np.array(self._readings), np.array(self._attitudes)
            self._readings, self._attitudes = [], []
            try:
                self.tare = fit_weight_tare(
                    readings,
                    attitudes,
                    sigma_loads=self.sigma_loads,
                    deflection=self.model.deflection,
                    weight_n=self.model.weight_n,
                    cg_m=self.model.centre_of_gravity_m,
                )
                self.fits += 1
                contradiction = declared_weight_contradiction(
                    readings,
                    attitudes,
                    sigma_loads=self.sigma_loads,
                    deflection=self.model.deflection,
                    weight_n=self.model.weight_n,
                    cg_m=self.model.centre_of_gravity_m,
                    model_name=f'model file {self.model.name}',
                )
                if contradiction and not self._contradiction_said:  # once a run
                    self._contradiction_said = True
                    self.warnings.append(contradiction)
            except WeightTareError as err:
                kept = 'the previous tare is kept' if self.tare is not None else 'no tare yet'
                self.warnings.append(
                    f'wind-off sweep of {len(readings)} held point(s) not used: {err}; {kept}'
                )
        return self.tare


@dataclass(frozen=True)
class HeldPoint:
    """One held attitude, averaged."""

    hold: int  # index of the hold in the run
    first_sample: int
    samples: int
    wind_off: bool
    support_attitude: np.ndarray  # (3,) mean support angles, rad
    q_pa: float
    readings: np.ndarray  # (6,) mean calibrated loads, tunnel axes
    reduced: Reduced | None = None  # wind-on points with a tare
    # sample σ of the coefficients
    scatter_body: np.ndarray = field(default_factory=lambda: np.full(6, np.nan))
    scatter_wind: np.ndarray = field(default_factory=lambda: np.full(6, np.nan))
    uncertainty_body: np.ndarray = field(default_factory=lambda: np.full(6, np.nan))  # k = 1
    uncertainty_wind: np.ndarray = field(default_factory=lambda: np.full(6, np.nan))
    tare: WeightTare | None = None


def _tare_with(parameters: np.ndarray, source: WeightTare) -> WeightTare:
    return WeightTare(
        float(parameters[0]),
        parameters[1:4] / parameters[0],
        parameters[4:],
        source.covariance,
        source.source,
        source.points,
    )


def point_uncertainty(
    readings, support, q_pa, model: ModelDescription, tare: WeightTare, sigma_loads
):
    """(body (6,), wind (6,)) standard uncertainty of a point's coefficients from the load σ (6,)
    and the tare covariance, by central differences through reduce_loads.
    """
    readings, support = np.asarray(readings, float), np.asarray(support, float)
    parameters = tare.parameters
    steps_loads = np.maximum(np.asarray(sigma_loads, float), 1e-9)
    steps_tare = np.maximum(
        np.sqrt(np.maximum(np.diag(tare.covariance), 0.0)), 1e-9 * (1 + np.abs(parameters))
    )
    columns = []
    for j in range(6):
        delta = np.zeros(6)
        delta[j] = steps_loads[j]
        plus, minus = (
            reduce_loads(readings + s * delta, support, q_pa, model, tare) for s in (1, -1)
        )
        columns.append(
            (np.concatenate([plus.body, plus.wind]) - np.concatenate([minus.body, minus.wind]))
            / (2 * steps_loads[j])
        )
    j_loads = np.column_stack(columns)
    columns = []
    for j in range(10):
        delta = np.zeros(10)
        delta[j] = steps_tare[j]
        plus, minus = (
            reduce_loads(readings, support, q_pa, model, _tare_with(parameters + s * delta, tare))
            for s in (1, -1)
        )
        columns.append(
            (np.concatenate([plus.body, plus.wind]) - np.concatenate([minus.body, minus.wind]))
            / (2 * steps_tare[j])
        )
    j_tare = np.column_stack(columns)
    variance = np.einsum(
        'ij,j,ij->i', j_loads, np.asarray(sigma_loads, float) ** 2, j_loads
    ) + np.einsum('ij,jk,ik->i', j_tare, tare.covariance, j_tare)
    u = np.sqrt(np.maximum(variance, 0.0))
    return u[:6], u[6:]


def held_point(
    hold: int,
    first: int,
    readings,
    support,
    q_pa,
    settings: HoldSettings,
    tracker: TareTracker,
) -> HeldPoint:
    """The point of one hold from its samples (n, 6), (n, 3), (n,). Wind-off points go to the
    tracker; wind-on points are reduced with the tracker's model and load σ.
    """
    model, sigma_loads = tracker.model, tracker.sigma_loads
    readings, support, q = (
        np.asarray(readings, float),
        np.asarray(support, float),
        np.asarray(q_pa, float),
    )
    mean_readings, mean_support, mean_q = (
        readings.mean(axis=0),
        support.mean(axis=0),
        float(q.mean()),
    )
    wind_off = bool(settings.wind_off(mean_q))
    if wind_off:
        tracker.add_wind_off(mean_readings, mean_support)
        return HeldPoint(hold, first, len(q), True, mean_support, mean_q, mean_readings)
    tare = tracker.current()
    if tare is None:
        return HeldPoint(hold, first, len(q), False, mean_support, mean_q, mean_readings)
    reduced = reduce_loads(mean_readings, mean_support, mean_q, model, tare)
    per_sample = reduce_loads(readings, support, q, model, tare)
    ddof = 1 if len(q) > 1 else 0
    u_body, u_wind = point_uncertainty(
        mean_readings, mean_support, mean_q, model, tare, sigma_loads
    )
    return HeldPoint(
        hold,
        first,
        len(q),
        False,
        mean_support,
        mean_q,
        mean_readings,
        reduced,
        per_sample.body.std(axis=0, ddof=ddof),
        per_sample.wind.std(axis=0, ddof=ddof),
        u_body,
        u_wind,
        tare,
    )


@dataclass(frozen=True)
class RunResult:
    points: tuple[HeldPoint, ...]  # every hold with a point, wind-off and wind-on, in time order
    holds: int  # holds found (with or without a point)
    warnings: tuple[str, ...]
    tares: tuple[WeightTare, ...]  # each tare fitted, in order

    @property
    def wind_on(self) -> tuple[HeldPoint, ...]:
        return tuple(p for p in self.points if not p.wind_off)


def reduce_run(
    readings, support_attitude, q_pa, model: ModelDescription, settings: HoldSettings, sigma_loads
) -> RunResult:
    """A whole run (S samples in time order) -> its held points, reduced."""
    readings, support, q = (np.asarray(a, float) for a in (readings, support_attitude, q_pa))
    holds = find_holds(support, q, settings)
    tracker = TareTracker(model, sigma_loads)
    points = []
    tares: list[WeightTare] = []
    for index, (start, stop) in enumerate(holds):
        chosen = settings.point_range(int(start), int(stop))
        if chosen is None:
            continue
        a, b = chosen
        point = held_point(index, a, readings[a:b], support[a:b], q[a:b], settings, tracker)
        if tracker.tare is not None and (not tares or tracker.tare is not tares[-1]):
            tares.append(tracker.tare)
        points.append(point)
    warnings = list(tracker.warnings)
    missing = sum(1 for p in points if not p.wind_off and p.reduced is None)
    if missing:
        warnings.append(
            f'{missing} wind-on held point(s) before any usable wind-off sweep were not reduced '
            f'(no weight tare and offsets)'
        )
    return RunResult(tuple(points), len(holds), tuple(warnings), tuple(tares))


OFFSET_WARNING_SHARE = 0.01  # of the rated load: beyond, not the balance at rest
TUNNEL_COMPONENTS = ('F_X', 'F_Y', 'F_Z', 'M_X', 'M_Y', 'M_Z')


def offset_warnings(
    tares: Sequence[WeightTare], capacity_tunnel, model_name: str, electrical_zero_given: bool
) -> list[str]:
    """One line when a wind-off sweep's fitted constant offsets exceed OFFSET_WARNING_SHARE of
    the rated load of a component.

    The offsets (weight_tare.py) take what the calibration leaves constant with nothing but the
    model's weight on the balance; beyond 1 % of the rated load that is the bridges' electrical
    zero carried through a calibration that has none (TM-663 §5(4): the zero belongs in output
    space), and with a non-linear calibration a load-space offset absorbs it only approximately.

    tares: the run's fitted tares; capacity_tunnel (6,): rated loads in tunnel axes, N and N·m.
    """
    if not tares:
        return []
    capacity = np.abs(np.asarray(capacity_tunnel, float))
    share = np.max(np.abs([t.offsets for t in tares]), axis=0) / capacity
    over = np.flatnonzero(share > OFFSET_WARNING_SHARE)
    if not len(over):
        return []
    worst = int(over[np.argmax(share[over])])
    largest = max((t.offsets[worst] for t in tares), key=abs)
    unit = 'N' if worst < 3 else 'N·m'
    others = ', '.join(
        f'{TUNNEL_COMPONENTS[k]} {100 * share[k]:.1f} %' for k in over if k != worst
    )
    also = f' (also {others})' if others else ''
    if electrical_zero_given:
        cause = "the electrical zero given is not the bridges' output at rest?"
    else:
        cause = (
            "the bridges' electrical zero is not removed: give --electrical-zero-mv "
            "(the calibrator's ~/zero)"
        )
    return [
        f'{model_name}: wind-off offsets of {TUNNEL_COMPONENTS[worst]} {largest:+.4g} {unit} '
        f'are {100 * share[worst]:.1f} % of its rated load {capacity[worst]:g} {unit}{also}, '
        f'beyond {100 * OFFSET_WARNING_SHARE:g} %: {cause}'
    ]
