"""Bags -> the calibration record: `run_refit`, behind `~/refit` (live/refit_process.py) and
`balance-calib refit`.

The balance config (its schedule replaced when the campaign ran another), the calibration in use
and the output directory are checked before any work; then the bags are read into corrected
points (refit/bag_points.py) and calibrated and written by the one path (path.calibrate).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
import time
from typing import Callable, cast, Sequence

from ..calibration_file import ConfigError
from ..calibration_settings import CalibrationSettings, Progress, RecordOptions
from ..config import BalanceConfig, load_balance_config
from ..model.calibration import Calibration
from ..refit.bag_points import BagReading, read_bag_points
from ..refit.errors import RefitError
from ..refit.pipeline import (
    CalibrationResult,
    check_model,
    check_out_dir,
    RefitResult,
    require_regular_file,
    summary_line,
)
from ..schedule_file import schedule_for
from .path import calibrate


@dataclass(frozen=True)
class RefitSettings:
    """run_refit's options (see run_refit)."""

    model: str = 'cubic'
    diagnose: bool = True
    estimate_body: bool = True
    progress: Progress | None = None
    plots: bool = True
    force: bool = False
    salvage: bool = False
    active_calibration: Calibration | str | Path | None = None
    overwrite: bool = True
    schedule: str | Path | None = None
    serial: str | None = None
    operator: str | None = None
    written: Callable[[RefitResult], None] | None = None


def run_refit(
    bag_paths: Sequence[str | Path],
    balance: str | Path,
    out_dir: str | Path,
    settings: RefitSettings | None = None,
) -> RefitResult:
    """Refit from bags and write calibration.yaml, report.json, report.md and plots into out_dir.

    settings (default RefitSettings()): every input error, integrity failure
    (bags/reader.py) and failed acceptance gate raises RefitError with one line naming the file;
    `out_dir` is checked before any work. force writes a calibration that failed a gate (marked in
    the report); salvage reads what is intact of a damaged bag and the report says what was lost;
    active_calibration (a Calibration or a file) is the calibration in use, which the new one's
    sensitivities must stay near. overwrite: an out_dir holding an earlier calibration record is
    replaced (the command line refuses it unless --overwrite; output_dir.py). schedule (a CSV in
    the layout of ../data/*_schedule.csv): the schedule the campaign ran when it is not the
    balance config's own; it replaces config.schedule, which the gates (the schedule gate among
    them) judge the campaign against. serial (default the balance config's) and operator: the
    signed record's (record.py). written(result): called once calibration.yaml, report.json and
    report.md are in out_dir, before the figures are drawn (~/refit replies then); run_refit
    returns after the figures.
    """
    given = settings or RefitSettings()
    say = given.progress or (lambda message: None)
    started = time.monotonic()
    paths = [Path(p) for p in bag_paths]
    if not paths:
        raise RefitError('no bags given (parameter calibration_bags is empty)')
    out_dir = Path(out_dir)
    check_out_dir(out_dir, given.overwrite)
    require_regular_file(balance, 'balance config')
    config = _balance_config(balance, given)
    active = _active_calibration(given.active_calibration)
    check_model(given.model)
    say(f'reading {len(paths)} bag(s)...')
    points = read_bag_points(
        paths,
        config,
        BagReading(
            salvage=given.salvage,
            estimate_body=given.estimate_body,
            progress=say,
            started_s=started,
        ),
    )
    written = given.written
    result = cast(
        CalibrationResult,
        calibrate(
            points,
            CalibrationSettings(
                model=given.model,
                diagnose=given.diagnose,
                force=given.force,
                active=active,
                serial=given.serial,
                operator=given.operator,
                progress=say,
                out=RecordOptions(
                    out_dir,
                    plots=given.plots,
                    overwrite=given.overwrite,
                    written=None
                    if written is None
                    else (lambda done, _: written(_refit_result(done, out_dir))),
                ),
            ),
        ),
    )
    return _refit_result(result, out_dir)


def _refit_result(result: CalibrationResult, out_dir: Path) -> RefitResult:
    """What run_refit returns for `result` written into out_dir."""
    return RefitResult(
        result.calibration,
        out_dir / 'calibration.yaml',
        result.report,
        summary_line(result.report),
        out_dir,
    )


def _balance_config(balance: str | Path, given: RefitSettings) -> BalanceConfig:
    """The balance config, its schedule replaced by given.schedule when there is one."""
    try:
        config = load_balance_config(balance)
        if given.schedule is not None:
            require_regular_file(given.schedule, 'schedule')
            from ..gates.limits import acceptance_limits

            margin = acceptance_limits(config, given.model).capacity_margin
            config = replace(config, schedule=schedule_for(config, given.schedule, margin))
    except ConfigError as err:
        raise RefitError(str(err)) from None
    return config


def _active_calibration(active: Calibration | str | Path | None) -> Calibration | None:
    """The calibration in use: as given, or loaded from its file."""
    from ..calibration_file import load_calibration

    if not isinstance(active, (str, Path)):
        return active
    require_regular_file(active, 'active calibration')
    try:
        return load_calibration(active)
    except (ConfigError, OSError) as err:  # ConfigError names the file (and line) itself
        text = str(err) if str(err).startswith(str(active)) else f'{active}: {err}'
        raise RefitError(f'active calibration {text}') from None
