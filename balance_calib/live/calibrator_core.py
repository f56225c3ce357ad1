"""What `balance_calibrator` computes, without rclpy: raw bridge outputs (mV) -> wrench in tunnel axes.

Per sample (or a batch of samples as one array):

1. reject samples with a NaN or infinite output (nothing is published for them);
2. subtract the tare: the mean bridge outputs of a wind-off window (`TareWindow`), mV. Outputs are
   measured from that zero, which is why the wind-on model drops its constant terms (TM-663
   §10.1: zero outputs must mean zero load). The tare is in the output domain, not in loads: the
   electrical zero is several % of full scale, and model(V + z) - model(z) != model(V) for the
   quadratic and cubic models, whereas model(V + z - z) = model(V);
3. loads in balance calibration axes from the active model without its constants;
4. flag loads beyond `envelope_margin` x capacity: the model is extrapolating there;
5. turn the loads into the tunnel axes of the installation, TM-663 §10.2 (eqs. (50)-(85)).

Step 3 then 5 is the memo's substitution: eqs. (50)-(55) evaluate the calibration-axis model on
outputs written in tunnel axes and map the result back, `to_tunnel(model(from_tunnel(V_tunnel)))`;
the bridges deliver calibration-axis outputs, so here it is `to_tunnel(model(V))` (see
`tunnel_axes.py`).

Models with variables besides the bridge outputs (Calibration.requires(): 'temperature',
'load_history') get them from the live inputs; when one is missing or stale the calibration's base
model runs instead, and the result says why (`WrenchBatch.fallback_reason`).
"""
from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..calibration_file import Calibration, ConfigError
from ..model.balance_model import BalanceModel
from ..model.terms import power_products
from ..tunnel_axes import Installation, parse_installation
from ..units import BRIDGE_OUTPUTS, COMPONENTS

MODEL_CHOICES = ('linear', 'quadratic', 'cubic', 'adopted')
DEFAULT_ENVELOPE_MARGIN = 1.1
UNITS = ('N', 'N', 'N', 'N·m', 'N·m', 'N·m')

# diagnostic_msgs/DiagnosticStatus levels, repeated here so the core needs no ROS messages
OK, WARN, ERROR = 0, 1, 2


def six_axis_loads(model: BalanceModel, outputs_mv, extra=None) -> np.ndarray:
    """Loads (N, 6) in FX..MZ order from the six raw channels (N, 6), whatever channels the model uses.

    A one-channel thrust stand (inputs FXV, component FX) reads force.x and fills F_X only.
    """
    outputs = np.atleast_2d(np.asarray(outputs_mv, dtype=float))
    columns = [BRIDGE_OUTPUTS.index(name) for name in model.inputs]
    loads = np.zeros((outputs.shape[0], 6))
    loads[:, [COMPONENTS.index(c) for c in model.components]] = model.loads(outputs[:, columns], extra)
    return loads


def six_axis(values, names, fill: float) -> np.ndarray:
    """A per-component vector over `names` spread onto FX..MZ, `fill` where a component is absent."""
    result = np.full(6, fill, dtype=float)
    result[[COMPONENTS.index(n) for n in names]] = np.asarray(values, dtype=float)
    return result


# --- the active calibration -------------------------------------------------------------------
@dataclass(frozen=True)
class ActiveCalibration:
    """A calibration made ready for wind-on use: constant-free models, axes and envelope."""

    calibration: Calibration
    source: str                     # file it was read from (for messages)
    requested_model: str            # the `model` parameter: 'adopted', 'cubic', ...
    model_name: str                 # the key of the model in calibration.models
    model: BalanceModel             # without constant terms (§10.1)
    requires: tuple[str, ...]       # live inputs it needs: 'temperature', 'load_history'
    base_name: str                  # the model that runs when an input is missing
    base_model: BalanceModel        # without constant terms
    installation: Installation
    envelope: np.ndarray            # (6,) |load| above this (N, N·m) is outside the calibrated range

    @cached_property
    def plan(self):
        """What one sample needs, precomputed: input columns, component slots, powers, coefficients."""
        names, plain, absolute, has_absolute = self.model._exponents
        columns = np.array([BRIDGE_OUTPUTS.index(v) for v in self.model.inputs])
        order = [self.model.inputs.index(v) for v in names if v in self.model.inputs]
        positions = np.array([COMPONENTS.index(c) for c in self.model.components])
        return columns[order], positions, plain, absolute if has_absolute else None, \
            np.array(self.model.coefficients)

    @property
    def capacity(self) -> np.ndarray:
        """(6,) full scale per component FX..MZ (inf for components the calibration lacks)."""
        return six_axis(self.calibration.capacity, self.calibration.components, np.inf)

    def age_days(self, now: _dt.datetime | None = None) -> float | None:
        fitted = self.calibration.fitted_datetime
        if fitted is None:
            return None
        now = now or _dt.datetime.now(_dt.timezone.utc)
        if fitted.tzinfo is None:
            fitted = fitted.replace(tzinfo=_dt.timezone.utc)
        return (now - fitted).total_seconds() / 86400.0


def activate(calibration: Calibration, model: str = 'adopted', installation: str | Installation = 'upright',
             envelope_margin: float = DEFAULT_ENVELOPE_MARGIN, source: str = '') -> ActiveCalibration:
    """Check that `model` and `installation` make sense for `calibration` and prepare it.

    Raises ConfigError (model missing from the calibration) or ValueError (installation, margin).
    """
    if not isinstance(installation, Installation):
        installation = parse_installation(installation)
    if not np.isfinite(envelope_margin) or envelope_margin <= 0:
        raise ValueError(f'envelope_margin must be a positive number, not {envelope_margin}')
    chosen = calibration.model(model)            # ConfigError names the models it has
    model_name = calibration.adopted if model in ('adopted', '') else model
    requires = calibration.requires(model_name)
    base_name = calibration.base_model if calibration.base_model in calibration.models else model_name
    base = calibration.models[base_name]
    if base.extra_variables:                      # a base that needs inputs itself is no fallback
        base_name, base = model_name, chosen
    return ActiveCalibration(calibration, source, model, model_name, chosen.without_constant(), requires,
                             base_name, base.without_constant(), installation,
                             float(envelope_margin) * six_axis(calibration.capacity, calibration.components, np.inf))


# --- live extra inputs ------------------------------------------------------------------------
@dataclass
class LoadHistory:
    """Whether the load on each component last rose (+1) or fell (-1), for hysteresis models.

    A change counts once it exceeds `deadband_fraction` of capacity, so noise does not flip it.
    Starts at +1 (rising), as the simulated balance does.
    """

    capacity: np.ndarray
    deadband_fraction: float = 0.005
    reference: np.ndarray | None = None
    direction: np.ndarray = field(default_factory=lambda: np.ones(6))

    def update(self, loads: np.ndarray) -> np.ndarray:
        """loads (N, 6) in time order -> direction (N, 6) after each sample."""
        loads = np.atleast_2d(loads)
        deadband = self.deadband_fraction * np.asarray(self.capacity, dtype=float)
        out = np.empty_like(loads)
        for k, row in enumerate(loads):   # a sequential state machine: inherently per sample
            if self.reference is None:
                self.reference = row.copy()
            change = row - self.reference
            moved = np.abs(change) > deadband
            self.direction = np.where(moved, np.sign(change), self.direction)
            self.reference = np.where(moved, row, self.reference)
            out[k] = self.direction
        return out


def _extra_variables(model: BalanceModel, n: int, temperature_c: np.ndarray | None,
                     reference_temperature_c: float | None, direction: np.ndarray | None) -> dict | str:
    """The model's non-output variables, or a string saying which one is unavailable."""
    extra = {}
    for variable in model.extra_variables:
        if variable in ('dT', 'dT2'):
            if temperature_c is None or not np.all(np.isfinite(temperature_c)):
                return 'temperature input missing or stale'
            if reference_temperature_c is None:
                return 'calibration has no reference_temperature_c'
            d_t = np.broadcast_to(np.asarray(temperature_c, float) - reference_temperature_c, (n,))
            extra[variable] = d_t if variable == 'dT' else d_t ** 2
        elif variable.startswith('dir_') and variable[4:] in COMPONENTS:
            if direction is None:
                return 'load history not available'
            extra[variable] = np.broadcast_to(direction, (n, 6))[:, COMPONENTS.index(variable[4:])]
        else:
            return f'no live input provides model variable {variable!r}'
    return extra


# --- samples -> wrench ------------------------------------------------------------------------
@dataclass(frozen=True)
class WrenchBatch:
    accepted: np.ndarray            # (N,) False for samples with a NaN/inf output (not published)
    loads_balance: np.ndarray       # (N, 6) tared loads, balance axes, N / N·m (NaN if rejected)
    wrench_tunnel: np.ndarray       # (N, 6) the same in tunnel axes (what /balance/wrench carries)
    out_of_envelope: np.ndarray     # (N,) a load beyond the envelope (published, but flagged)
    model_used: str
    fallback_reason: str = ''       # why the base model ran instead of the requested one ('' = it did not)


def model_loads(active: ActiveCalibration, outputs_mv, *, temperature_c=None,
                load_direction=None) -> tuple[np.ndarray, str, str]:
    """Balance-axis loads (N, 6) of finite, tared outputs (N, 6); also the model used and why a fallback."""
    outputs = np.atleast_2d(np.asarray(outputs_mv, dtype=float))
    n = outputs.shape[0]
    model, name, reason = active.model, active.model_name, ''
    extra = _extra_variables(model, n, None if temperature_c is None else np.asarray(temperature_c, float),
                             active.calibration.reference_temperature_c, load_direction)
    if isinstance(extra, str):
        model, name, reason = active.base_model, active.base_name, extra
        extra = _extra_variables(model, n, None, None, load_direction)
        if isinstance(extra, str):      # the base model needs inputs too: nothing sensible to run
            raise ConfigError(f'{active.source}: neither {active.model_name} nor {active.base_name} '
                              f'can run: {reason}')
    return six_axis_loads(model, outputs, extra or None), name, reason


def compute_wrench(active: ActiveCalibration, outputs_mv, *, zero_mv=None, temperature_c=None,
                   load_direction=None, tare_temperature_c=None, tare_direction=None) -> WrenchBatch:
    """Raw outputs (N, 6) mV, tare zero_mv (6,) -> wrench in tunnel axes (N, 6); see the module docstring."""
    outputs = np.atleast_2d(np.asarray(outputs_mv, dtype=float))
    if outputs.shape[0] == 1 and not active.model.extra_variables:
        return _one_plain_sample(active, outputs, zero_mv)
    accepted = np.all(np.isfinite(outputs), axis=1)
    tared = outputs - (np.zeros(6) if zero_mv is None else np.asarray(zero_mv, dtype=float))
    loads = np.full(outputs.shape, np.nan)
    name, reason = active.model_name, ''
    if accepted.any():
        temps = None if temperature_c is None else np.broadcast_to(np.asarray(temperature_c, float),
                                                                    (len(outputs),))[accepted]
        direction = None if load_direction is None else np.broadcast_to(load_direction, outputs.shape)[accepted]
        loads[accepted], name, reason = model_loads(active, tared[accepted], temperature_c=temps,
                                                    load_direction=direction)
        if zero_mv is not None and active.model.extra_variables and name == active.model_name:
            # The tare zeroed the outputs at the temperature and load direction of its moment; what
            # the model's pure temperature / direction terms gave then belongs to that zero too, so
            # the output reads 0 there and those terms act on the change since the tare.
            offset, offset_name, _ = model_loads(
                active, np.zeros((1, 6)),
                temperature_c=None if tare_temperature_c is None else np.array([tare_temperature_c], float),
                load_direction=None if tare_direction is None else np.atleast_2d(tare_direction))
            if offset_name == name:
                loads[accepted] -= offset[0]
    wrench = active.installation.to_tunnel(loads)          # TM-663 §10.2
    with np.errstate(invalid='ignore'):
        outside = accepted & np.any(np.abs(loads) > active.envelope, axis=1)
    return WrenchBatch(accepted, loads, wrench, outside, name, reason)


def _one_plain_sample(active: ActiveCalibration, outputs: np.ndarray, zero_mv) -> WrenchBatch:
    """compute_wrench for the live path: one sample, a model of the bridge outputs only (~10 µs)."""
    columns, positions, plain, absolute, coefficients = active.plan
    tared = outputs[0] if zero_mv is None else outputs[0] - zero_mv
    values = tared[columns]
    loads = np.zeros((1, 6))
    accepted = bool(np.isfinite(values).all() and np.isfinite(outputs).all())
    if not accepted:
        loads[:] = np.nan
        return WrenchBatch(np.array([False]), loads, loads.copy(), np.array([False]), active.model_name)
    design = power_products(values[None, :], plain, absolute)[0]
    loads[0, positions] = coefficients @ design
    outside = bool((np.abs(loads[0]) > active.envelope).any())
    return WrenchBatch(np.array([True]), loads, active.installation.to_tunnel(loads), np.array([outside]),
                       active.model_name)


# --- tare -------------------------------------------------------------------------------------
def tare_zero(outputs_mv) -> np.ndarray:
    """The zero a tare subtracts: mean bridge outputs (6,) mV over a wind-off window (N, 6)."""
    return np.mean(np.atleast_2d(np.asarray(outputs_mv, dtype=float)), axis=0)


@dataclass
class TareWindow:
    """Collects the next `samples` accepted samples after ~/tare."""

    samples: int
    outputs_mv: list = field(default_factory=list)

    def __post_init__(self):
        if int(self.samples) < 1:
            raise ValueError(f'tare needs at least one sample, not {self.samples}')

    def add(self, outputs_mv) -> bool:
        """Add accepted raw samples (N, 6) mV; True once the window is full (the rest is ignored)."""
        outputs = np.atleast_2d(np.asarray(outputs_mv, dtype=float))
        self.outputs_mv.extend(outputs[:max(0, self.samples - len(self.outputs_mv))])
        return self.complete

    @property
    def complete(self) -> bool:
        return len(self.outputs_mv) >= self.samples

    @property
    def zero_mv(self) -> np.ndarray:
        return tare_zero(np.array(self.outputs_mv))


def describe_tare(zero_mv, active: ActiveCalibration) -> str:
    """The zero subtracted, per bridge output in mV, and the load it stands for in tunnel axes."""
    zero = np.asarray(zero_mv, dtype=float)
    equivalent = active.installation.to_tunnel(six_axis_loads(active.base_model, zero[None, :])[0]) \
        if not active.base_model.extra_variables else np.full(6, np.nan)
    outputs = ', '.join(f'{c}={v:+.5f} mV' for c, v in zip(active.calibration.bridge_outputs, zero))
    loads = ', '.join(f'{c}={v:+.3f} {u}' for c, v, u in zip(COMPONENTS, equivalent, UNITS))
    return (f'{outputs} (the load these outputs read as, {active.installation.name} tunnel axes, '
            f'{active.base_name} model: {loads})')


# --- diagnostics ------------------------------------------------------------------------------
@dataclass
class InputCounters:
    """Counts since start and since the last diagnostics report."""

    received: int = 0
    published: int = 0
    rejected_nonfinite: int = 0
    out_of_envelope: int = 0
    period_received: int = 0
    period_rejected: int = 0
    period_out_of_envelope: int = 0

    def count(self, batch: WrenchBatch) -> None:
        if len(batch.accepted) == 1:      # the live path: one sample, no numpy reductions
            n, ok, out = 1, int(bool(batch.accepted[0])), int(bool(batch.out_of_envelope[0]))
        else:
            n, ok, out = len(batch.accepted), int(batch.accepted.sum()), int(batch.out_of_envelope.sum())
        self.received += n
        self.period_received += n
        self.published += ok
        self.rejected_nonfinite += n - ok
        self.period_rejected += n - ok
        self.out_of_envelope += out
        self.period_out_of_envelope += out

    def start_period(self) -> None:
        self.period_received = self.period_rejected = self.period_out_of_envelope = 0


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
    last_sample_age_s: float | None            # None: no sample yet
    stale_after_s: float
    temperature_age_s: float | None
    fallback_reason: str
    tare_zero_mv: np.ndarray | None            # None: never tared
    refit_running: bool = False


def diagnostics(active: ActiveCalibration, state: LiveState, node_name: str = 'balance_calibrator',
                now: _dt.datetime | None = None) -> list[StatusReport]:
    """Input health and calibration status; levels OK / WARN / ERROR as DiagnosticStatus has them."""
    c = state.counters
    hardware = active.calibration.balance
    rate = c.period_received / state.period_s if state.period_s > 0 else 0.0
    level, problems = OK, []
    if state.last_sample_age_s is None:
        level, problems = WARN, ['no sample received yet']
    elif state.last_sample_age_s > state.stale_after_s:
        level, problems = WARN, [f'stale input: no sample for {state.last_sample_age_s:.1f} s']
    if c.period_rejected:
        level = max(level, WARN)
        problems.append(f'{c.period_rejected} NaN/inf samples rejected')
    if c.period_out_of_envelope:
        level = max(level, WARN)
        problems.append(f'{c.period_out_of_envelope} samples outside the calibrated envelope')
    input_values = (
        ('input_rate_hz', f'{rate:.1f}'),
        ('last_sample_age_s', 'never' if state.last_sample_age_s is None else f'{state.last_sample_age_s:.3f}'),
        ('stale', str(state.last_sample_age_s is None or state.last_sample_age_s > state.stale_after_s)),
        ('samples_received', str(c.received)),
        ('wrenches_published', str(c.published)),
        ('rejected_nonfinite', str(c.rejected_nonfinite)),
        ('out_of_envelope', str(c.out_of_envelope)),
        ('envelope', ', '.join(f'{k}={v:.4g}' for k, v in zip(COMPONENTS, active.envelope))),
    )
    reports = [StatusReport(level, f'{node_name}: input', '; '.join(problems) or f'{rate:.1f} Hz',
                            hardware, input_values)]

    cal = active.calibration
    age = active.age_days(now)
    sigma = ', '.join(f'{k}={float(v):.3f}' for k, v in cal.sigma_pct_fs.items()) or 'unknown'
    inputs = []
    for needed in active.requires:
        if needed == 'temperature':
            fresh = state.temperature_age_s is not None and state.temperature_age_s <= state.stale_after_s
            inputs.append((needed, 'fresh' if fresh else 'missing' if state.temperature_age_s is None else
                           f'stale ({state.temperature_age_s:.1f} s)'))
        else:
            inputs.append((needed, 'fresh' if state.last_sample_age_s is not None else 'missing'))
    cal_level = WARN if state.fallback_reason else OK
    message = (f'{active.model_name} model, {active.installation.name} installation'
               + (f'; FALLBACK to {active.base_name}: {state.fallback_reason}' if state.fallback_reason else ''))
    tare = state.tare_zero_mv
    cal_values = (
        ('calibration_file', active.source),
        ('model', active.model_name),
        ('model_requested', active.requested_model),
        ('model_in_use', active.base_name if state.fallback_reason else active.model_name),
        ('fallback_reason', state.fallback_reason or 'none'),
        ('installation', f'{active.installation.name} ({active.installation.spec})'),
        ('fitted_at', cal.fitted_at or 'unknown (memo matrices)'),
        ('age_days', 'unknown' if age is None else f'{age:.2f}'),
        ('sigma_pct_fs', sigma),
        ('requires', ', '.join(active.requires) or 'none'),
        ('inputs', ', '.join(f'{k}: {v}' for k, v in inputs) or 'bridge outputs only'),
        ('tare_zero_mv', 'none' if tare is None else
         ', '.join(f'{c}={v:+.5f}' for c, v in zip(cal.bridge_outputs, tare))),
        ('refit_running', str(state.refit_running)),
    )
    reports.append(StatusReport(cal_level, f'{node_name}: calibration', message, hardware, cal_values))
    return reports


def parse_reliability(value: str) -> str:
    key = str(value).strip().lower().replace('-', '_')
    if key not in ('reliable', 'best_effort'):
        raise ValueError(f'input_reliability must be reliable or best_effort, not {value!r}')
    return key
