"""Check loads before a tunnel entry (interfaces.md, "Check loads, and comparing two
calibrations"): known loads read through a calibration, each point-component against k·u.

Readings. A table's points are read through the calibration (natural zeros removed as the table
gives them); each load series gets the tare estimated from its own points with the calibration
held fixed (fit/series_tares.py), as a validation series of another setup does. A bag is cut into
load points as refit cuts it (refit/load_points.py); its zero points (§5(4)) are subtracted, and
the calibration body is the calibration's own (calibration.yaml `extra.calibration_body`): its
tare loads for each point's gravity direction, its tare outputs by the model's inverse (as
reduction.retare_with_model). Zero points are not check points.

Uncertainty of a reading, k = 1: the one /balance/wrench_uncertainty publishes (model/
uncertainty.py: σ_k √(1 + leverage)), the tare's share (a table series' tare standard error; a
bag's interpolated zero, from its zero points' own scatter) and the standard error of the check
point's own mean (a bag: its samples' scatter, refit/load_points.py; a point of one sample: the
run's repeatability from consecutive zero points), in quadrature.

Support: where the point lies outside the calibration's recorded support (coverage/support.py,
total loads), or without one beyond the rated load, the reading is an extrapolation: said per
point, never silently passed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ..model.calibration import Calibration

VERDICTS = ('pass', 'marginal', 'fail')
MARGINAL_FRACTION = 0.05  # failures at most this share of the point-components ...
MARGINAL_RATIO = 1.5  # ... and each within this many k·u: marginal, not fail


class CheckInputError(ValueError):
    """Check loads that cannot be read against this calibration; the message names the file."""


@dataclass(frozen=True)
class CheckReadings:
    """Check points read through a calibration, the calibration's components, SI."""

    source: str
    point: tuple[str, ...]  # (P,) point names: a table's point ids, a bag's P-0012
    components: tuple[str, ...]
    capacity: np.ndarray  # (n,) N / N·m
    applied: np.ndarray  # (P, n) the known check loads
    reading: np.ndarray  # (P, n) what the calibration reads for them
    uncertainty: np.ndarray  # (P, n) k = 1 (see the module's docstring)
    outside: np.ndarray  # (P, n) bool: outside the calibrated support (or beyond rated)
    support: str  # what `outside` judged against
    model_name: str
    warnings: tuple[str, ...] = field(default_factory=tuple)

    @property
    def error(self) -> np.ndarray:
        return self.reading - self.applied


@dataclass(frozen=True)
class CheckResult:
    readings: CheckReadings
    k: float
    ratio: np.ndarray  # (P, n) |error| / (k·u); NaN where u or the error is not finite
    failed: np.ndarray  # (P, n) bool: ratio > 1 or not finite
    verdict: str

    def summary(self) -> dict:
        """check.json (interfaces.md), then what lies outside the support and the warnings."""
        r = self.readings
        error = r.error / r.capacity * 100.0
        limit = self.k * r.uncertainty / r.capacity * 100.0
        components = {}
        for j, c in enumerate(r.components):
            column = error[:, j]
            finite = column[np.isfinite(column)]
            worst = finite[np.argmax(np.abs(finite))] if finite.size else np.nan
            components[c] = {
                'rms_error_pct_fs': _number(np.sqrt(np.mean(finite**2)) if finite.size else None),
                'worst_error_pct_fs': _number(worst),
                'failed': int(self.failed[:, j].sum()),
            }
        failed = [
            {
                'point': r.point[i],
                'component': r.components[j],
                'error_pct_fs': _number(error[i, j]),
                'limit_pct_fs': _number(limit[i, j]),
                'ratio': _number(self.ratio[i, j], 3),
                'outside_support': bool(r.outside[i, j]),
            }
            for i, j in zip(*np.nonzero(self.failed))
        ]
        finite_ratio = self.ratio[np.isfinite(self.ratio)]
        return {
            'points': len(r.point),
            'k': self.k if self.k != int(self.k) else int(self.k),
            'verdict': self.verdict,
            'worst_ratio': _number(finite_ratio.max() if finite_ratio.size else None, 4),
            'components': components,
            'failed': failed,
            # beyond the promised keys
            'point_components': int(self.failed.size),
            'outside_support': [
                {
                    'point': r.point[i],
                    'components': [c for c, o in zip(r.components, r.outside[i]) if o],
                }
                for i in np.flatnonzero(r.outside.any(axis=1))
            ],
            'support': r.support,
            'model': r.model_name,
            'source': r.source,
            'warnings': list(r.warnings) + self.range_warnings(),
        }

    def range_warnings(self) -> list[str]:
        outside = self.readings.outside
        if not outside.any():
            return []
        points = int(outside.any(axis=1).sum())
        passed = int((outside & ~self.failed).sum())
        return [
            f'{points} of {len(outside)} check points lie outside the calibrated range '
            f'({self.readings.support}): their {int(outside.sum())} point-components are read '
            f'by extrapolation ({passed} of them within k·u, which says nothing about the '
            'calibration there)'
        ]


def _number(value, digits: int = 5):
    if value is None or not np.isfinite(value):
        return None
    return round(float(value), digits)


def judge(readings: CheckReadings, k: float = 2.0) -> CheckResult:
    """Pass/fail of every point-component against k·u, and the verdict (interfaces.md):
    pass when all pass; marginal when the failures are at most 5 % of the point-components and
    each within 1.5·k·u; fail otherwise. A reading or u that is not finite fails.
    """
    if not (np.isfinite(k) and k > 0):
        raise ValueError(f'--k must be a positive number, not {k}')
    with np.errstate(invalid='ignore', divide='ignore'):
        ratio = np.abs(readings.error) / (k * readings.uncertainty)
    ratio = np.where(np.isfinite(ratio), ratio, np.nan)
    failed = ~(ratio <= 1.0)
    if not failed.any():
        verdict = 'pass'
    elif failed.sum() <= MARGINAL_FRACTION * failed.size and bool(
        np.all(ratio[failed] <= MARGINAL_RATIO)
    ):
        verdict = 'marginal'
    else:
        verdict = 'fail'
    return CheckResult(readings, float(k), ratio, failed, verdict)


# --- readings -----------------------------------------------------------------------------------
def usable_model(calibration: Calibration, model: str) -> tuple[str, list[str]]:
    """The model to read with and a warning: one that needs inputs besides the bridge outputs
    (temperature, load history) gives way to the calibration's base model, as the live
    calibrator falls back when such an input is missing.
    """
    name = calibration.adopted if model in ('adopted', '') else model
    chosen = calibration.model(name)
    if not chosen.extra_variables:
        return name, []
    base = calibration.base_model
    if base not in calibration.models or calibration.models[base].extra_variables:
        raise CheckInputError(
            f'model {name} needs {", ".join(chosen.extra_variables)} and the calibration has '
            'no base model without them'
        )
    return base, [
        f'model {name} needs {", ".join(chosen.extra_variables)}, which check loads do not '
        f'carry: read with the base model {base}'
    ]


def table_readings(calibration: Calibration, table, model: str = 'adopted') -> CheckReadings:
    """Check points of a BALFIT-style table (tables/balfit_reader.CalibrationTable)."""
    from ..coverage.run import run_coverage
    from ..fit.series_tares import tares_with_model_fixed

    if tuple(table.load_symbols) != tuple(calibration.components) or tuple(
        table.bridge_symbols
    ) != tuple(calibration.bridge_outputs):
        raise CheckInputError(
            f'{table.source}: loads {",".join(table.load_symbols)} and outputs '
            f'{",".join(table.bridge_symbols)} are not the calibration\'s '
            f'{",".join(calibration.components)} and {",".join(calibration.bridge_outputs)}'
        )
    unit = table.output_internal_unit
    if unit != calibration.output_unit:
        raise CheckInputError(
            f'{table.source}: bridge outputs in {unit}; the calibration reads '
            f'{calibration.output_unit}'
        )
    series = np.asarray(table.series, dtype=int)
    labels, counts = np.unique(series, return_counts=True)
    lonely = labels[counts < 2]
    if lonely.size:
        raise CheckInputError(
            f'{table.source}: load series {", ".join(map(str, lonely[:5]))} has a single point: '
            'its tare, estimated with the calibration held fixed, would absorb its whole error; '
            'give each series at least two points (e.g. its zero-load reading)'
        )
    name, warnings = usable_model(calibration, model)
    coverage = run_coverage(calibration, outputs_mv=table.bridge_outputs, model=name)
    applied = table.applied_loads_si
    tare_rows, _, tare_sigma = tares_with_model_fixed(coverage.loads, applied, series)
    sigma_rows = np.array([tare_sigma[int(s)] for s in series])
    uncertainty = np.sqrt(coverage.uncertainty**2 + sigma_rows**2)
    outside, support = _outside(coverage, applied + tare_rows, calibration)
    return CheckReadings(
        table.source,
        tuple(table.point_id),
        tuple(calibration.components),
        np.asarray(calibration.capacity, dtype=float),
        applied,
        coverage.loads - tare_rows,
        uncertainty,
        outside,
        support,
        name,
        tuple(warnings),
    )


def calibration_body(calibration: Calibration, source: str):
    """The calibration body calibration.yaml records (refit writes it), else the balance
    config's; CheckInputError when neither names one.
    """
    from ..config import CalibrationBody, load_balance_config
    from ..errors import ConfigError

    recorded = (calibration.extra or {}).get('calibration_body')
    if isinstance(recorded, dict) and 'weight_n' in recorded:
        cg = [float(x) for x in recorded.get('cg_m', (0.0, 0.0, 0.0))]
        return CalibrationBody(float(recorded['weight_n']), (cg[0], cg[1], cg[2]))
    try:
        return load_balance_config(calibration.balance).calibration_body
    except ConfigError:
        raise CheckInputError(
            f'{source}: the calibration records no calibration body (extra.calibration_body) '
            f'and no balance config {calibration.balance!r} is found: a bag cannot be tared'
        ) from None


def bag_readings(
    calibration: Calibration,
    points,
    point_variance_mv2,
    source: str,
    model: str = 'adopted',
) -> CheckReadings:
    """Check points of a campaign bag cut into load points (refit/load_points.cut_load_points):
    zero points subtracted, the calibration's body as tare; zero points are not check points.
    point_variance_mv2 (P, n_bridges): variance of each point's mean output, mV² (the cut's
    CutSummary.point_variance_mv2), None or NaN where unknown.
    """
    from ..coverage.run import outputs_for_run_loads, run_coverage
    from ..tare.calibration_body import tare_loads
    from ..units import COMPONENTS
    from ..zero_points import subtract_zero_points

    if tuple(calibration.components) != COMPONENTS:
        raise CheckInputError(
            f'{source}: a bag carries six components; the calibration has '
            f'{", ".join(calibration.components)}: give the check loads as a table'
        )
    zero = subtract_zero_points(
        points.times_s, points.outputs_mv, points.is_zero_point, points.orientation, points.label
    )
    loaded = ~points.is_zero_point
    if not loaded.any():
        raise CheckInputError(f'{source}: only zero points, no check loads')
    name, warnings = usable_model(calibration, model)
    body_loads = tare_loads(calibration_body(calibration, source), points.gravity)
    wind_on = calibration.model(name).without_constant()
    body_outputs = outputs_for_run_loads(calibration.model(name), body_loads)  # either form
    outputs = zero.zeroed_outputs_mv + body_outputs
    coverage = run_coverage(calibration, outputs_mv=outputs[loaded], model=name)
    variance_mv2, note = _point_variance(points, zero, point_variance_mv2)
    warnings += note
    jacobian = wind_on.jacobian(outputs[loaded])
    own = np.einsum('pki,pi->pk', jacobian**2, variance_mv2[loaded])
    uncertainty = np.sqrt(coverage.uncertainty**2 + own)
    applied = np.asarray(points.applied_loads, dtype=float)[loaded]
    outside, support = _outside(coverage, applied + body_loads[loaded], calibration)
    return CheckReadings(
        source,
        tuple(f'P-{int(label):04d}' for label in np.asarray(points.label)[loaded]),
        tuple(calibration.components),
        np.asarray(calibration.capacity, dtype=float),
        applied,
        coverage.loads - body_loads[loaded],
        uncertainty,
        outside,
        support,
        name,
        tuple(warnings),
    )


def _point_variance(points, zero, point_variance_mv2) -> tuple[np.ndarray, list[str]]:
    """(P, n) variance (mV²) of each point's zeroed mean output: its own mean's and, interpolated
    in time, its bracketing zero points' (the tare's share). A point whose own scatter is unknown
    (fewer than two samples) takes the run's repeatability instead, from consecutive zero points
    in one orientation (half the mean square of their differences: diagnosis/lack_of_fit.py); with
    no such pair it counts as 0. Either is said.
    """
    from ..diagnosis.lack_of_fit import zero_point_pairs

    variance = (
        np.array(point_variance_mv2, dtype=float)
        if point_variance_mv2 is not None
        else np.full(np.shape(points.outputs_mv), np.nan)
    )
    unknown = ~np.isfinite(variance).all(axis=1)
    note = []
    if unknown.any():
        pairs = zero_point_pairs(points)
        if len(pairs):
            variance[unknown] = np.mean(np.square(pairs), axis=0) / 2.0
            note.append(
                f'{int(unknown.sum())} points have fewer than two samples: their own scatter is '
                f'taken from {len(pairs)} pairs of consecutive zero points'
            )
        else:
            variance[unknown] = 0.0
            note.append(
                f'{int(unknown.sum())} points have fewer than two samples and no zero point '
                'repeats: their own scatter is unknown and left out of u'
            )
    times = np.asarray(points.times_s, dtype=float)
    before = np.where(zero.before >= 0, zero.before, zero.after)
    after = np.where(zero.after >= 0, zero.after, zero.before)
    span = times[after] - times[before]
    weight = np.where(span > 0, (times - times[before]) / np.where(span > 0, span, 1.0), 0.0)
    share = np.where(
        (before == after)[:, None],
        variance[before],
        ((1 - weight) ** 2)[:, None] * variance[before] + (weight**2)[:, None] * variance[after],
    )
    total = variance + np.where(np.asarray(points.is_zero_point)[:, None], 0.0, share)
    return total, note


def _outside(coverage, total_loads: np.ndarray, calibration: Calibration):
    """(P, n) outside the calibrated support, and what it was judged against: the recorded
    support (coverage/support.py) at the total loads, else the rated loads.
    """
    if coverage.outside is not None:
        return np.asarray(coverage.outside, dtype=bool), (
            "the calibration's recorded support: calibrated range + 2 % FS, leverage within "
            '1.1x the largest of a calibration point'
        )
    capacity = np.asarray(calibration.capacity, dtype=float)
    with np.errstate(invalid='ignore'):
        beyond = ~(np.abs(total_loads) <= capacity)
    return beyond, 'the rated loads (the calibration records no support)'


def read_check_inputs(
    calibration: Calibration, paths: Sequence[str], model: str = 'adopted'
) -> CheckReadings:
    """One table (.csv) or campaign bags, read as check points. CheckInputError, TableError,
    BagError and LoadPointError name the file.
    """
    from pathlib import Path

    if len(paths) == 1 and Path(paths[0]).suffix.lower() == '.csv':
        from ..tables.balfit_reader import read_tables

        return table_readings(calibration, read_tables([paths[0]]), model)
    if any(Path(p).suffix.lower() == '.csv' for p in paths):
        raise CheckInputError(
            f'{", ".join(paths)}: give one table (.csv) or campaign bags, not both or several '
            'tables'
        )
    from ..bags.reader import read_bags
    from ..refit.load_points import cut_load_points

    source = ', '.join(str(p) for p in paths)
    bag = read_bags([Path(p) for p in paths], required=('raw', 'applied_load', 'gravity'))
    points, cut = cut_load_points(bag, None, source=source)
    return bag_readings(calibration, points, cut.point_variance_mv2, source, model)
