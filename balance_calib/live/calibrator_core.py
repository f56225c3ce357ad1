"""What `balance_calibrator` computes, without rclpy: raw bridge outputs (mV) -> wrench in tunnel axes.

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

import datetime as _dt
import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..calibration_file import Calibration, ConfigError
from ..model.balance_model import BalanceModel
from ..model.inverse import InverseDidNotConverge
from ..model.terms import power_products
from ..tunnel_axes import Installation, parse_installation
from ..units import BRIDGE_OUTPUTS, COMPONENTS

MODEL_CHOICES = ('linear', 'quadratic', 'cubic', 'adopted')
DEFAULT_ENVELOPE_MARGIN = 1.1
DEFAULT_OUTPUT_RANGE_FACTOR = 2.0
UNITS = ('N', 'N', 'N', 'N·m', 'N·m', 'N·m')

# diagnostic_msgs/DiagnosticStatus levels, repeated here so the core needs no ROS messages
OK, WARN, ERROR, STALE = 0, 1, 2, 3


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
    result[[COMPONENTS.index(n) if n in COMPONENTS else BRIDGE_OUTPUTS.index(n) for n in names]] = \
        np.asarray(values, dtype=float)
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
    output_range_mv: np.ndarray = field(default_factory=lambda: np.full(6, np.inf))
    # (6,) |raw output| above this (mV) is a saturated bridge (inf for channels the calibration lacks)

    @cached_property
    def iterative(self) -> bool:
        """The model is R-091's iterative form (outputs from loads, inverted by Newton per sample)."""
        return getattr(self.model, 'form', 'direct') == 'iterative'

    @cached_property
    def plan(self):
        """What one sample needs, precomputed: input columns, component slots, powers, coefficients.
        An iterative model has no polynomial of the outputs: columns and slots only (powers None)."""
        columns = np.array([BRIDGE_OUTPUTS.index(v) for v in self.model.inputs])
        positions = np.array([COMPONENTS.index(c) for c in self.model.components])
        if self.iterative:
            return columns, positions, None, None, None
        names, plain, absolute, has_absolute = self.model._exponents
        order = [self.model.inputs.index(v) for v in names if v in self.model.inputs]
        return columns[order], positions, plain, absolute if has_absolute else None, \
            np.array(self.model.coefficients)

    @cached_property
    def one_sample_terms(self) -> tuple[tuple[int, ...], ...] | None:
        """Per term, the raw-output columns to multiply (with repetition), for one sample in plain
        Python; None when a term has an absolute value or a power beyond 3 (then numpy's path), or
        for an iterative model."""
        columns, _, plain, absolute, _ = self.plan
        if plain is None or absolute is not None or plain.size == 0 or plain.max() > 3 or plain.min() < 0:
            return None
        return tuple(tuple(int(columns[v]) for v in range(plain.shape[1]) for _ in range(int(plain[t, v])))
                     for t in range(plain.shape[0]))

    @cached_property
    def one_sample_index(self) -> np.ndarray | None:
        """one_sample_terms as an (n_terms, width) index into the six outputs followed by a 1.0 (index 6):
        the design row of one sample is then one fancy index and one product."""
        terms = self.one_sample_terms
        if terms is None:
            return None
        width = max(len(t) for t in terms)
        return np.array([t + (6,) * (width - len(t)) for t in terms], dtype=np.intp)

    @cached_property
    def coefficients_six(self) -> np.ndarray:
        """(6, n_terms) the model's coefficients in FX..MZ rows (zero rows for components it lacks)."""
        _, positions, _, _, coefficients = self.plan
        six = np.zeros((6, coefficients.shape[1]))
        six[positions] = coefficients
        return six

    @cached_property
    def envelope_list(self) -> list[float]:
        return np.asarray(self.envelope, dtype=float).tolist()

    @cached_property
    def output_range_list(self) -> list[float]:
        return self.output_range_mv.tolist()

    @cached_property
    def unused_inputs(self) -> np.ndarray | None:
        """Columns of the six raw outputs that the calibration does not read (a 1-, 3- or 5-bridge
        calibration), None when it reads all six: their values, NaN included, change nothing."""
        used = [BRIDGE_OUTPUTS.index(b) for b in self.calibration.bridge_outputs]
        unused = [i for i in range(6) if i not in used]
        return np.array(unused, dtype=np.intp) if unused else None

    def inputs_finite(self, outputs: np.ndarray) -> np.ndarray:
        """(N,) True where every raw output the calibration reads is finite; outputs (N, 6)."""
        if self.unused_inputs is None:
            return np.isfinite(outputs).all(axis=1)
        used = np.isfinite(outputs)
        used[:, self.unused_inputs] = True
        return used.all(axis=1)

    @cached_property
    def absent_components(self) -> tuple[str, ...]:
        """Components of the published wrench (tunnel axes) that the calibration does not give
        (a 1-, 3- or 5-component balance): published as 0, their uncertainty NaN, never out of
        the envelope or overloaded."""
        present = set(self.calibration.components)
        return tuple(COMPONENTS[i] for i, p in enumerate(self.installation.permutation)
                     if COMPONENTS[p] not in present)

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
             envelope_margin: float = DEFAULT_ENVELOPE_MARGIN, source: str = '',
             output_range_factor: float = DEFAULT_OUTPUT_RANGE_FACTOR) -> ActiveCalibration:
    """Check that `model` and `installation` make sense for `calibration` and prepare it.

    Raises ConfigError (model missing from the calibration, capacities or rated outputs not
    positive finite numbers) or ValueError (installation, margin, range factor).
    """
    if not isinstance(installation, Installation):
        installation = parse_installation(installation)
    if not np.isfinite(envelope_margin) or not 0.5 <= envelope_margin <= 10.0:
        raise ValueError(f'envelope_margin must be between 0.5 and 10 (x capacity), not {envelope_margin}')
    if not np.isfinite(output_range_factor) or not 1.0 <= output_range_factor <= 100.0:
        raise ValueError(f'output_range_factor must be between 1 and 100 (x rated output), not {output_range_factor}')
    _check_channels(calibration, source)
    for what, values, names in (('capacity', calibration.capacity, calibration.components),
                                ('rated_output_mv', calibration.rated_output_mv, calibration.bridge_outputs)):
        bad = [f'{n}={v}' for n, v in zip(names, np.asarray(values, dtype=float)) if not (np.isfinite(v) and v > 0)]
        if bad:
            raise ConfigError(f'{source or calibration.balance}: {what} must be positive finite numbers '
                              f'({", ".join(bad)})')
    chosen = calibration.model(model)            # ConfigError names the models it has
    model_name = calibration.adopted if model in ('adopted', '') else model
    requires = calibration.requires(model_name)
    base_name = calibration.base_model if calibration.base_model in calibration.models else model_name
    base = calibration.models[base_name]
    if base.extra_variables:                      # a base that needs inputs itself is no fallback
        base_name, base = model_name, chosen
    return ActiveCalibration(calibration, source, model, model_name, chosen.without_constant(), requires,
                             base_name, base.without_constant(), installation,
                             float(envelope_margin) * six_axis(calibration.capacity, calibration.components, np.inf),
                             float(output_range_factor) * np.abs(six_axis(calibration.rated_output_mv,
                                                                          calibration.bridge_outputs, np.inf)))


def _check_channels(calibration: Calibration, source: str) -> None:
    """The live calibrator reads six raw channels (FXV..MZV in force.x..torque.z of balance/raw)
    and publishes six components (FX..MZ): a calibration under other names (a table's own
    symbols) or with more bridge outputs than that (an 8-channel sensor) is refused in one line."""
    where = source or calibration.balance
    for what, names, known, verb in (
            ('components', calibration.components, COMPONENTS, 'publishes'),
            ('bridge outputs', calibration.bridge_outputs, BRIDGE_OUTPUTS, 'reads')):
        if set(names) <= set(known) and len(set(names)) == len(names):
            continue
        raise ConfigError(
            f'{where}: {what} {", ".join(names)}: balance_calibrator {verb} only '
            f'{", ".join(known)}, each once, so this calibration ({len(calibration.components)} '
            f'components from {len(calibration.bridge_outputs)} bridge outputs) cannot run live '
            f'(balance-calib fit --axes names a table\'s loads and bridges as TM-663\'s)')


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
    accepted: np.ndarray            # (N,) published; False for NaN/inf or saturated samples
    loads_balance: np.ndarray       # (N, 6) loads after the tare load, balance axes, N / N·m (NaN if rejected)
    wrench_tunnel: np.ndarray       # (N, 6) the same in tunnel axes (what /balance/wrench carries)
    out_of_envelope: np.ndarray     # (N,) a load beyond the envelope (published, but flagged)
    model_used: str
    fallback_reason: str = ''       # why the base model ran instead of the requested one ('' = it did not)
    loads_total: np.ndarray | None = None   # (N, 6) before the tare load: what the balance carries
    saturated: np.ndarray | None = None     # (N,) an output beyond the bridge's range (or a non-finite load)
    not_converged: np.ndarray | None = None  # (N,) iterative model: Newton did not converge (not published)
    design_row: np.ndarray | None = None    # (n_terms,) a lone sample's design row (model term order), for its
    #                                         uncertainty; None for batches and other paths

    @property
    def nonfinite(self) -> np.ndarray:
        rejected = ~self.accepted & ~self.saturated
        return rejected if self.not_converged is None else rejected & ~self.not_converged


def model_loads(active: ActiveCalibration, outputs_mv, *, temperature_c=None,
                load_direction=None) -> tuple[np.ndarray, str, str]:
    """Balance-axis loads (N, 6) of finite outputs (N, 6); also the model used and why a fallback."""
    outputs = np.atleast_2d(np.asarray(outputs_mv, dtype=float))
    n = outputs.shape[0]
    if not active.model.extra_variables:
        return _plain_loads(active, outputs), active.model_name, ''
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


def _plain_loads(active: ActiveCalibration, outputs: np.ndarray) -> np.ndarray:
    """A model of the bridge outputs only: a direct model as one power-product and one matrix product
    (TM-663 eqs. (1)-(18)); an iterative model by its vectorised Newton iteration (AIAA R-091), NaN rows
    where it did not converge."""
    columns, positions, plain, absolute, coefficients = active.plan
    loads = np.zeros((outputs.shape[0], 6))
    if plain is None:
        loads[:, positions] = active.model.loads_and_status(outputs[:, columns])[0]
    else:
        loads[:, positions] = power_products(outputs[:, columns], plain, absolute) @ coefficients.T
    return loads


def compute_wrench(active: ActiveCalibration, outputs_mv, *, zero_mv=None, tare_load=None, temperature_c=None,
                   load_direction=None, zero_temperature_c=None, zero_direction=None) -> WrenchBatch:
    """Raw outputs (N, 6) mV -> wrench in tunnel axes (N, 6); see the module docstring.

    zero_mv (6,): the electrical zero, subtracted from the outputs; tare_load (6,) N / N·m, balance
    axes: the tare load, subtracted from the loads. zero_temperature_c / zero_direction: the
    conditions when the zero was taken (for models with temperature or load-direction terms).
    """
    outputs = np.atleast_2d(np.asarray(outputs_mv, dtype=float))
    if outputs.shape[0] == 1 and not active.model.extra_variables:
        return _one_plain_sample(active, outputs, zero_mv, tare_load)
    with np.errstate(invalid='ignore', over='ignore'):
        finite = active.inputs_finite(outputs)       # channels the calibration does not read aside
        saturated = finite & (np.abs(outputs) > active.output_range_mv).any(axis=1)
    accepted = finite & ~saturated
    zeroed = outputs if zero_mv is None else outputs - np.asarray(zero_mv, dtype=float)
    name, reason = active.model_name, ''
    if accepted.all():
        totals, name, reason = _loads_with_zero(active, zeroed, temperature_c, load_direction, zero_mv,
                                                zero_temperature_c, zero_direction)
    else:
        totals = np.full(outputs.shape, np.nan)
        if accepted.any():
            temps = None if temperature_c is None else np.broadcast_to(np.asarray(temperature_c, float),
                                                                        (len(outputs),))[accepted]
            direction = None if load_direction is None else np.broadcast_to(load_direction, outputs.shape)[accepted]
            totals[accepted], name, reason = _loads_with_zero(active, zeroed[accepted], temps, direction, zero_mv,
                                                              zero_temperature_c, zero_direction)
    not_converged = np.zeros(len(outputs), dtype=bool)
    with np.errstate(invalid='ignore', over='ignore'):
        overflow = accepted & ~np.isfinite(totals).all(axis=1)    # finite outputs, loads beyond float range
        if overflow.any():
            if active.iterative:          # finite outputs without loads: Newton did not converge there
                not_converged = overflow
            else:
                saturated = saturated | overflow
            accepted = accepted & ~overflow
            totals[overflow] = np.nan
        outside = accepted & np.any(np.abs(totals) > active.envelope, axis=1)
    loads = totals if tare_load is None else totals - np.asarray(tare_load, dtype=float)
    wrench = active.installation.to_tunnel(loads)          # TM-663 §10.2
    return WrenchBatch(accepted, loads, wrench, outside, name, reason, totals, saturated, not_converged)


def _one_plain_sample(active: ActiveCalibration, outputs: np.ndarray, zero_mv, tare_load) -> WrenchBatch:
    """compute_wrench for one sample of a model of the bridge outputs only: the live path at low rates,
    where every sample comes alone (the same steps as the batch, with fewer numpy calls)."""
    row = outputs[0]
    values = row.tolist()
    rejected = not all(map(math.isfinite, values)) and not active.inputs_finite(outputs)[0]
    saturated = not rejected and any(abs(v) > r for v, r in zip(values, active.output_range_list))
    index = active.one_sample_index
    if index is not None and not (rejected or saturated) and max(map(abs, values)) < 1e30:
        fast = _one_polynomial_sample(active, row, zero_mv, tare_load, index)
        if fast is not None:
            return fast
    loads = np.full((1, 6), np.nan)
    not_converged = False
    if not (rejected or saturated):      # other polynomials, an iterative model, or the fast path's leftovers
        columns, positions, plain, absolute, coefficients = active.plan
        with np.errstate(invalid='ignore', over='ignore'):
            loads[0] = 0.0
            zeroed = row if zero_mv is None else row - zero_mv
            if plain is None:        # AIAA R-091: the model's own Newton iteration
                loads[0, positions] = active.model.loads_and_status(zeroed[columns][None, :])[0][0]
            else:
                loads[0, positions] = coefficients @ power_products(zeroed[columns][None, :], plain, absolute)[0]
            failed = not all(map(math.isfinite, loads[0].tolist()))     # beyond float range / no convergence
        if failed:
            loads[:] = np.nan
            if plain is None:
                not_converged = True
            else:
                saturated = True
    accepted = not (rejected or saturated or not_converged)
    outside = accepted and bool((np.abs(loads[0]) > active.envelope).any())
    tared = loads if tare_load is None or not accepted else loads - tare_load
    return WrenchBatch(np.array([accepted]), tared, active.installation.to_tunnel(tared), np.array([outside]),
                       active.model_name, '', loads, np.array([saturated]), np.array([not_converged]))


def _one_polynomial_sample(active: ActiveCalibration, row: np.ndarray, zero_mv, tare_load, index) -> WrenchBatch | None:
    """The common case of the live path: one finite, unsaturated sample of a polynomial model of at most
    third degree (TM-663 eqs. (1)-(18)); outputs below 1e30 mV, so no product can overflow. None if
    the loads are not finite all the same (the general path then says why)."""
    padded = np.ones(7)
    padded[:6] = row if zero_mv is None else row - zero_mv
    design_row = padded[index].prod(axis=1)
    loads = (active.coefficients_six @ design_row)[None, :]
    values = loads[0].tolist()
    if not all(map(math.isfinite, values)):
        return None
    outside = any(abs(v) > e for v, e in zip(values, active.envelope_list))
    tared = loads if tare_load is None else loads - tare_load
    return WrenchBatch(np.array([True]), tared, active.installation.to_tunnel(tared), np.array([outside]),
                       active.model_name, '', loads, np.array([False]), np.array([False]), design_row)


def _loads_with_zero(active, zeroed, temperature_c, load_direction, zero_mv, zero_temperature_c, zero_direction):
    loads, name, reason = model_loads(active, zeroed, temperature_c=temperature_c, load_direction=load_direction)
    if zero_mv is not None and active.model.extra_variables and name == active.model_name:
        # The zero removed the outputs at the temperature and load direction of its moment; what the
        # model's pure temperature / direction terms gave then belongs to that zero too, so those
        # terms act on the change since the zero.
        offset, offset_name, _ = model_loads(
            active, np.zeros((1, 6)),
            temperature_c=None if zero_temperature_c is None else np.array([zero_temperature_c], float),
            load_direction=None if zero_direction is None else np.atleast_2d(zero_direction))
        if offset_name == name:
            loads = loads - offset[0]
    return loads, name, reason


# --- tare and zero ----------------------------------------------------------------------------
def tare_zero(outputs_mv) -> np.ndarray:
    """The electrical zero: mean bridge outputs (6,) mV over a window (N, 6) with nothing on the balance."""
    return np.mean(np.atleast_2d(np.asarray(outputs_mv, dtype=float)), axis=0)


@dataclass(frozen=True)
class Steadiness:
    """Whether a window of samples holds one load, judged against the window's own noise."""

    steady: bool
    reason: str                 # '' when steady; else one line naming the component
    scatter_ratio: float        # worst std / noise over the components
    step_ratio: float           # worst |mean(second half) - mean(first half)| / noise


def check_steady(values, names, units, scale, max_ratio: float) -> Steadiness:
    """values (N, k): a window of loads (or outputs); scale (k,) full scale per column.

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
        return Steadiness(False, f'{n} samples cannot show whether the load is steady (at least 4)', np.inf, np.inf)
    differences = np.diff(values, axis=0)
    mad = np.median(np.abs(differences - np.median(differences, axis=0)), axis=0)
    noise = np.maximum(1.4826 * mad / np.sqrt(2.0), 1e-5 * np.where(np.isfinite(scale), scale, 1.0))
    scatter = np.std(values, axis=0) / noise
    step = np.abs(values[n // 2:].mean(axis=0) - values[:n // 2].mean(axis=0)) / noise
    worst_scatter, worst_step = int(np.argmax(scatter)), int(np.argmax(step))
    if step[worst_step] > max_ratio:
        k = worst_step
        delta = values[n // 2:, k].mean() - values[:n // 2, k].mean()
        return Steadiness(False, f'{names[k]} moved by {delta:+.4g} {units[k]} within the window '
                                 f'({step[k]:.0f}x its noise {noise[k]:.3g} {units[k]}): a load step or ramp',
                          float(scatter.max()), float(step.max()))
    if scatter[worst_scatter] > max_ratio:
        k = worst_scatter
        return Steadiness(False, f'{names[k]} scatters by {np.std(values[:, k]):.4g} {units[k]} '
                                 f'({scatter[k]:.1f}x its sample-to-sample noise {noise[k]:.3g} {units[k]})',
                          float(scatter.max()), float(step.max()))
    return Steadiness(True, '', float(scatter.max()), float(step.max()))


@dataclass
class TareWindow:
    """Collects the next `samples` accepted raw samples after ~/tare or ~/zero (kind 'tare' or 'zero')."""

    samples: int
    kind: str = 'tare'
    outputs_mv: list = field(default_factory=list)
    temperatures_c: list = field(default_factory=list)

    def __post_init__(self):
        if int(self.samples) < 1:
            raise ValueError(f'tare needs at least one sample, not {self.samples}')

    def add(self, outputs_mv, temperature_c: float | None = None) -> bool:
        """Add accepted raw samples (N, 6) mV; True once the window is full (the rest is ignored)."""
        outputs = np.atleast_2d(np.asarray(outputs_mv, dtype=float))
        taken = outputs[:max(0, self.samples - len(self.outputs_mv))]
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
    zero_mv: np.ndarray | None = None      # for kind 'zero'
    tare_load: np.ndarray | None = None    # for kind 'tare': balance axes, N / N·m
    tare_sigma: np.ndarray | None = None   # standard uncertainty of that mean (scatter / √n), balance axes


def evaluate_window(window: TareWindow, active: ActiveCalibration, *, max_ratio: float, zero_mv=None,
                    zero_temperature_c=None, zero_direction=None, load_direction=None) -> TareResult:
    """The zero (output space) or tare load (load space) of a full window, or why it is refused."""
    outputs = np.array(window.outputs_mv, dtype=float)
    n = len(outputs)
    if window.kind == 'zero':
        names = active.calibration.bridge_outputs
        columns = [BRIDGE_OUTPUTS.index(v) for v in names]
        units = (active.calibration.output_unit,) * len(names)
        steady = check_steady(outputs[:, columns], names, units,
                              np.asarray(active.calibration.rated_output_mv, float), max_ratio)
        if not steady.steady:
            return TareResult(False, f'zero refused: the window of {n} samples is not steady: {steady.reason}')
        zero = tare_zero(outputs)
        if active.unused_inputs is not None:       # channels not read: no zero (finite, persisted)
            zero[active.unused_inputs] = 0.0
        return TareResult(True, f'zero: averaged {n} samples, steady (scatter {steady.scatter_ratio:.1f}x, step '
                                f'{steady.step_ratio:.1f}x noise); electrical zero now subtracted: '
                                f'{describe_zero(zero, active)}', zero_mv=zero)
    batch = compute_wrench(active, outputs, zero_mv=zero_mv, temperature_c=window.temperature_c,
                           load_direction=load_direction, zero_temperature_c=zero_temperature_c,
                           zero_direction=zero_direction)
    failed = int(np.count_nonzero(~np.isfinite(batch.loads_total).all(axis=1)))
    if failed:          # an iterative model's Newton iteration did not converge (or outputs saturated)
        return TareResult(False, f'tare refused: {failed} of the window\'s {n} samples give no load '
                                 f'(the {batch.model_used} model\'s Newton iteration did not converge or a bridge '
                                 f'saturated)')
    components = active.calibration.components
    columns = [COMPONENTS.index(c) for c in components]
    loads = batch.loads_total[:, columns]
    units = tuple(UNITS[COMPONENTS.index(c)] for c in components)
    steady = check_steady(loads, components, units, np.asarray(active.calibration.capacity, float), max_ratio)
    if not steady.steady:
        return TareResult(False, f'tare refused: the window of {n} samples is not steady: {steady.reason}')
    tare_load = np.mean(batch.loads_total, axis=0)
    mean_outputs = outputs.mean(axis=0)
    return TareResult(True, f'tare: averaged {n} samples, steady (scatter {steady.scatter_ratio:.1f}x, step '
                            f'{steady.step_ratio:.1f}x noise); tare load now subtracted: '
                            f'{describe_tare(tare_load, active)}; mean wind-off outputs: ' +
                      ', '.join(f'{b}={output_text(mean_outputs[BRIDGE_OUTPUTS.index(b)], active)}'
                                for b in active.calibration.bridge_outputs)
                      + ('' if zero_mv is not None else '; no electrical zero taken (~/zero with nothing on the '
                         'balance): the calibration sees outputs measured from the bridges\' own zero'),
                      tare_load=tare_load, tare_sigma=np.std(batch.loads_total, axis=0, ddof=1) / np.sqrt(n))


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
    return (f'{describe_loads(tare_load, active)} ({active.installation.name} tunnel axes, {active.model_name} '
            f'model on the full outputs)')


def describe_zero(zero_mv, active: ActiveCalibration) -> str:
    """The zero subtracted, per bridge output in mV, and the load it stands for in tunnel axes."""
    zero = np.asarray(zero_mv, dtype=float)
    try:
        equivalent = six_axis_loads(active.base_model, zero[None, :])[0] if not active.base_model.extra_variables \
            else np.full(6, np.nan)
    except InverseDidNotConverge:      # an iterative model without a solution there: no number
        equivalent = np.full(6, np.nan)
    names = active.calibration.bridge_outputs
    outputs = ', '.join(f'{c}={output_text(v, active)}'
                        for c, v in zip(names, zero[[BRIDGE_OUTPUTS.index(b) for b in names]]))
    return (f'{outputs} (the load these outputs read as, {active.installation.name} tunnel axes, '
            f'{active.base_name} model: {describe_loads(equivalent, active)})')


# --- diagnostics ------------------------------------------------------------------------------
@dataclass
class InputCounters:
    """Counts since start and since the last diagnostics report."""

    received: int = 0
    published: int = 0
    rejected_nonfinite: int = 0
    saturated: int = 0
    out_of_envelope: int = 0
    not_converged: int = 0          # iterative model: samples where Newton did not converge
    period_received: int = 0
    period_rejected: int = 0
    period_saturated: int = 0
    period_out_of_envelope: int = 0
    period_not_converged: int = 0

    def count_one(self, out_of_envelope: bool) -> None:
        """count() for one accepted sample (the live path at low rates)."""
        self.received += 1
        self.period_received += 1
        self.published += 1
        if out_of_envelope:
            self.out_of_envelope += 1
            self.period_out_of_envelope += 1

    def count(self, batch: WrenchBatch) -> None:
        if len(batch.accepted) == 1 and batch.accepted[0]:
            self.count_one(bool(batch.out_of_envelope[0]))
            return
        n, ok = len(batch.accepted), int(np.count_nonzero(batch.accepted))
        saturated = 0 if batch.saturated is None else int(np.count_nonzero(batch.saturated))
        failed = 0 if batch.not_converged is None else int(np.count_nonzero(batch.not_converged))
        out = int(np.count_nonzero(batch.out_of_envelope))
        self.received += n
        self.period_received += n
        self.published += ok
        self.rejected_nonfinite += n - ok - saturated - failed
        self.period_rejected += n - ok - saturated - failed
        self.saturated += saturated
        self.period_saturated += saturated
        self.not_converged += failed
        self.period_not_converged += failed
        self.out_of_envelope += out
        self.period_out_of_envelope += out

    def start_period(self) -> None:
        self.period_received = self.period_rejected = self.period_out_of_envelope = self.period_saturated = 0
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
    last_sample_age_s: float | None            # None: no sample yet
    stale_after_s: float
    temperature_age_s: float | None
    fallback_reason: str
    tare_zero_mv: np.ndarray | None            # the electrical zero (None: none taken)
    refit_running: bool = False
    tare_load: np.ndarray | None = None        # balance axes, N / N·m (None: no tare)
    tare_source: str = ''                      # where the tare was persisted / restored from
    tare_refused: str = ''                     # why the persisted zero and tare were not restored
    input_problems: tuple[tuple[str, int, int], ...] = ()   # (what, total, this period)
    input_values: tuple[tuple[str, str], ...] = ()
    overload: tuple[str, ...] | None = None    # components over the limit now (None = no overload)
    overload_values: tuple[tuple[str, str], ...] = ()
    lowpass_hz: float = 0.0


def count_key(what: str) -> str:
    """The /diagnostics key stem of an input problem: 'samples lost (gaps in the stamps)' ->
    'samples_lost' (with _last_period and _since_start: the count of this diagnostics period, the
    count since the node started)."""
    return what.split(' (')[0].replace(' ', '_')


def diagnostics(active: ActiveCalibration, state: LiveState, node_name: str = 'balance_calibrator',
                now: _dt.datetime | None = None) -> list[StatusReport]:
    """Input health, calibration status and overload; levels OK / WARN / ERROR / STALE as DiagnosticStatus."""
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
        problems.append(f'{c.period_saturated} samples saturated (an output beyond '
                        f'{", ".join(f"{v:.3g}" for v in active.output_range_mv)} '
                        f'{active.calibration.output_unit}): not published')
    if c.period_not_converged:
        level = ERROR
        problems.append(f'{c.period_not_converged} samples where the {active.model_name} model\'s Newton '
                        f'iteration (AIAA R-091) did not converge: not published')
    if c.period_out_of_envelope:
        level = max(level, WARN) if level != STALE else level
        problems.append(f'{c.period_out_of_envelope} samples outside the calibrated envelope')
    for what, total, period in state.input_problems:
        if period:
            level = max(level, WARN) if level != STALE else level
            # both counts, named: this period's (as the other counts here) and the total
            problems.append(f'{period} {what} in the last {state.period_s:.1f} s '
                            f'({total} since start)')
    input_values = (
        ('input_rate_hz', f'{rate:.1f}'),
        ('last_sample_age_s', 'never' if state.last_sample_age_s is None else f'{state.last_sample_age_s:.3f}'),
        ('stale', str(state.last_sample_age_s is None or state.last_sample_age_s > state.stale_after_s)),
        ('samples_received', str(c.received)),
        ('wrenches_published', str(c.published)),
        ('rejected_nonfinite', str(c.rejected_nonfinite)),
        ('saturated', str(c.saturated)),
        ('newton_not_converged', str(c.not_converged)),
        ('out_of_envelope', str(c.out_of_envelope)),
        ('envelope', ', '.join(f'{k}={v:.4g}' for k, v in zip(COMPONENTS, active.envelope))),
        *((f'{count_key(what)}_{window}', str(count))
          for what, total, period in state.input_problems
          for window, count in (('last_period', period), ('since_start', total))),
        *state.input_values,
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
    cal_level = WARN if state.fallback_reason or state.tare_refused else OK
    absent = active.absent_components
    message = (f'{active.model_name} model, {active.installation.name} installation'
               + (f'; {6 - len(absent)}-component calibration: {", ".join(absent)} absent '
                  f'(published as 0, uncertainty NaN)' if absent else '')
               + (f'; FALLBACK to {active.base_name}: {state.fallback_reason}' if state.fallback_reason else ''))
    if state.tare_refused:
        message += (f'; zero and tare NOT restored ({state.tare_refused}): '
                    'take ~/zero and ~/tare again')
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
        ('zero_mv', 'none' if zero is None else
         ', '.join(f'{b}={zero[BRIDGE_OUTPUTS.index(b)]:+.5f}' for b in cal.bridge_outputs)),
        ('tare_load', 'none' if state.tare_load is None else
         f'{describe_loads(state.tare_load, active)} (tunnel axes)'),
        ('tare_file', state.tare_source or 'none'),
        ('tare_not_restored', state.tare_refused or 'none'),
        ('lowpass_hz', f'{state.lowpass_hz:g}' if state.lowpass_hz else 'off'),
        ('refit_running', str(state.refit_running)),
    )
    reports.append(StatusReport(cal_level, f'{node_name}: calibration', message, hardware, cal_values))
    if state.overload is None:
        reports.append(StatusReport(OK, f'{node_name}: overload', 'no overload', hardware, state.overload_values))
    else:
        reports.append(StatusReport(ERROR, f'{node_name}: overload',
                                    f'OVERLOAD: {", ".join(state.overload)} beyond the rated load limit',
                                    hardware, state.overload_values))
    return reports


def parse_reliability(value: str) -> str:
    key = str(value).strip().lower().replace('-', '_')
    if key not in ('reliable', 'best_effort'):
        raise ValueError(f'input_reliability must be reliable or best_effort, not {value!r}')
    return key
