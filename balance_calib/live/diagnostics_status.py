"""The calibrator's /diagnostics as plain data: the input counters, what the node knows at a
tick (LiveState) and the three DiagnosticStatus reports built from them (input, calibration,
overload), with the levels of diagnostic_msgs/DiagnosticStatus.
"""

from __future__ import annotations

from dataclasses import dataclass
import datetime as _dt

import numpy as np

from ..model.active_calibration import ActiveCalibration
from ..units import BRIDGE_OUTPUTS, COMPONENTS
from .calibrator_core import WrenchBatch
from .load_text import describe_loads
from .support_share import SupportShare

# diagnostic_msgs/DiagnosticStatus levels, repeated here so the core needs no ROS messages
OK, WARN, ERROR, STALE = 0, 1, 2, 3


@dataclass
class InputCounters:
    """Counts since start and since the last diagnostics report."""

    received: int = 0
    published: int = 0
    rejected_nonfinite: int = 0
    saturated: int = 0
    out_of_envelope: int = 0
    not_converged: int = 0  # iterative model: samples where Newton did not converge
    period_received: int = 0
    period_rejected: int = 0
    period_saturated: int = 0
    period_out_of_envelope: int = 0
    period_not_converged: int = 0

    def count(self, batch: WrenchBatch) -> None:
        """Count a batch the pure core computed."""
        n, ok = len(batch.accepted), int(np.count_nonzero(batch.accepted))
        out = int(np.count_nonzero(batch.out_of_envelope))
        if ok == n:  # every sample published: none saturated or failed (nor counted here)
            self.add(n, ok, out=out)
            return
        saturated = 0 if batch.saturated is None else int(np.count_nonzero(batch.saturated))
        failed = 0 if batch.not_converged is None else int(np.count_nonzero(batch.not_converged))
        self.add(n, ok, saturated, failed, out)

    def add(self, n: int, ok: int, saturated: int = 0, failed: int = 0, out: int = 0) -> None:
        """N samples received, ok of them published, saturated / failed (Newton) not, out of the
        envelope (published, flagged); the rest were rejected as not finite.
        """
        self.received += n
        self.period_received += n
        self.published += ok
        if ok != n:  # at 1 kHz almost every call is one published sample
            self.rejected_nonfinite += n - ok - saturated - failed
            self.period_rejected += n - ok - saturated - failed
            self.saturated += saturated
            self.period_saturated += saturated
            self.not_converged += failed
            self.period_not_converged += failed
        if out:
            self.out_of_envelope += out
            self.period_out_of_envelope += out

    def start_period(self) -> None:
        """Zero the counts of the diagnostics period (a report was sent)."""
        self.period_received = self.period_rejected = self.period_out_of_envelope = (
            self.period_saturated
        ) = 0
        self.period_not_converged = 0


@dataclass(frozen=True)
class StatusReport:
    """One diagnostic_msgs/DiagnosticStatus, as plain data."""

    level: int
    name: str
    message: str
    hardware_id: str
    values: tuple[tuple[str, str], ...]


@dataclass(frozen=True)
class LiveState:
    """What the node knows at a diagnostics tick."""

    period_s: float
    counters: InputCounters
    last_sample_age_s: float | None  # None: no sample yet
    stale_after_s: float
    temperature_age_s: float | None
    fallback_reason: str
    tare_zero_mv: np.ndarray | None  # the electrical zero (None: none taken)
    refit_running: bool = False
    tare_load: np.ndarray | None = None  # balance axes, N / N·m (None: no tare)
    tare_source: str = ''  # where the tare was persisted / restored from
    tare_refused: str = ''  # why the persisted zero and tare were not restored
    input_problems: tuple[tuple[str, int, int], ...] = ()  # (what, total, this period)
    input_values: tuple[tuple[str, str], ...] = ()
    overload: tuple[str, ...] | None = None  # components over the limit now (None = no overload)
    overload_values: tuple[tuple[str, str], ...] = ()
    lowpass_hz: float = 0.0
    support: SupportShare | None = None  # the period's samples against the schedule's support


def support_values(support: SupportShare | None) -> tuple[tuple[str, str], ...]:
    """/diagnostics keys of the share outside the calibration's support (live/support_share.py):
    outside_support_share (a number, or 'n/a: why'), the samples it judged and the components.
    """
    if support is None or support.share is None:
        why = 'not judged' if support is None else support.reason
        return (('outside_support_share', f'n/a: {why}'),)
    return (
        ('outside_support_share', f'{support.share:.4f}'),
        ('outside_support_checked', f'{support.outside} of {support.checked} samples'),
        ('outside_support_components', ', '.join(support.components) or 'none'),
    )


def count_key(what: str) -> str:
    """The /diagnostics key stem of an input problem: 'samples lost (gaps in the stamps)' ->
    'samples_lost' (with _last_period and _since_start: the count of this diagnostics period, the
    count since the node started).
    """
    return what.split(' (')[0].replace(' ', '_')


def diagnostics(
    active: ActiveCalibration,
    state: LiveState,
    node_name: str = 'balance_calibrator',
    now: _dt.datetime | None = None,
) -> list[StatusReport]:
    """Input health, calibration status and overload; levels OK / WARN / ERROR / STALE as
    DiagnosticStatus.
    """
    c = state.counters
    hardware = active.calibration.balance
    rate = c.period_received / state.period_s if state.period_s > 0 else 0.0
    level, problems = OK, []
    if state.last_sample_age_s is None:
        level, problems = STALE, ['no sample received yet']
    elif state.last_sample_age_s > state.stale_after_s:
        level, problems = STALE, [f'stale input: no sample for {state.last_sample_age_s:.1f} s']
    if c.period_rejected:
        level = max(level, WARN) if level != STALE else level
        problems.append(f'{c.period_rejected} NaN/inf samples rejected')
    if c.period_saturated:
        level = ERROR
        problems.append(
            f'{c.period_saturated} samples saturated (an output beyond '
            f'{", ".join(f"{v:.3g}" for v in active.output_range_mv)} '
            f'{active.calibration.output_unit}): not published'
        )
    if c.period_not_converged:
        level = ERROR
        problems.append(
            f"{c.period_not_converged} samples where the {active.model_name} model's Newton "
            f'iteration (AIAA R-091) did not converge: not published'
        )
    if c.period_out_of_envelope:
        level = max(level, WARN) if level != STALE else level
        problems.append(f'{c.period_out_of_envelope} samples outside the calibrated envelope')
    for what, total, period in state.input_problems:
        if period:
            level = max(level, WARN) if level != STALE else level
            # both counts, named: this period's (as the other counts here) and the total
            problems.append(
                f'{period} {what} in the last {state.period_s:.1f} s ({total} since start)'
            )
    input_values = (
        ('input_rate_hz', f'{rate:.1f}'),
        (
            'last_sample_age_s',
            'never' if state.last_sample_age_s is None else f'{state.last_sample_age_s:.3f}',
        ),
        (
            'stale',
            str(state.last_sample_age_s is None or state.last_sample_age_s > state.stale_after_s),
        ),
        ('samples_received', str(c.received)),
        ('wrenches_published', str(c.published)),
        ('rejected_nonfinite', str(c.rejected_nonfinite)),
        ('saturated', str(c.saturated)),
        ('newton_not_converged', str(c.not_converged)),
        ('out_of_envelope', str(c.out_of_envelope)),
        ('envelope', ', '.join(f'{k}={v:.4g}' for k, v in zip(COMPONENTS, active.envelope))),
        *(
            (f'{count_key(what)}_{window}', str(count))
            for what, total, period in state.input_problems
            for window, count in (('last_period', period), ('since_start', total))
        ),
        *state.input_values,
    )
    reports = [
        StatusReport(
            level,
            f'{node_name}: input',
            '; '.join(problems) or f'{rate:.1f} Hz',
            hardware,
            input_values,
        )
    ]

    cal = active.calibration
    age = active.age_days(now)
    sigma = ', '.join(f'{k}={float(v):.3f}' for k, v in cal.sigma_pct_fs.items()) or 'unknown'
    inputs = []
    for needed in active.requires:
        if needed == 'temperature':
            fresh = (
                state.temperature_age_s is not None
                and state.temperature_age_s <= state.stale_after_s
            )
            inputs.append(
                (
                    needed,
                    'fresh'
                    if fresh
                    else 'missing'
                    if state.temperature_age_s is None
                    else f'stale ({state.temperature_age_s:.1f} s)',
                )
            )
        else:
            inputs.append((needed, 'fresh' if state.last_sample_age_s is not None else 'missing'))
    support = state.support
    outside_support = support is not None and bool(support.share)
    cal_level = WARN if state.fallback_reason or state.tare_refused or outside_support else OK
    absent = active.absent_components
    message = (
        f'{active.model_name} model, {active.installation.name} installation'
        + (
            f'; {6 - len(absent)}-component calibration: {", ".join(absent)} absent '
            f'(published as 0, uncertainty NaN)'
            if absent
            else ''
        )
        + (
            f'; FALLBACK to {active.base_name}: {state.fallback_reason}'
            if state.fallback_reason
            else ''
        )
    )
    if outside_support:
        assert support is not None and support.share is not None
        message += (
            f"; {100 * support.share:.1f} % of the last period's samples outside the "
            f"calibration's support ({', '.join(support.components)}): extrapolated"
        )
    if state.tare_refused:
        message += (
            f'; zero and tare NOT restored ({state.tare_refused}): take ~/zero and ~/tare again'
        )
    zero = state.tare_zero_mv
    cal_values = (
        ('calibration_file', active.source),
        ('model', active.model_name),
        ('model_requested', active.requested_model),
        ('model_in_use', active.base_name if state.fallback_reason else active.model_name),
        ('fallback_reason', state.fallback_reason or 'none'),
        ('installation', f'{active.installation.name} ({active.installation.spec})'),
        ('components', ', '.join(cal.components)),
        ('output_unit', cal.output_unit),
        ('absent_components', ', '.join(absent) or 'none'),
        ('fitted_at', cal.fitted_at or 'unknown (memo matrices)'),
        ('age_days', 'unknown' if age is None else f'{age:.2f}'),
        ('sigma_pct_fs', sigma),
        ('requires', ', '.join(active.requires) or 'none'),
        ('inputs', ', '.join(f'{k}: {v}' for k, v in inputs) or 'bridge outputs only'),
        (
            'zero_mv',
            'none'
            if zero is None
            else ', '.join(
                f'{b}={zero[BRIDGE_OUTPUTS.index(b)]:+.5f}' for b in cal.bridge_outputs
            ),
        ),
        (
            'tare_load',
            'none'
            if state.tare_load is None
            else f'{describe_loads(state.tare_load, active)} (tunnel axes)',
        ),
        ('tare_file', state.tare_source or 'none'),
        ('tare_not_restored', state.tare_refused or 'none'),
        ('lowpass_hz', f'{state.lowpass_hz:g}' if state.lowpass_hz else 'off'),
        ('refit_running', str(state.refit_running)),
        *support_values(support),
    )
    reports.append(
        StatusReport(cal_level, f'{node_name}: calibration', message, hardware, cal_values)
    )
    if state.overload is None:
        reports.append(
            StatusReport(
                OK, f'{node_name}: overload', 'no overload', hardware, state.overload_values
            )
        )
    else:
        reports.append(
            StatusReport(
                ERROR,
                f'{node_name}: overload',
                f'OVERLOAD: {", ".join(state.overload)} beyond the rated load limit',
                hardware,
                state.overload_values,
            )
        )
    return reports
