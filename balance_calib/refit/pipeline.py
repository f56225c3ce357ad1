"""The bag side of the calibration path, behind `~/refit`, `balance-calib refit` and `simulate`.

bags -> load points -> zero points + tare (refit/bag_points.py) -> calibrate/path.calibrate ->
calibrate_bag here: linear, quadratic and cubic fits (§2-3) -> diagnosis of the residuals (what
the base model lacks) -> calibration.yaml, report.json, report.md and residual plots
(interfaces.md), written by calibrate/write_record.py. Before anything is written the acceptance
gates (gates/) must pass: a failed gate raises RefitError with one line, unless `force` (then the
report says so).
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
import time
from typing import Callable, cast, Iterator, Mapping, Sequence, TYPE_CHECKING

import numpy as np

from ..accuracy.sigma import sigma_by_component
from ..calibration_file import ConfigError
from ..calibration_points import CalibrationPoints, CutSummary
from ..calibration_settings import CalibrationSettings
from ..calibration_stages import run_stages
from ..config import BalanceConfig
from ..fit.crossval import press_residuals
from ..fit.least_squares import fit_model, FitResult, UnexcitedTermsError
from ..gates.gate import BAG_PRIORITY, Gate
from ..model.calibration import Calibration
from ..model.inverse import InverseDidNotConverge
from ..model.tm663 import MODEL_ORDERS, tm663_terms
from ..reduction import LoadPoints, Reduction, retare_with_model
from ..zero_points import ZeroPointError
from .bag_points import (
    BagReading,
    campaign_points,
    load_points_record,
    reduced_points,
)
from .errors import named as _named
from .errors import RefitError
from .errors import where as _where
from .load_points import LoadPointError

if TYPE_CHECKING:
    from ..diagnosis.diagnose import Diagnosis

Progress = Callable[[str], None]

__all__ = ['campaign_points', 'RefitError']


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
    cut: CutSummary | None = None,
    settings: CalibrationSettings | None = None,
    *,
    estimate_body: bool = True,
    sources: Sequence[str] = (),
) -> CalibrationResult:
    """calibrate_bag of load points cut elsewhere (a simulation, a test): the bag branch of
    calibrate/path.calibrate, which writes nothing here. Returns the fits, the diagnosis, the
    calibration and its report.

    settings: what the calibration is asked to do (default CalibrationSettings()); estimate_body:
    the calibration body from the zero points (else the declared one); sources: the files the
    points came from, named in errors.
    """
    settings = settings or CalibrationSettings()
    check_model(settings.model)
    record = load_points_record(points, cut, sources)
    reading = BagReading(estimate_body=estimate_body, progress=settings.progress)
    return calibrate_bag(reduced_points(record, config, reading), settings)


def check_model(model: str) -> None:
    """RefitError unless `model` is a TM-663 base model (linear, quadratic, cubic)."""
    if model not in MODEL_ORDERS:
        raise RefitError(f'base model {model!r}: expected one of {", ".join(MODEL_ORDERS)}')


def calibrate_bag(points: CalibrationPoints, settings: CalibrationSettings) -> CalibrationResult:
    """Everything after the zero points and tare of a bag's (or a simulation's) points; pure
    (writes nothing): BagStages run in the path's one order (calibration_stages.run_stages).
    """
    return run_stages(BagStages(points, settings), settings.force, settings.progress)


class BagStages:
    """The stages (calibration_stages.py) of a bag's (or a simulation's) points: the TM-663
    fits, the residual diagnosis and the refit's gates. Returns the fits, the diagnosis, the
    calibration and its report.

    A failed acceptance gate (gates/) is a RefitError, unless settings.force; settings.active is
    the calibration in use, whose sensitivities the new one must stay near; the points must cover
    the balance config's schedule; settings.serial (default the config's `serial`) and operator
    go into the signed record (record.py).
    """

    priority = BAG_PRIORITY
    names_others = True

    def __init__(self, points: CalibrationPoints, settings: CalibrationSettings) -> None:
        bag = points.bag
        if bag is None or bag.reduction is None or bag.config is None:
            raise ValueError(f'{points.source}: no reduced bag points to calibrate')
        check_model(settings.model)
        self.bag, self.settings = bag, settings
        self.config, self.reduction, self.cut = bag.config, bag.reduction, bag.cut
        self.sources: Sequence[str] = bag.files
        self.where = _where(self.sources)
        self.loaded = bag.load_points  # the gates judge the points as cut
        self.say = settings.progress or (lambda message: None)
        self.diagnosis: Diagnosis | None = None

    def refused(self, message: str) -> Exception:
        return RefitError(message)

    def screen(self) -> list[Gate]:
        """The output range, before any fit."""
        from ..gates.outputs import output_range_gate

        with self._named_errors():
            return [output_range_gate(self.config, self.reduction)]

    def fit(self) -> None:
        """The base model's orders up to cubic, the tare from the fitted model's inverse, and
        the fits again.
        """
        from ..gates.limits import acceptance_limits

        base_model = self.settings.model
        with self._named_errors():
            self.orders = [
                o
                for o in MODEL_ORDERS
                if MODEL_ORDERS.index(o) <= max(MODEL_ORDERS.index(base_model), 2)
            ]
            fits = _fit_all(self.reduction, self.config, self.orders)
            # tare outputs from the fitted model's inverse instead of the linear eqs. (32)-(37),
            # then refit
            self.reduction = retare_with_model(self.reduction, fits[base_model].fit.model)
            self.fits = _fit_all(self.reduction, self.config, self.orders)
            self.limits = acceptance_limits(self.config, base_model)

    def data_gates(self) -> list[Gate]:
        """The campaign's gates; the fit's too when no diagnosis follows."""
        from ..gates.bags import base_model_residuals, data_gates, fit_gates

        gates = data_gates(
            self.config,
            self.loaded,
            self.reduction,
            self.fits,
            self.cut,
            self.settings.active,
            self.limits,
            None,
        )
        if not self.settings.diagnose:
            gates += fit_gates(
                self.config,
                self.loaded,
                base_model_residuals(self.reduction, self.fits[self.settings.model]),
                self.limits,
            )
        return gates

    def diagnose(self) -> None:
        """The diagnosis of the base model's residuals, when asked for."""
        first = self.config.components[0]
        self.say(
            'fits: '
            + ', '.join(
                f'{o} σ{first} {self.fits[o].sigma_pct_fs[first]:.3f} % FS' for o in self.orders
            )
        )
        if self.settings.diagnose:
            model = self.settings.model
            self.diagnosis = _run_diagnosis(
                self.reduction, self.config, model, self.fits[model], self.say, self.cut
            )

    def fit_gates(self) -> list[Gate]:
        """σ and outliers of the model that will be adopted (effects found included)."""
        from ..gates.bags import base_model_residuals, fit_gates
        from ..gates.gate import ModelResiduals

        if not self.settings.diagnose:
            return []
        diagnosis = self.diagnosis
        if diagnosis is None:
            return fit_gates(
                self.config,
                self.loaded,
                base_model_residuals(self.reduction, self.fits[self.settings.model]),
                self.limits,
            )
        from ..diagnosis.coherence import diagnosis_structure

        unexplained = {c: u.tracks for u in diagnosis.unexplained for c in u.components}
        return fit_gates(
            self.config,
            self.loaded,
            ModelResiduals(
                diagnosis.sigma_pct_fs['after'],
                diagnosis.residuals_after,
                diagnosis.press_residuals_after,
                'adopted model' if diagnosis.effects else 'base model',
            ),
            self.limits,
            unexplained,
            diagnosis_structure(diagnosis, self.loaded, self.config),
        )

    def result(self, gates: Sequence[Gate], forced: bool) -> CalibrationResult:
        """The calibration and its report, signed, with the gates' verdicts."""
        from ..gates.gate import failed, gates_report
        from ..record import signed_record
        from .report import build_calibration, build_report

        config, reduction, fits, cut, sources = (
            self.config,
            self.reduction,
            self.fits,
            self.cut,
            self.sources,
        )
        base_model, diagnosis, bag, settings = (
            self.settings.model,
            self.diagnosis,
            self.bag,
            self.settings,
        )
        loaded = self.loaded
        calibration = build_calibration(config, reduction, fits, base_model, diagnosis, sources)
        report = build_report(config, loaded, reduction, fits, base_model, diagnosis, cut, sources)
        serial = settings.serial or config.serial
        if serial:
            cast(dict, calibration.extra)['serial'] = serial
        # the lab's record first, then the numbers the report adds to it (report_sections.py)
        report['record'] = {
            **signed_record(
                balance=config.name,
                serial=serial,
                operator=settings.operator,
                inputs=sources,
                calibration=calibration,
            ),
            **report['record'],
        }
        report['acceptance'] = gates_report(gates, forced=forced)
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
        if bag.integrity is not None:
            report['bag_integrity'] = dict(bag.integrity)
        if bag.started_s is not None:
            report['wall_time_s'] = round(time.monotonic() - bag.started_s, 3)
        if bag.clock is not None and 'record' in report:
            # the stamps are a simulator's clock: the report must not date a campaign by them
            report['record']['campaign']['clock'] = bag.clock
        return CalibrationResult(
            config,
            loaded,
            reduction,
            fits,
            base_model,
            diagnosis,
            calibration,
            report,
            cut,
            tuple(gates),
        )

    @contextmanager
    def _named_errors(self) -> Iterator[None]:
        """A fit's failure as a RefitError naming the campaign's files, never a traceback."""
        try:
            yield
        except (
            ZeroPointError,
            InverseDidNotConverge,
            LoadPointError,
            ConfigError,
            RefitError,
        ) as err:
            raise RefitError(_named(str(err), self.sources)) from None
        except (np.linalg.LinAlgError, FloatingPointError, ValueError) as err:
            # absurd numbers that survived the edges (a flipped exponent bit): say so
            raise RefitError(
                f'{self.where}: the load points cannot be fitted ({" ".join(str(err).split())})'
            ) from None


def _missing_points_warning(gates) -> list[str]:
    """A campaign that lost a few of its scheduled points passes the schedule gate: say so."""
    gate = next((g for g in gates if g.name == 'schedule'), None)
    if gate is None or not gate.passed or not gate.details.get('missing'):
        return []
    return [
        f'{gate.details["missing"]} of the schedule\'s {gate.details["expected"]} points are '
        f"missing from the campaign (within the schedule gate's limit): {gate.reason}"
    ]


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


def require_regular_file(path: str | Path, what: str) -> None:
    """RefitError for a path that is no regular file or too large: a FIFO or device would block
    the read or never end, so it is refused before opening.
    """
    import stat

    path = Path(path)
    if not path.exists():
        return  # a shipped name such as 'lmc6522'; the loader says if it is unknown
    mode = path.stat().st_mode
    if stat.S_ISDIR(mode) or not stat.S_ISREG(mode):
        raise RefitError(f'{path}: {what} is not a regular file')
    if path.stat().st_size > _MAX_CONFIG_BYTES:
        raise RefitError(f'{path}: {what} of {path.stat().st_size} bytes is too large')
