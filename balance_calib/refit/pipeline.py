"""The refit pipeline behind `~/refit` and `balance-calib refit`.

bags -> load points -> zero points + tare (corrected data, §5(4), §6-7) -> linear, quadratic and
cubic fits (§2-3) -> diagnosis of the residuals (what the base model lacks) -> calibration.yaml,
report.json, report.md and residual plots (interfaces.md). Before anything is written the
acceptance gates (gates/) must pass: a failed gate raises RefitError with one line, unless
`force` (then the report says so). Everything is written into a staging directory beside `out_dir`
and moved into place only when complete, so a failure or a kill leaves `out_dir` as it was.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import json
import os
from pathlib import Path
import shutil
import time
from typing import Callable, cast, Mapping, Sequence, TYPE_CHECKING

import numpy as np

from ..accuracy.sigma import sigma_by_component
from ..calibration_file import ConfigError, save_calibration
from ..config import BalanceConfig, load_balance_config, LoadSchedule
from ..fit.crossval import press_residuals
from ..fit.least_squares import fit_model, FitResult, UnexcitedTermsError
from ..model.calibration import Calibration
from ..model.inverse import InverseDidNotConverge
from ..model.tm663 import MODEL_ORDERS, tm663_terms
from ..reduction import LoadPoints, reduce_points, Reduction, retare_with_model
from ..schedule_file import schedule_for
from ..zero_points import ZeroPointError
from .load_points import cut_load_points, CutSummary, LoadPointError

if TYPE_CHECKING:
    from ..diagnosis.diagnose import Diagnosis

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
    fits: Mapping[str, ModelFit]  # linear, quadratic, cubic
    base_model: str
    diagnosis: Diagnosis | None  # balance_calib.diagnosis result, if run
    calibration: Calibration
    report: dict
    cut: CutSummary | None = None
    gates: tuple = ()  # gates.gate.Gate, in order


@dataclass(frozen=True)
class RefitResult:
    calibration: Calibration
    calibration_path: Path
    report: dict
    summary: str
    out_dir: Path


def _fit_all(
    reduction: Reduction, config: BalanceConfig, orders: Sequence[str]
) -> dict[str, ModelFit]:
    data = reduction.corrected
    fits = {}
    for order in orders:
        try:
            fit = fit_model(
                tm663_terms(order, config.bridge_outputs),
                data.bridge_outputs_mv,
                data.loads,
                name=order,
                rated_outputs=config.rated_outputs_by_name,
                components=config.components,
                inputs=config.bridge_outputs,
            )
        except UnexcitedTermsError as err:
            raise RefitError(str(err)) from None
        press = press_residuals(fit.model.design(data.bridge_outputs_mv), fit.residuals)
        fits[order] = ModelFit(
            fit,
            sigma_by_component(fit.residuals, config.capacity, config.components),
            sigma_by_component(press, config.capacity, config.components),
        )
    return fits


def calibrate_points(
    points: LoadPoints,
    config: BalanceConfig,
    *,
    base_model: str = 'cubic',
    diagnose: bool = True,
    estimate_body: bool = True,
    progress: Progress | None = None,
    cut: CutSummary | None = None,
    sources: Sequence[str] = (),
    active: Calibration | None = None,
    force: bool = False,
    schedule: LoadSchedule | None = None,
    serial: str | None = None,
    operator: str | None = None,
) -> CalibrationResult:
    """Everything after the load points; pure (writes nothing).

    Raises RefitError when an acceptance gate fails (gates/), unless force; active is the
    calibration in use, whose sensitivities the new one must stay near; schedule the load
    schedule the campaign ran (None: the balance config's own), which the points must cover;
    serial (default the config's `serial`) and operator go into the signed record (record.py).
    """
    from ..gates.bags import base_model_residuals, data_gates, fit_gates
    from ..gates.gate import failed, gates_report, ModelResiduals
    from ..gates.limits import acceptance_limits
    from ..gates.outputs import output_range_gate

    say = progress or (lambda message: None)
    if base_model not in MODEL_ORDERS:
        raise RefitError(f'base model {base_model!r}: expected one of {", ".join(MODEL_ORDERS)}')
    if len(points.label) < 10:
        raise RefitError(
            f'only {len(points.label)} load points: far too few to calibrate a balance'
        )
    try:
        reduction = reduce_points(points, config, estimate_body_weight=estimate_body)
        say(
            f'zero points and tare applied to {len(points.label)} points '
            f'(body {reduction.body.weight_n:.2f} N, {reduction.body_source})'
        )
        range_gate = output_range_gate(config, reduction)
        _refuse_unless_forced([range_gate], force, sources, say)
        orders = [
            o
            for o in MODEL_ORDERS
            if MODEL_ORDERS.index(o) <= max(MODEL_ORDERS.index(base_model), 2)
        ]
        fits = _fit_all(reduction, config, orders)
        # tare outputs from the fitted model's inverse instead of the linear eqs. (32)-(37), then
        # refit
        reduction = retare_with_model(reduction, fits[base_model].fit.model)
        fits = _fit_all(reduction, config, orders)
        limits = acceptance_limits(config, base_model)
    except (ZeroPointError, InverseDidNotConverge, LoadPointError, ConfigError, RefitError) as err:
        raise RefitError(_named(str(err), sources)) from None
    except (np.linalg.LinAlgError, FloatingPointError, ValueError) as err:
        # absurd numbers that survived the edges (a flipped exponent bit): say so, never a
        # traceback
        raise RefitError(
            f'{_where(sources)}: the load points cannot be fitted ({" ".join(str(err).split())})'
        ) from None
    gates = [range_gate] + data_gates(
        config, points, reduction, fits, cut, active, limits, schedule
    )
    if not diagnose:
        gates += fit_gates(
            config, points, base_model_residuals(reduction, fits[base_model]), limits
        )
    _refuse_unless_forced(gates, force, sources, say)
    say(
        'fits: '
        + ', '.join(
            f'{o} σFX {fits[o].sigma_pct_fs[config.components[0]]:.3f} % FS' for o in orders
        )
    )

    diagnosis = None
    if diagnose:
        diagnosis = _run_diagnosis(reduction, config, base_model, fits[base_model], say, cut)
        if diagnosis is not None:
            # σ and outliers of the model that will be adopted (effects found included)
            from ..diagnosis.coherence import diagnosis_structure

            unexplained = {c: u.tracks for u in diagnosis.unexplained for c in u.components}
            extra = fit_gates(
                config,
                points,
                ModelResiduals(
                    diagnosis.sigma_pct_fs['after'],
                    diagnosis.residuals_after,
                    diagnosis.press_residuals_after,
                    'adopted model' if diagnosis.effects else 'base model',
                ),
                limits,
                unexplained,
                diagnosis_structure(diagnosis, points, config),
            )
        else:
            extra = fit_gates(
                config, points, base_model_residuals(reduction, fits[base_model]), limits
            )
        _refuse_unless_forced(extra, force, sources, say)
        gates += extra

    from .report import build_calibration, build_report

    calibration = build_calibration(config, reduction, fits, base_model, diagnosis, sources)
    report = build_report(config, points, reduction, fits, base_model, diagnosis, cut, sources)
    from ..record import signed_record

    serial = serial or config.serial
    if serial:
        cast(dict, calibration.extra)['serial'] = serial
    # the lab's record first, then the numbers the report adds to it (report_sections.py)
    report['record'] = {
        **signed_record(
            balance=config.name,
            serial=serial,
            operator=operator,
            inputs=sources,
            calibration=calibration,
        ),
        **report['record'],
    }
    report['acceptance'] = gates_report(gates, forced=force)
    report['warnings'] = list(report.get('warnings', [])) + _missing_points_warning(gates)
    if cut is not None:
        report['sessions'] = {
            'count': len(cut.pauses_s) + 1,
            'pauses_s': [round(p, 1) for p in cut.pauses_s],
        }
    bad = failed(gates)
    if bad:
        cast(dict, calibration.extra)['acceptance'] = {
            'forced': True,
            'failed': [g.name for g in bad],
        }
    return CalibrationResult(
        config,
        points,
        reduction,
        fits,
        base_model,
        diagnosis,
        calibration,
        report,
        cut,
        tuple(gates),
    )


def _refuse_unless_forced(gates, force: bool, sources: Sequence[str], say: Progress) -> None:
    from ..gates.gate import failed

    for gate in gates:
        say(f'gate {gate.name}: {"ok" if gate.passed else "FAILED"}: {gate.reason}')
    # the most specific cause first: a unit error also spoils σ, not the other way round
    priority = (
        'marker_order',
        'clipping',
        'output_range',
        'sensitivity',
        'active_calibration',
        'capacity',
        'body_weight',
        'zero_points',
        'schedule',
        'outliers',
        'sigma',
    )
    bad = sorted(
        failed(gates),
        key=lambda g: priority.index(g.name) if g.name in priority else len(priority),
    )
    if bad and not force:
        also = f' (also failed: {", ".join(g.name for g in bad[1:])})' if len(bad) > 1 else ''
        raise RefitError(
            f'{_where(sources)}: refused by acceptance gate {bad[0].name}: {bad[0].reason}{also}; '
            f'nothing written (--force writes it anyway)'
        )


def _missing_points_warning(gates) -> list[str]:
    """A campaign that lost a few of its scheduled points passes the schedule gate: say so."""
    gate = next((g for g in gates if g.name == 'schedule'), None)
    if gate is None or not gate.passed or not gate.details.get('missing'):
        return []
    return [
        f'{gate.details["missing"]} of the schedule\'s {gate.details["expected"]} points are '
        f"missing from the campaign (within the schedule gate's limit): {gate.reason}"
    ]


def _named(text: str, sources: Sequence[str]) -> str:
    """The message with the campaign's files in front, unless it names them already."""
    if not sources or any(str(s) in text for s in sources):
        return text
    return f'{_where(sources)}: {text}'


def _where(sources: Sequence[str]) -> str:
    return ', '.join(str(s) for s in sources) if sources else 'campaign'


def point_scatter_for(points: LoadPoints, cut: CutSummary | None) -> dict:
    """diagnose()'s point_variance_mv2 (P, n) and point_samples (P,) in the order of `points`.

    The cut keeps each point's own scatter (load_points.py); the points are matched by label, so
    a reordering or a subset between the cut and the diagnosis cannot pair a point with another's
    scatter. Empty (repeatability from the zero points) without a cut or when a point is missing.
    """
    if cut is None or cut.point_variance_mv2 is None or cut.point_labels is None:
        return {}
    labels = np.asarray(cut.point_labels)
    at = {label: i for i, label in enumerate(labels.tolist())}
    if len(at) != len(labels):
        return {}
    index = [at.get(label, -1) for label in np.asarray(points.label).tolist()]
    if min(index, default=-1) < 0:
        return {}
    return {
        'point_variance_mv2': np.asarray(cut.point_variance_mv2, float)[index],
        'point_samples': np.asarray(cut.point_samples)[index],
    }


def _run_diagnosis(reduction, config, base_model, base_fit, say, cut=None):
    try:
        from ..diagnosis import diagnose as diagnose_residuals
    except ImportError:
        say('diagnosis not available: residuals not examined')
        return None
    scatter = point_scatter_for(reduction.points, cut)
    say(
        'examining the residuals for effects the base model lacks (repeatability from '
        + ("the points' own samples)..." if scatter else 'consecutive zero points)...')
    )
    return diagnose_residuals(reduction, config, base_model=base_model, **scatter)


def run_refit(
    bag_paths: Sequence[str | Path],
    balance: str | Path,
    out_dir: str | Path,
    *,
    model: str = 'cubic',
    diagnose: bool = True,
    estimate_body: bool = True,
    progress: Progress | None = None,
    plots: bool = True,
    force: bool = False,
    salvage: bool = False,
    active_calibration: Calibration | str | Path | None = None,
    overwrite: bool = True,
    schedule: str | Path | None = None,
    serial: str | None = None,
    operator: str | None = None,
    written: Callable[[RefitResult], None] | None = None,
) -> RefitResult:
    """Refit from bags and write calibration.yaml, report.json, report.md and plots into out_dir.

    Every input error, integrity failure (bags/reader.py) and failed acceptance gate raises
    RefitError with one line naming the file; `out_dir` is checked before any work. force writes
    a calibration that failed a gate (marked in the report); salvage reads what is intact of a
    damaged bag and the report says what was lost; active_calibration (a Calibration or a file)
    is the calibration in use, which the new one's sensitivities must stay near. overwrite: an
    out_dir holding an earlier calibration record is replaced (the command line refuses it unless
    --overwrite; output_dir.py). schedule (a CSV in the layout of ../data/*_schedule.csv): the
    schedule the campaign ran when it is not the balance config's own; it replaces
    config.schedule, which the gates (the schedule gate among them) judge the campaign against.
    serial (default the balance config's) and operator: the signed record's (record.py).
    written(result): called once calibration.yaml, report.json and report.md are in out_dir,
    before the figures are drawn (~/refit replies then); run_refit returns after the figures.
    """
    from ..bags.errors import BagError
    from ..bags.messages import SIMULATION_TOPIC
    from ..bags.reader import read_bags
    from ..calibration_file import load_calibration

    say = progress or (lambda message: None)
    started = time.monotonic()
    paths = [Path(p) for p in bag_paths]
    if not paths:
        raise RefitError('no bags given (parameter calibration_bags is empty)')
    out_dir = Path(out_dir)
    check_out_dir(out_dir, overwrite)
    _require_regular_file(balance, 'balance config')
    try:
        config = load_balance_config(balance)
        if schedule is not None:
            _require_regular_file(schedule, 'schedule')
            from ..gates.limits import acceptance_limits

            margin = acceptance_limits(config, model).capacity_margin
            config = replace(config, schedule=schedule_for(config, schedule, margin))
    except ConfigError as err:
        raise RefitError(str(err)) from None
    active = active_calibration
    if isinstance(active, (str, Path)):
        _require_regular_file(active, 'active calibration')
        try:
            active = load_calibration(active)
        except (ConfigError, OSError) as err:  # ConfigError names the file (and line) itself
            text = str(err) if str(err).startswith(str(active)) else f'{active}: {err}'
            raise RefitError(f'active calibration {text}') from None
    say(f'reading {len(paths)} bag(s)...')

    said = ['']

    def bag_progress(done, total):
        line = f'read {done}/{total} messages ({100 * done / max(total, 1):.0f} %)'
        if line != said[0]:  # the reader may report its last count twice (end of data, end of bag)
            said[0] = line
            say(line)

    try:
        bag = read_bags(
            paths,
            required=('raw', 'applied_load', 'gravity'),
            progress=bag_progress,
            salvage=salvage,
            extra_topics=(SIMULATION_TOPIC,),
        )
    except BagError as err:
        raise RefitError(str(err)) from None
    for loss in bag.losses:
        say(f'salvaged: {loss}')
    source = ', '.join(str(p) for p in paths)
    try:
        points, cut = cut_load_points(bag, config, source=source)
    except LoadPointError as err:
        raise RefitError(str(err)) from None
    say(
        f'{cut.points} load points, {cut.samples_used} samples used, '
        f'{cut.samples_rejected_outliers} outliers and {cut.samples_rejected_nan} NaN samples '
        'rejected'
    )
    if cut.pauses_s:
        say(
            f'{len(cut.pauses_s) + 1} sessions: pauses of '
            f'{", ".join(f"{p:.0f}" for p in cut.pauses_s)} s shortened on the time axis'
        )
    result = calibrate_points(
        points,
        config,
        base_model=model,
        diagnose=diagnose,
        estimate_body=estimate_body,
        progress=say,
        cut=cut,
        sources=[str(p) for p in paths],
        active=active,
        force=force,
        serial=serial,
        operator=operator,
    )
    result.report['bag_integrity'] = {
        'salvaged': bool(salvage and bag.losses),
        'lost': list(bag.losses),
        'messages_read': dict(bag.message_counts),
    }
    result.report['wall_time_s'] = round(time.monotonic() - started, 3)
    simulated = bag.extra.get(SIMULATION_TOPIC)
    if simulated is not None and len(simulated.messages) and 'record' in result.report:
        # the stamps are a simulator's clock: the report must not date a campaign by them
        result.report['record']['campaign']['clock'] = str(simulated.messages[0].data)
    say(
        f'writing calibration.yaml, report.json, report.md{" and plots" if plots else ""} into '
        f'{out_dir}'
    )
    refit = RefitResult(
        result.calibration,
        out_dir / 'calibration.yaml',
        result.report,
        summary_line(result.report),
        out_dir,
    )
    out = write_outputs(
        result,
        out_dir,
        plots=plots,
        overwrite=overwrite,
        written=None if written is None else (lambda _: written(refit)),
        progress=say,
    )
    say(f'wrote {out}')
    return refit


def summary_line(report: Mapping) -> str:
    before, after = report['sigma_pct_fs']['before'], report['sigma_pct_fs']['after']
    parts = ' '.join(f'{c} {before[c]:.3f}->{after[c]:.3f}' for c in before)
    effects = (
        ', '.join(e['name'] + '(' + '/'.join(e['components']) + ')' for e in report['effects'])
        or 'none'
    )
    return f'{report["balance"]}: {report["points"]} points; σ % FS {parts}; effects: {effects}'


def check_out_dir(out_dir: Path, overwrite: bool = True) -> Path:
    """output_dir.check_out_dir with its refusal as a RefitError (before any work)."""
    from ..output_dir import check_out_dir as check
    from ..output_dir import OutputError

    try:
        return check(out_dir, overwrite=overwrite)
    except OutputError as err:
        raise RefitError(str(err)) from None


_MAX_CONFIG_BYTES = 64 * 1024 * 1024


def _require_regular_file(path: str | Path, what: str) -> None:
    """A FIFO or device would block the read or never end: refuse it before opening."""
    import stat

    path = Path(path)
    if not path.exists():
        return  # a shipped name such as 'lmc6522'; the loader says if it is unknown
    mode = path.stat().st_mode
    if stat.S_ISDIR(mode) or not stat.S_ISREG(mode):
        raise RefitError(f'{path}: {what} is not a regular file')
    if path.stat().st_size > _MAX_CONFIG_BYTES:
        raise RefitError(f'{path}: {what} of {path.stat().st_size} bytes is too large')


def write_outputs(
    result: CalibrationResult,
    out_dir: Path,
    *,
    plots: bool = True,
    overwrite: bool = True,
    written: Callable[[Path], None] | None = None,
    progress: Progress | None = None,
) -> Path:
    """Write the files into a staging directory, then move them in (nothing half-written).

    output_dir.py says how: a new out_dir appears whole with one rename; into an existing one
    (allowed with overwrite) the earlier run's outputs not written again are removed and each
    file is replaced by a rename. Files are readable by others (0644, directory 0755).

    The figures come last, off the critical path: calibration.yaml, report.json and report.md
    (which already names every figure) are installed first and `written(out_dir)` is called;
    then each figure is drawn into a staging directory and renamed into out_dir. A figure that
    cannot be drawn is said (progress, report's `warnings`) and left out of report.md's links;
    the calibration stays.
    """
    from ..output_dir import install_outputs, make_staging
    from .report import report_markdown

    out_dir = Path(out_dir)
    figures = []
    if plots:
        from .plots import figure_plan

        figures = figure_plan(result)
    result.report.setdefault('plots', [name for name, _ in figures])
    staging = make_staging(out_dir, check_out_dir(out_dir, overwrite), 'refit')
    try:
        save_calibration(staging / 'calibration.yaml', result.calibration)
        (staging / 'report.json').write_text(
            json.dumps(result.report, indent=2, allow_nan=False) + '\n'
        )
        (staging / 'report.md').write_text(report_markdown(result.report, result))
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    out = install_outputs(staging, out_dir, overwrite=overwrite)
    if written is not None:
        written(out)
    if figures:
        _draw_figures(result, figures, out, progress or (lambda message: None))
    return out


def _draw_figures(result: CalibrationResult, figures, out_dir: Path, say: Progress) -> None:
    """Draw (name, draw) into a staging directory in out_dir and rename each into place; a
    failure is told and taken out of the report (report.json, report.md rewritten atomically).
    """
    from ..calibration_file import write_text_atomically
    from ..figure_png import draw_figures
    from ..output_dir import FILE_MODE, make_staging
    from .report import report_markdown

    staging = make_staging(out_dir, out_dir, 'refit')
    try:
        # the residual figures share one figure (refit/plots.py); the others are drawn beside
        failed = draw_figures(
            figures, staging, beside=lambda name: not name.startswith('residuals_')
        )
        for name in dict.fromkeys(name for name, _ in figures):  # a name drawn twice: once
            if name not in failed:
                os.chmod(staging / name, FILE_MODE)
                os.replace(staging / name, out_dir / name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    if not failed:
        return
    report = result.report
    report['plots'] = [name for name in report.get('plots', []) if name not in failed]
    report['warnings'] = list(report.get('warnings', [])) + [
        f'figure {name} could not be drawn ({why}); the calibration is not affected'
        for name, why in failed.items()
    ]
    for line in report['warnings'][-len(failed) :]:
        say(line)
    write_text_atomically(
        out_dir / 'report.json', json.dumps(report, indent=2, allow_nan=False) + '\n'
    )
    write_text_atomically(out_dir / 'report.md', report_markdown(report, result))


def campaign_points(campaign) -> LoadPoints:
    """LoadPoints straight from a simulated Campaign (no bag), for the demo and tests."""
    means, times, temps = campaign.point_means()
    return LoadPoints(
        np.asarray(campaign.point),
        means,
        times,
        temps,
        np.asarray(campaign.orientation),
        campaign.gravity,
        campaign.applied_loads,
    )
