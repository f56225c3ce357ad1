"""Did the balance change between two calibrations? (interfaces.md, "Check loads, and comparing
two calibrations").

Both calibrations read the same bridge outputs: those calibration A reads as a set of loads
(its own calibration points, or a LOADS.csv). Per component the difference of the readings
(B − A) in % FS, against the combined standard uncertainty √(u_A² + u_B²) of the difference, u as
/balance/wrench_uncertainty defines it (model/uncertainty.py). A component has changed when the
RMS difference exceeds twice the RMS combined uncertainty.

The primary sensitivity of bridge i, S_i, is its output per unit of its own load at zero load:
the diagonal of (∂L/∂V)⁻¹ at V = 0, the model's Jacobian inverted. (S_B/S_A − 1)·100 says in
per cent how much a bridge's gain moved (a 1 % weaker bridge: −1 %).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model.calibration import Calibration
from .check_loads import calibration_body, CheckInputError, usable_model

CHANGED_FACTOR = 2.0  # changed: RMS difference > this x RMS combined uncertainty


@dataclass(frozen=True)
class Comparison:
    components: tuple[str, ...]
    capacity: np.ndarray  # (n,)
    loads: np.ndarray  # (P, n) the loads A reads at the compared outputs, N / N·m
    difference: np.ndarray  # (P, n) B − A, N / N·m
    combined_u: np.ndarray  # (P, n) √(u_A² + u_B²), N / N·m
    sensitivity_change_pct: dict[str, float | None]
    points_from: str  # where the loads came from
    models: tuple[str, str]
    warnings: tuple[str, ...] = field(default_factory=tuple)

    @property
    def difference_pct_fs(self) -> np.ndarray:
        return self.difference / self.capacity * 100.0

    @property
    def combined_u_pct_fs(self) -> np.ndarray:
        return self.combined_u / self.capacity * 100.0

    @property
    def changed(self) -> list[str]:
        rms_d, rms_u = self._rms()
        return [c for c, d, u in zip(self.components, rms_d, rms_u) if not d <= CHANGED_FACTOR * u]

    def _rms(self) -> tuple[np.ndarray, np.ndarray]:
        return (
            np.sqrt(np.nanmean(self.difference_pct_fs**2, axis=0)),
            np.sqrt(np.nanmean(self.combined_u_pct_fs**2, axis=0)),
        )

    def summary(self) -> dict:
        """compare.json (interfaces.md), then where the points came from and the models."""
        rms_d, rms_u = self._rms()
        changed = self.changed
        components = {}
        for j, c in enumerate(self.components):
            column = self.difference_pct_fs[:, j]
            finite = column[np.isfinite(column)]
            worst = finite[np.argmax(np.abs(finite))] if finite.size else np.nan
            components[c] = {
                'rms_difference_pct_fs': _number(rms_d[j]),
                'worst_difference_pct_fs': _number(worst),
                'combined_u_pct_fs': _number(rms_u[j]),
                'changed': c in changed,
            }
        return {
            'components': components,
            'sensitivity_change_pct': dict(self.sensitivity_change_pct),
            'changed': changed,
            # beyond the promised keys
            'points': int(len(self.loads)),
            'points_from': self.points_from,
            'models': {'A': self.models[0], 'B': self.models[1]},
            'warnings': list(self.warnings),
        }


def _number(value, digits: int = 5):
    return round(float(value), digits) if value is not None and np.isfinite(value) else None


def refuse_unlike(a: Calibration, b: Calibration, name_a: str, name_b: str) -> None:
    """CheckInputError in one line unless both calibrations are of the same balance (name and,
    when both record one, serial), components, bridge outputs and units.
    """
    serial_a = (a.extra or {}).get('serial')
    serial_b = (b.extra or {}).get('serial')
    for what, left, right in (
        ('balance', a.balance.lower(), b.balance.lower()),
        ('serial', serial_a if serial_b else None, serial_b if serial_a else None),
        ('components', ','.join(a.components), ','.join(b.components)),
        ('bridge outputs', ','.join(a.bridge_outputs), ','.join(b.bridge_outputs)),
        ('output unit', a.output_unit, b.output_unit),
        (
            'load units',
            ','.join((a.extra or {}).get('load_units_si', ())),
            ','.join((b.extra or {}).get('load_units_si', ())),
        ),
    ):
        if left != right:
            raise CheckInputError(
                f'{name_a} and {name_b} differ in {what} ({left} / {right}): they are not two '
                'calibrations of one balance'
            )


def own_points(calibration: Calibration) -> tuple[np.ndarray, str]:
    """(P, n) total loads of the calibration's own points: its balance config's schedule with the
    calibration body's tare per orientation; without a schedule, one-component sweeps over the
    recorded support. CheckInputError when it has neither (give LOADS.csv).
    """
    from ..config import load_balance_config
    from ..coverage.run import recorded_support
    from ..errors import ConfigError
    from ..tare.calibration_body import tare_loads

    try:
        config = load_balance_config(calibration.balance)
    except ConfigError:
        config = None
    if (
        config is not None
        and config.schedule is not None
        and tuple(config.components) == tuple(calibration.components)
    ):
        schedule = config.schedule
        gravity = np.array([config.gravity(i) for i in schedule.orientation])
        body = calibration_body(calibration, calibration.balance)
        loaded = ~schedule.is_zero_point
        total = np.asarray(schedule.loads, dtype=float) + tare_loads(body, gravity)
        return total[loaded], (
            f"the {int(loaded.sum())} loaded points of {config.name}'s schedule (Appendix "
            "sheet) with the calibration body's tare"
        )
    support = recorded_support(calibration)
    if support is None:
        raise CheckInputError(
            f'calibration of {calibration.balance} records neither a schedule nor a support to '
            'compare on: give --loads LOADS.csv'
        )
    levels = np.linspace(0.0, 1.0, 11)
    rows = []
    for j in range(len(calibration.components)):
        block = np.zeros((len(levels) * 2, len(calibration.components)))
        block[: len(levels), j] = levels * support.load_max[j]
        block[len(levels) :, j] = levels * support.load_min[j]
        rows.append(block)
    sweeps = np.unique(np.vstack(rows), axis=0)
    return sweeps, 'one-component sweeps over the recorded support (calibrated range)'


def primary_sensitivities(model) -> np.ndarray | None:
    """(n,) S_i = ((∂L/∂V)⁻¹)_ii at zero output, mV per N or N·m; None when the model has not as
    many components as bridges or its Jacobian is singular there.
    """
    if len(model.components) != len(model.inputs):
        return None
    wind_on = model.without_constant()
    try:
        jacobian = np.atleast_3d(wind_on.jacobian(np.zeros((1, len(model.inputs)))))[0]
        return np.diag(np.linalg.inv(jacobian))
    except (np.linalg.LinAlgError, ValueError, KeyError, ArithmeticError):
        return None


def compare_calibrations(
    a: Calibration, b: Calibration, loads=None, *, points_from: str = '', model: str = 'adopted'
) -> Comparison:
    """Compare two calibrations of one balance at `loads` (P, n) N / N·m, or at A's own points.

    Raises CheckInputError (no points), UncertaintyUnavailable (a calibration without
    coefficient covariance) or InverseDidNotConverge.
    """
    from ..coverage.run import LOADS_BEYOND_CAPACITY, outputs_for_run_loads, run_coverage

    warnings: list[str] = []
    if loads is None:
        loads, points_from = own_points(a)
    loads = np.atleast_2d(np.asarray(loads, dtype=float))
    capacity = np.asarray(a.capacity, dtype=float)
    reachable = np.all(np.abs(loads) <= LOADS_BEYOND_CAPACITY * capacity, axis=1)
    if not reachable.all():
        warnings.append(
            f'{int((~reachable).sum())} loads beyond {LOADS_BEYOND_CAPACITY:g}x the rated load '
            'left out'
        )
        loads = loads[reachable]
    if not len(loads):
        raise CheckInputError('no loads to compare the calibrations at')
    name_a, said_a = usable_model(a, model)
    name_b, said_b = usable_model(b, model)
    warnings += [f'A: {w}' for w in said_a] + [f'B: {w}' for w in said_b]
    outputs = outputs_for_run_loads(a.model(name_a), loads)
    read_a = run_coverage(a, outputs_mv=outputs, model=name_a)
    read_b = run_coverage(b, outputs_mv=outputs, model=name_b)
    s_a = primary_sensitivities(a.model(name_a))
    s_b = primary_sensitivities(b.model(name_b))
    if s_a is None or s_b is None:
        sensitivity = dict.fromkeys(a.bridge_outputs)
    else:
        sensitivity = {
            v: _number((sb / sa - 1.0) * 100.0, 4) for v, sa, sb in zip(a.bridge_outputs, s_a, s_b)
        }
    return Comparison(
        tuple(a.components),
        capacity,
        read_a.loads,
        read_b.loads - read_a.loads,
        np.sqrt(read_a.uncertainty**2 + read_b.uncertainty**2),
        sensitivity,
        points_from,
        (name_a, name_b),
        tuple(warnings),
    )
