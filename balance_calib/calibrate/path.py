"""The one calibration path: points in, a calibration (and its record on disk) out.

`calibrate(points, settings)` is what `balance-calib refit` and `~/refit` (from_bags.run_refit),
`balance-calib simulate` and `balance-calib fit` run. Whatever the points were read from, it
runs them in one order (calibration_stages.run_stages): screen gates -> model selection and fit
-> data gates -> diagnosis -> fit gates after the diagnosis -> calibration and report. What
the points carry chooses the stages: a bag's (or a simulation's) record the TM-663 fits of
refit/pipeline.BagStages (linear, quadratic and cubic §2-3, the residual diagnosis, the refit's
gates); a table's rows the series-tare fits of tables/calibrate.TableStages (both model forms,
method choice, validation, the loop closed on the table, the table's gates). Either way the
result is signed (record.py) and, when settings.out is given, written by the one record writer
(write_record.py).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Union

from ..calibration_points import CalibrationPoints
from ..calibration_settings import CalibrationSettings
from ..calibration_stages import run_stages
from .records import bag_record, table_record
from .write_record import Record, write_record

if TYPE_CHECKING:
    from ..refit.pipeline import CalibrationResult
    from ..tables.calibrate import TableCalibration

    Calibrated = Union[CalibrationResult, TableCalibration]


def calibrate(points: CalibrationPoints, settings: CalibrationSettings) -> Calibrated:
    """The calibration of `points` (a CalibrationResult for a bag or a simulation, a
    TableCalibration for a table), its record written into settings.out when given.

    Raises the side's own error (RefitError, TableCalibrationError) with one line when the points
    cannot be calibrated or an acceptance gate refuses them (unless settings.force).
    """
    result: Calibrated
    record: Record
    if points.bag is not None:
        from ..refit.pipeline import BagStages

        result = run_stages(BagStages(points, settings), settings.force, settings.progress)
        if settings.out is None:
            return result
        record = bag_record(result)
    elif points.table is not None:
        from ..tables.calibrate import TableStages

        table = run_stages(
            TableStages(points.table, settings.table, statistics=True),
            settings.force,
            settings.progress,
        )
        result = _signed(table, settings)
        if settings.out is None:
            return result
        record = table_record(result)
    else:
        raise ValueError(f'{points.source}: the points carry neither a bag nor a table')
    say = settings.progress or (lambda message: None)
    say(
        f'writing calibration.yaml, report.json, report.md'
        f'{" and plots" if settings.out.plots else ""} into {settings.out.out_dir}'
    )
    out = _write(record, settings, points.bag is not None)
    say(f'wrote {out}')
    return result


def _signed(result: TableCalibration, settings: CalibrationSettings) -> TableCalibration:
    """A table's calibration with its report's record signed (record.py)."""
    from ..record import signed_record

    if settings.serial:
        result.calibration.extra['serial'] = settings.serial  # type: ignore[index]
    result.report['record'] = signed_record(
        balance=result.report['balance'],
        serial=settings.serial,
        operator=settings.operator,
        inputs=list(settings.table.inputs),
        calibration=result.calibration,
    )
    return result


def _write(record: Record, settings: CalibrationSettings, bag: bool) -> Path:
    """write_record into settings.out; a refused out_dir is the bag side's RefitError there."""
    from ..output_dir import OutputError
    from ..refit.errors import RefitError

    assert settings.out is not None
    try:
        return write_record(record, settings.out, settings.progress)
    except OutputError as err:
        if bag:
            raise RefitError(str(err)) from None
        raise
