"""What `balance_calibrator` computes, without rclpy: raw bridge outputs (mV) -> wrench in tunnel
axes.

Per sample (or a batch of samples as one array):

1. reject samples with a NaN or infinite output, or an output beyond the bridge's range
   (`output_range_factor` x rated output: saturated, the model would extrapolate into nonsense);
   nothing is published for them;
2. subtract the electrical zero (`~/zero`: mean bridge outputs with nothing on the balance), mV,
   in output space as TM-663 §5(4) does with its zero points;
3. loads in balance calibration axes from the active model without its constants (§10.1) on those
   full outputs: what the balance carries (model weight included); flag loads beyond
   `envelope_margin` x capacity (the model is extrapolating there). A direct (TM-663) model is a
   polynomial of the outputs, evaluated here from a precomputed plan; an iterative (AIAA R-091)
   model gives outputs from loads and is inverted per sample by its own vectorised Newton iteration
   (`IterativeModel.loads_and_status`): a sample where Newton does not converge is not published
   and is counted (`not_converged`), like a saturated one;
4. subtract the tare load (`~/tare`: the mean loads of a wind-off window, N and N·m) in load
   space. The calibration is nonlinear, so model(V) - model(V0) != model(V - V0): a tare taken
   in output space would be off by up to several % FS with the model's weight on the balance;
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

from dataclasses import dataclass, field
import datetime as _dt

import numpy as np

from ..calibration_file import ConfigError
from ..model.active_calibration import ActiveCalibration, six_axis_loads
from ..model.balance_model import BalanceModel
from ..model.inverse import InverseDidNotConverge
from ..units import BRIDGE_OUTPUTS, COMPONENTS
from .support_share import SupportShare

UNITS = ('N', 'N', 'N', 'N·m', 'N·m', 'N·m')

# diagnostic_msgs/DiagnosticStatus levels, repeated here so the core needs no ROS messages
OK, WARN, ERROR, STALE = 0, 1, 2, 3


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
        """Loads (N, 6) in time order -> direction (N, 6) after each sample."""
        loads = np.atleast_2d(loads)
        deadband = self.deadband_fraction * np.asarray(self.capacity, dtype=float)
        out = np.empty_like(loads)
        for k, row in enumerate(loads):  # a sequential state machine: inherently per sample
            if self.reference is None:
                self.reference = row.copy()
            change = row - self.reference
            moved = np.abs(change) > deadband
            self.direction = np.where(moved, np.sign(change), self.direction)
            self.reference = np.where(moved, row, self.reference)
            out[k] = self.direction
        return out


def _extra_variables(
    model: BalanceModel,
    n: int,
    temperature_c: np.ndarray | None,
    reference_temperature_c: float | None,
    direction: np.ndarray | None,
) -> dict | str:
    """The model's non-output variables, or a string saying which one is unavailable."""
    extra = {}
    for variable in model.extra_variables:
        if variable in ('dT', 'dT2'):
            if temperature_c is None or not np.all(np.isfinite(temperature_c)):
                return 'temperature input missing or stale'
            if reference_temperature_c is None:
                return 'calibration has no reference_temperature_c'
            d_t = np.broadcast_to(np.asarray(temperature_c, float) - reference_temperature_c, (n,))
            extra[variable] = d_t if variable == 'dT' else d_t**2
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
    accepted: np.ndarray  # (N,) published; False for NaN/inf or saturated samples
    # (N, 6) loads after the tare load, balance axes, N / N·m (NaN if rejected)
    loads_balance: np.ndarray
    wrench_tunnel: np.ndarray  # (N, 6) the same in tunnel axes (what /balance/wrench carries)
    out_of_envelope: np.ndarray  # (N,) a load beyond the envelope (published, but flagged)
    model_used: str
    # why the base model ran instead of the requested one ('' = it did not)
    fallback_reason: str = ''
    loads_total: np.ndarray | None = None  # (N, 6) before the tare load: what the balance carries
    # (N,) an output beyond the bridge's range (or a non-finite load)
    saturated: np.ndarray | None = None
    # (N,) iterative model: Newton did not converge (not published)
    not_converged: np.ndarray | None = None
    # (M, n_terms) the design rows of the M accepted samples (model term order), for their
    # uncertainty; None for models with inputs besides the outputs, iterative ones, or a batch
    # with an overflow
    design_row: np.ndarray | None = None

    @property
    def nonfinite(self) -> np.ndarray:
        rejected = ~self.accepted & ~self.saturated
        return rejected if self.not_converged is None else rejected & ~self.not_converged


def model_loads(
    active: ActiveCalibration, outputs_mv, *, temperature_c=None, load_direction=None
) -> tuple[np.ndarray, str, str]:
    """Balance-axis loads (N, 6) of finite outputs (N, 6); also the model used and why a
    fallback.
    """
    outputs = np.atleast_2d(np.asarray(outputs_mv, dtype=float))
    n = outputs.shape[0]
    if not active.model.extra_variables:
        return _plain_loads(active, outputs)[0], active.model_name, ''
    model, name, reason = active.model, active.model_name, ''
    extra = _extra_variables(
        model,
        n,
        None if temperature_c is None else np.asarray(temperature_c, float),
        active.calibration.reference_temperature_c,
        load_direction,
    )
    if isinstance(extra, str):
        model, name, reason = active.base_model, active.base_name, extra
        extra = _extra_variables(model, n, None, None, load_direction)
        if isinstance(extra, str):  # the base model needs inputs too: nothing sensible to run
            raise ConfigError(
                f'{active.source}: neither {active.model_name} nor {active.base_name} '
                f'can run: {reason}'
            )
    return six_axis_loads(model, outputs, extra or None), name, reason


def _plain_loads(
    active: ActiveCalibration, outputs: np.ndarray
) -> tuple[np.ndarray, np.ndarray | None]:
    """A model of the bridge outputs only: a direct model as one power-product and one matrix
    product (TM-663 eqs. (1)-(18)); an iterative model by its vectorised Newton iteration (AIAA
    R-091), NaN rows where it did not converge. Loads (N, 6) and, for a direct model, its design
    rows (N, n_terms) (None for an iterative one).
    """
    columns, positions, plain, absolute, _ = active.plan
    if plain is None:
        loads = np.zeros((outputs.shape[0], 6))
        loads[:, positions] = active.model.loads_and_status(outputs[:, columns])[0]
        return loads, None
    # the factors of every term gathered from [outputs, |outputs|, 1] and multiplied
    factors = np.empty((outputs.shape[0], 13))
    factors[:, :6] = outputs
    if absolute is not None:
        np.abs(outputs, out=factors[:, 6:12])
    factors[:, 12] = 1.0
    design = np.multiply.reduce(factors[:, active.design_index], axis=2)
    return design @ active.coefficients_six_t, design  # zero columns: components it lacks


def _rows(outputs_mv) -> np.ndarray:
    """Samples as a float array (N, 6), without a copy when they are one already."""
    if type(outputs_mv) is np.ndarray and outputs_mv.ndim == 2 and outputs_mv.dtype == float:
        return outputs_mv
    return np.atleast_2d(np.asarray(outputs_mv, dtype=float))


def compute_wrench(
    active: ActiveCalibration,
    outputs_mv,
    *,
    zero_mv=None,
    tare_load=None,
    temperature_c=None,
    load_direction=None,
    zero_temperature_c=None,
    zero_direction=None,
) -> WrenchBatch:
    """Raw outputs (N, 6) mV -> wrench in tunnel axes (N, 6); see the module docstring.

    zero_mv (6,): the electrical zero, subtracted from the outputs; tare_load (6,) N / N·m, balance
    axes: the tare load, subtracted from the loads. zero_temperature_c / zero_direction: the
    conditions when the zero was taken (for models with temperature or load-direction terms).
    """
    outputs = _rows(outputs_mv)
    with np.errstate(invalid='ignore', over='ignore'):  # beyond float range: flagged below
        return _compute_wrench(
            active,
            outputs,
            zero_mv,
            tare_load,
            temperature_c,
            load_direction,
            zero_temperature_c,
            zero_direction,
        )


def _compute_wrench(
    active,
    outputs,
    zero_mv,
    tare_load,
    temperature_c,
    load_direction,
    zero_temperature_c,
    zero_direction,
) -> WrenchBatch:
    n = len(outputs)
    # the whole batch checked at once (at 1 kHz a batch is one sample): per-sample masks only
    # for a batch where some output is not finite or beyond the bridge's range
    everyone = bool(np.logical_and.reduce(np.abs(outputs) <= active.output_limit_mv, axis=None))
    if everyone:
        saturated = np.zeros(n, dtype=bool)
        accepted = ~saturated
    else:
        finite = active.inputs_finite(outputs)  # channels the calibration does not read aside
        saturated = finite & (np.abs(outputs) > active.output_range_mv).any(axis=1)
        accepted = finite & ~saturated
        everyone = bool(accepted.all())
    zeroed = outputs if zero_mv is None else outputs - np.asarray(zero_mv, dtype=float)
    name, reason, design = active.model_name, '', None
    if everyone and not active.model.extra_variables:  # the outputs alone: design rows kept
        totals, design = _plain_loads(active, zeroed)
    elif everyone:
        totals, name, reason = _loads_with_zero(
            active,
            zeroed,
            temperature_c,
            load_direction,
            zero_mv,
            zero_temperature_c,
            zero_direction,
        )
    else:
        totals = np.full(outputs.shape, np.nan)
        if not active.model.extra_variables and accepted.any():
            totals[accepted], design = _plain_loads(active, zeroed[accepted])
        elif accepted.any():
            temps = (
                None
                if temperature_c is None
                else np.broadcast_to(np.asarray(temperature_c, float), (n,))[accepted]
            )
            direction = (
                None
                if load_direction is None
                else np.broadcast_to(load_direction, outputs.shape)[accepted]
            )
            totals[accepted], name, reason = _loads_with_zero(
                active,
                zeroed[accepted],
                temps,
                direction,
                zero_mv,
                zero_temperature_c,
                zero_direction,
            )
    not_converged = np.zeros(n, dtype=bool)
    if everyone and np.logical_and.reduce(np.abs(totals) <= active.envelope_limit, axis=None):
        outside = np.zeros(n, dtype=bool)  # every load finite and inside the envelope
    else:
        # finite outputs, loads beyond float range
        overflow = accepted & ~np.isfinite(totals).all(axis=1)
        if overflow.any():
            if active.iterative:  # finite outputs without loads: Newton did not converge there
                not_converged = overflow
            else:
                saturated = saturated | overflow
            accepted = accepted & ~overflow
            totals[overflow] = np.nan
            design = None  # its rows no longer match the published samples
        outside = accepted & np.any(np.abs(totals) > active.envelope, axis=1)
    loads = totals if tare_load is None else totals - np.asarray(tare_load, dtype=float)
    wrench = active.installation.to_tunnel(loads)  # TM-663 §10.2
    return WrenchBatch(
        accepted, loads, wrench, outside, name, reason, totals, saturated, not_converged, design
    )


def _loads_with_zero(
    active, zeroed, temperature_c, load_direction, zero_mv, zero_temperature_c, zero_direction
):
    loads, name, reason = model_loads(
        active, zeroed, temperature_c=temperature_c, load_direction=load_direction
    )
    if zero_mv is not None and active.model.extra_variables and name == active.model_name:
        # The zero removed the outputs at the temperature and load direction of its moment; what
        # the model's pure temperature / direction terms gave then belongs to that zero too, so
        # those terms act on the change since the zero.
        offset, offset_name, _ = model_loads(
            active,
            np.zeros((1, 6)),
            temperature_c=None
            if zero_temperature_c is None
            else np.array([zero_temperature_c], float),
            load_direction=None if zero_direction is None else np.atleast_2d(zero_direction),
        )
        if offset_name == name:
            loads = loads - offset[0]
    return loads, name, reason


# --- tare and zero ----------------------------------------------------------------------------
def tare_zero(outputs_mv) -> np.ndarray:
    """The electrical zero: mean bridge outputs (6,) mV over a window (N, 6) with nothing on the
    balance.
    """
    return np.mean(np.atleast_2d(np.asarray(outputs_mv, dtype=float)), axis=0)


@dataclass(frozen=True)
class Steadiness:
    """Whether a window of samples holds one load, judged against the window's own noise."""

    steady: bool
    reason: str  # '' when steady; else one line naming the component
    scatter_ratio: float  # worst std / noise over the components
    step_ratio: float  # worst |mean(second half) - mean(first half)| / noise


def check_steady(values, names, units, scale, max_ratio: float) -> Steadiness:
    """Values (N, k): a window of loads (or outputs); scale (k,) full scale per column.

    The noise σ of each column comes from successive differences (robust: 1.4826 x MAD / √2), which
    a ramp or a single step barely moves; floor 1e-5 x scale so noise-free data has a scale too.
    Not steady: std beyond max_ratio x σ (scatter), or the two halves' means apart by more than
    max_ratio x σ (a step or a ramp inside the window). For white noise of n samples the std is σ
    and the halves' difference has σ·2/√n, so a steady window passes at max_ratio = 3 or more.
    """
    values = np.atleast_2d(np.asarray(values, dtype=float))
    n = values.shape[0]
    scale = np.asarray(scale, dtype=float)
    if n < 4:
        return Steadiness(
            False,
            f'{n} samples cannot show whether the load is steady (at least 4)',
            np.inf,
            np.inf,
        )
    differences = np.diff(values, axis=0)
    mad = np.median(np.abs(differences - np.median(differences, axis=0)), axis=0)
    noise = np.maximum(
        1.4826 * mad / np.sqrt(2.0), 1e-5 * np.where(np.isfinite(scale), scale, 1.0)
    )
    scatter = np.std(values, axis=0) / noise
    step = np.abs(values[n // 2 :].mean(axis=0) - values[: n // 2].mean(axis=0)) / noise
    worst_scatter, worst_step = int(np.argmax(scatter)), int(np.argmax(step))
    if step[worst_step] > max_ratio:
        k = worst_step
        delta = values[n // 2 :, k].mean() - values[: n // 2, k].mean()
        return Steadiness(
            False,
            f'{names[k]} moved by {delta:+.4g} {units[k]} within the window '
            f'({step[k]:.0f}x its noise {noise[k]:.3g} {units[k]}): a load step or ramp',
            float(scatter.max()),
            float(step.max()),
        )
    if scatter[worst_scatter] > max_ratio:
        k = worst_scatter
        return Steadiness(
            False,
            f'{names[k]} scatters by {np.std(values[:, k]):.4g} {units[k]} '
            f'({scatter[k]:.1f}x its sample-to-sample noise {noise[k]:.3g} {units[k]})',
            float(scatter.max()),
            float(step.max()),
        )
    return Steadiness(True, '', float(scatter.max()), float(step.max()))


@dataclass
class TareWindow:
    """Collects the next `samples` accepted raw samples after ~/tare or ~/zero (kind 'tare' or
    'zero').
    """

    samples: int
    kind: str = 'tare'
    outputs_mv: list = field(default_factory=list)
    temperatures_c: list = field(default_factory=list)

    def __post_init__(self):
        if int(self.samples) < 1:
            raise ValueError(f'tare needs at least one sample, not {self.samples}')

    def add(self, outputs_mv, temperature_c: float | None = None) -> bool:
        """Add accepted raw samples (N, 6) mV; True once the window is full (the rest is
        ignored).
        """
        outputs = np.atleast_2d(np.asarray(outputs_mv, dtype=float))
        taken = outputs[: max(0, self.samples - len(self.outputs_mv))]
        self.outputs_mv.extend(taken)
        if temperature_c is not None and len(taken):
            self.temperatures_c.append(float(temperature_c))
        return self.complete

    @property
    def complete(self) -> bool:
        return len(self.outputs_mv) >= self.samples

    @property
    def zero_mv(self) -> np.ndarray:
        return tare_zero(np.array(self.outputs_mv))

    @property
    def temperature_c(self) -> float | None:
        return float(np.mean(self.temperatures_c)) if self.temperatures_c else None


@dataclass(frozen=True)
class TareResult:
    ok: bool
    message: str
    zero_mv: np.ndarray | None = None  # for kind 'zero'
    tare_load: np.ndarray | None = None  # for kind 'tare': balance axes, N / N·m
    # standard uncertainty of that mean (scatter / √n), balance axes
    tare_sigma: np.ndarray | None = None
    # the window's mean raw outputs (6,) mV, before the zero: what another calibration re-reads
    tare_outputs_mv: np.ndarray | None = None


def evaluate_window(
    window: TareWindow,
    active: ActiveCalibration,
    *,
    max_ratio: float,
    zero_mv=None,
    zero_temperature_c=None,
    zero_direction=None,
    load_direction=None,
) -> TareResult:
    """The zero (output space) or tare load (load space) of a full window, or why it is refused."""
    outputs = np.array(window.outputs_mv, dtype=float)
    n = len(outputs)
    if window.kind == 'zero':
        names = active.calibration.bridge_outputs
        columns = [BRIDGE_OUTPUTS.index(v) for v in names]
        units = (active.calibration.output_unit,) * len(names)
        steady = check_steady(
            outputs[:, columns],
            names,
            units,
            np.asarray(active.calibration.rated_output_mv, float),
            max_ratio,
        )
        if not steady.steady:
            return TareResult(
                False, f'zero refused: the window of {n} samples is not steady: {steady.reason}'
            )
        zero = tare_zero(outputs)
        if active.unused_inputs is not None:  # channels not read: no zero (finite, persisted)
            zero[active.unused_inputs] = 0.0
        return TareResult(
            True,
            f'zero: averaged {n} samples, steady (scatter {steady.scatter_ratio:.1f}x, step '
            f'{steady.step_ratio:.1f}x noise); electrical zero now subtracted: '
            f'{describe_zero(zero, active)}',
            zero_mv=zero,
        )
    batch = compute_wrench(
        active,
        outputs,
        zero_mv=zero_mv,
        temperature_c=window.temperature_c,
        load_direction=load_direction,
        zero_temperature_c=zero_temperature_c,
        zero_direction=zero_direction,
    )
    failed = int(np.count_nonzero(~np.isfinite(batch.loads_total).all(axis=1)))
    if failed:  # an iterative model's Newton iteration did not converge (or outputs saturated)
        return TareResult(
            False,
            f"tare refused: {failed} of the window's {n} samples give no load "
            f"(the {batch.model_used} model's Newton iteration did not converge or a bridge "
            f'saturated)',
        )
    components = active.calibration.components
    columns = [COMPONENTS.index(c) for c in components]
    loads = batch.loads_total[:, columns]
    units = tuple(UNITS[COMPONENTS.index(c)] for c in components)
    steady = check_steady(
        loads, components, units, np.asarray(active.calibration.capacity, float), max_ratio
    )
    if not steady.steady:
        return TareResult(
            False, f'tare refused: the window of {n} samples is not steady: {steady.reason}'
        )
    tare_load = np.mean(batch.loads_total, axis=0)
    mean_outputs = outputs.mean(axis=0)
    return TareResult(
        True,
        f'tare: averaged {n} samples, steady (scatter {steady.scatter_ratio:.1f}x, step '
        f'{steady.step_ratio:.1f}x noise); tare load now subtracted: '
        f'{describe_tare(tare_load, active)}; mean wind-off outputs: '
        + ', '.join(
            f'{b}={output_text(mean_outputs[BRIDGE_OUTPUTS.index(b)], active)}'
            for b in active.calibration.bridge_outputs
        )
        + (
            ''
            if zero_mv is not None
            else '; no electrical zero taken (~/zero with nothing on the '
            "balance): the calibration sees outputs measured from the bridges' own zero"
        ),
        tare_load=tare_load,
        tare_sigma=np.std(batch.loads_total, axis=0, ddof=1) / np.sqrt(n),
        tare_outputs_mv=mean_outputs,
    )


def output_text(value: float, active: ActiveCalibration) -> str:
    """A bridge output with its unit: mV to 5 decimals; counts, -, mV/V to 6 digits."""
    unit = active.calibration.output_unit
    return f'{value:+.5f} mV' if unit == 'mV' else f'{value:+.6g} {unit}'


def describe_loads(loads_balance, active: ActiveCalibration) -> str:
    """A load (6,) in balance axes, written per component in the installation's tunnel axes."""
    tunnel = active.installation.to_tunnel(np.asarray(loads_balance, dtype=float))
    return ', '.join(f'{c}={v:+.3f} {u}' for c, v, u in zip(COMPONENTS, tunnel, UNITS))


def describe_tare(tare_load, active: ActiveCalibration) -> str:
    """The tare load subtracted, N and N·m, in tunnel axes."""
    return (
        f'{describe_loads(tare_load, active)} ({active.installation.name} tunnel axes, '
        f'{active.model_name} model on the full outputs)'
    )


def describe_zero(zero_mv, active: ActiveCalibration) -> str:
    """The zero subtracted, per bridge output in mV, and the load it stands for in tunnel axes."""
    zero = np.asarray(zero_mv, dtype=float)
    try:
        equivalent = (
            six_axis_loads(active.base_model, zero[None, :])[0]
            if not active.base_model.extra_variables
            else np.full(6, np.nan)
        )
    except InverseDidNotConverge:  # an iterative model without a solution there: no number
        equivalent = np.full(6, np.nan)
    names = active.calibration.bridge_outputs
    outputs = ', '.join(
        f'{c}={output_text(v, active)}'
        for c, v in zip(names, zero[[BRIDGE_OUTPUTS.index(b) for b in names]])
    )
    return (
        f'{outputs} (the load these outputs read as, {active.installation.name} tunnel axes, '
        f'{active.base_name} model: {describe_loads(equivalent, active)})'
    )


# --- diagnostics ------------------------------------------------------------------------------
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


def parse_reliability(value: str) -> str:
    key = str(value).strip().lower().replace('-', '_')
    if key not in ('reliable', 'best_effort'):
        raise ValueError(f'input_reliability must be reliable or best_effort, not {value!r}')
    return key
