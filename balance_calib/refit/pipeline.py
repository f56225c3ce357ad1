"""The refit pipeline behind `~/refit` and `balance-calib refit`.

bags -> load points -> zero points + tare (corrected data, §5(4), §6-7) -> linear, quadratic and
cubic fits (§2-3) -> diagnosis of the residuals (what the base model lacks) -> calibration.yaml,
report.json, report.md and residual plots (interfaces.md). Everything is written into a staging
directory and moved into place only when complete, so a failure leaves `out_dir` as it was.
"""
from __future__ import annotations

import json
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from ..accuracy.sigma import sigma_by_component
from ..calibration_file import Calibration, ConfigError, now_iso, save_calibration
from ..config import BalanceConfig, load_balance_config
from ..fit.crossval import press_residuals
from ..fit.least_squares import FitResult, UnexcitedTermsError, fit_model
from ..model.inverse import InverseDidNotConverge
from ..model.tm663 import MODEL_ORDERS, tm663_terms
from ..reduction import LoadPoints, Reduction, reduce_points, retare_with_model
from ..zero_points import ZeroPointError
from .load_points import CutSummary, LoadPointError, cut_load_points

Progress = Callable[[str], None]


class RefitError(ValueError):
    """The refit cannot be done with these inputs; the message says which file and why."""


@dataclass(frozen=True)
class ModelFit:
    fit: FitResult
    sigma_pct_fs: dict[str, float]
    sigma_crossval_pct_fs: dict[str, float]


@dataclass(frozen=True)
class CalibrationResult:
    """The pure result of a refit before anything is written."""

    config: BalanceConfig
    points: LoadPoints
    reduction: Reduction
    fits: Mapping[str, ModelFit]           # linear, quadratic, cubic
    base_model: str
    diagnosis: object | None               # balance_calib.diagnosis result, if run
    calibration: Calibration
    report: dict
    cut: CutSummary | None = None


@dataclass(frozen=True)
class RefitResult:
    calibration: Calibration
    calibration_path: Path
    report: dict
    summary: str
    out_dir: Path


def _fit_all(reduction: Reduction, config: BalanceConfig, orders: Sequence[str]) -> dict[str, ModelFit]:
    data = reduction.corrected
    fits = {}
    for order in orders:
        try:
            fit = fit_model(tm663_terms(order, config.bridge_outputs), data.bridge_outputs_mv, data.loads, name=order,
                            rated_outputs=config.rated_outputs_by_name, components=config.components,
                            inputs=config.bridge_outputs)
        except UnexcitedTermsError as err:
            raise RefitError(str(err)) from None
        press = press_residuals(fit.model.design(data.bridge_outputs_mv), fit.residuals)
        fits[order] = ModelFit(fit, sigma_by_component(fit.residuals, config.capacity, config.components),
                               sigma_by_component(press, config.capacity, config.components))
    return fits


def calibrate_points(points: LoadPoints, config: BalanceConfig, *, base_model: str = 'cubic',
                     diagnose: bool = True, estimate_body: bool = True, progress: Progress | None = None,
                     cut: CutSummary | None = None, sources: Sequence[str] = ()) -> CalibrationResult:
    """Everything after the load points; pure (writes nothing)."""
    say = progress or (lambda message: None)
    if base_model not in MODEL_ORDERS:
        raise RefitError(f'base model {base_model!r}: expected one of {", ".join(MODEL_ORDERS)}')
    if len(points.label) < 10:
        raise RefitError(f'only {len(points.label)} load points: far too few to calibrate a balance')
    try:
        reduction = reduce_points(points, config, estimate_body_weight=estimate_body)
        say(f'zero points and tare applied to {len(points.label)} points '
            f'(body {reduction.body.weight_n:.2f} N, {reduction.body_source})')
        orders = [o for o in MODEL_ORDERS if MODEL_ORDERS.index(o) <= max(MODEL_ORDERS.index(base_model), 2)]
        fits = _fit_all(reduction, config, orders)
        # tare outputs from the fitted model's inverse instead of the linear eqs. (32)-(37), then refit
        reduction = retare_with_model(reduction, fits[base_model].fit.model)
        fits = _fit_all(reduction, config, orders)
    except (ZeroPointError, InverseDidNotConverge, LoadPointError) as err:
        raise RefitError(str(err)) from None
    say('fits: ' + ', '.join(f'{o} σFX {fits[o].sigma_pct_fs[config.components[0]]:.3f} % FS' for o in orders))

    diagnosis = None
    if diagnose:
        diagnosis = _run_diagnosis(reduction, config, base_model, fits[base_model], say)

    from .report import build_calibration, build_report
    calibration = build_calibration(config, reduction, fits, base_model, diagnosis, sources)
    report = build_report(config, points, reduction, fits, base_model, diagnosis, cut, sources)
    return CalibrationResult(config, points, reduction, fits, base_model, diagnosis, calibration, report, cut)


def _run_diagnosis(reduction, config, base_model, base_fit, say):
    try:
        from ..diagnosis import diagnose as diagnose_residuals
    except ImportError:
        say('diagnosis not available: residuals not examined')
        return None
    say('examining the residuals for effects the base model lacks...')
    return diagnose_residuals(reduction, config, base_model=base_model)


def run_refit(bag_paths: Sequence[str | Path], balance: str | Path, out_dir: str | Path, *,
              model: str = 'cubic', diagnose: bool = True, estimate_body: bool = True,
              progress: Progress | None = None, plots: bool = True) -> RefitResult:
    """Refit from bags and write calibration.yaml, report.json, report.md and plots into out_dir."""
    from ..bags.errors import BagError
    from ..bags.reader import read_bags
    say = progress or (lambda message: None)
    started = time.monotonic()
    paths = [Path(p) for p in bag_paths]
    if not paths:
        raise RefitError('no bags given (parameter calibration_bags is empty)')
    try:
        config = load_balance_config(balance)
    except ConfigError as err:
        raise RefitError(str(err)) from None
    say(f'reading {len(paths)} bag(s)...')

    def bag_progress(done, total):
        say(f'read {done}/{total} messages ({100 * done / max(total, 1):.0f} %)')

    try:
        bag = read_bags(paths, required=('raw', 'applied_load', 'gravity'), progress=bag_progress)
    except BagError as err:
        raise RefitError(str(err)) from None
    source = ', '.join(str(p) for p in paths)
    try:
        points, cut = cut_load_points(bag, config, source=source)
    except LoadPointError as err:
        raise RefitError(str(err)) from None
    say(f'{cut.points} load points, {cut.samples_used} samples used, {cut.samples_rejected_outliers} outliers '
        f'and {cut.samples_rejected_nan} NaN samples rejected')
    result = calibrate_points(points, config, base_model=model, diagnose=diagnose, estimate_body=estimate_body,
                              progress=say, cut=cut, sources=[str(p) for p in paths])
    result.report['wall_time_s'] = round(time.monotonic() - started, 3)
    out = write_outputs(result, Path(out_dir), plots=plots)
    say(f'wrote {out}')
    return RefitResult(result.calibration, Path(out_dir) / 'calibration.yaml', result.report,
                       summary_line(result.report), Path(out_dir))


def summary_line(report: Mapping) -> str:
    before, after = report['sigma_pct_fs']['before'], report['sigma_pct_fs']['after']
    parts = ' '.join(f'{c} {before[c]:.3f}->{after[c]:.3f}' for c in before)
    effects = ', '.join(e['name'] + '(' + '/'.join(e['components']) + ')' for e in report['effects']) or 'none'
    return f'{report["balance"]}: {report["points"]} points; σ % FS {parts}; effects: {effects}'


def write_outputs(result: CalibrationResult, out_dir: Path, *, plots: bool = True) -> Path:
    """Write the files into a staging directory, then move each into out_dir (nothing half-written)."""
    from .report import report_markdown
    out_dir.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix='.refit-', dir=out_dir))
    try:
        save_calibration(staging / 'calibration.yaml', result.calibration)
        (staging / 'report.json').write_text(json.dumps(result.report, indent=2, allow_nan=False) + '\n')
        figures = []
        if plots:
            from .plots import residual_figures
            figures = residual_figures(result, staging)
        result.report.setdefault('plots', [f.name for f in figures])
        (staging / 'report.json').write_text(json.dumps(result.report, indent=2, allow_nan=False) + '\n')
        (staging / 'report.md').write_text(report_markdown(result.report, result))
        for item in sorted(staging.iterdir()):
            item.replace(out_dir / item.name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return out_dir


def campaign_points(campaign) -> LoadPoints:
    """LoadPoints straight from a simulated Campaign (no bag), for the demo and tests."""
    means, times, temps = campaign.point_means()
    return LoadPoints(np.asarray(campaign.point), means, times, temps, np.asarray(campaign.orientation),
                      campaign.gravity, campaign.applied_loads)
