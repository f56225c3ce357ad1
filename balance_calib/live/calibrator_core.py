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

Beside it: the ~/zero and ~/tare windows (tare_window.py), the text of a load, zero and tare
(load_text.py) and the /diagnostics reports (diagnostics_status.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from ..calibration_file import ConfigError
from ..model.active_calibration import ActiveCalibration, six_axis_loads
from ..model.balance_model import BalanceModel
from ..units import COMPONENTS


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
        """(N,) True for the samples rejected as not finite (neither saturated nor unsolved)."""
        rejected = ~self.accepted & ~self.saturated
        return rejected if self.not_converged is None else rejected & ~self.not_converged


def model_loads(
    active: ActiveCalibration,
    outputs_mv: ArrayLike,
    *,
    temperature_c: ArrayLike | None = None,
    load_direction: np.ndarray | None = None,
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


def _rows(outputs_mv: ArrayLike) -> np.ndarray:
    """Samples as a float array (N, 6), without a copy when they are one already."""
    if type(outputs_mv) is np.ndarray and outputs_mv.ndim == 2 and outputs_mv.dtype == float:
        return outputs_mv
    return np.atleast_2d(np.asarray(outputs_mv, dtype=float))


def compute_wrench(
    active: ActiveCalibration,
    outputs_mv: ArrayLike,
    *,
    zero_mv: ArrayLike | None = None,
    tare_load: ArrayLike | None = None,
    temperature_c: ArrayLike | None = None,
    load_direction: np.ndarray | None = None,
    zero_temperature_c: float | None = None,
    zero_direction: np.ndarray | None = None,
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
    active: ActiveCalibration,
    outputs: np.ndarray,
    zero_mv: ArrayLike | None,
    tare_load: ArrayLike | None,
    temperature_c: ArrayLike | None,
    load_direction: np.ndarray | None,
    zero_temperature_c: float | None,
    zero_direction: np.ndarray | None,
) -> WrenchBatch:
    """compute_wrench on float rows (N, 6), floating-point warnings already silenced."""
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
    active: ActiveCalibration,
    zeroed: np.ndarray,
    temperature_c: ArrayLike | None,
    load_direction: np.ndarray | None,
    zero_mv: ArrayLike | None,
    zero_temperature_c: float | None,
    zero_direction: np.ndarray | None,
) -> tuple[np.ndarray, str, str]:
    """model_loads of the zeroed outputs (loads, model used, why a fallback); with a zero and a
    model with temperature or direction terms, less what those terms gave when the zero was taken.
    """
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


def parse_reliability(value: str) -> str:
    """The input_reliability parameter as 'reliable' or 'best_effort'; ValueError otherwise."""
    key = str(value).strip().lower().replace('-', '_')
    if key not in ('reliable', 'best_effort'):
        raise ValueError(f'input_reliability must be reliable or best_effort, not {value!r}')
    return key
