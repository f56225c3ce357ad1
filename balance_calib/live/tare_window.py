"""~/zero and ~/tare: the window of samples each takes, whether it held one load, and the
electrical zero (output space) or tare load (load space) it gives.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..model.active_calibration import ActiveCalibration
from ..units import BRIDGE_OUTPUTS, COMPONENTS
from .calibrator_core import compute_wrench
from .load_text import describe_tare, describe_zero, output_text, UNITS


def tare_zero(outputs_mv: ArrayLike) -> np.ndarray:
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


def check_steady(
    values: ArrayLike,
    names: Sequence[str],
    units: Sequence[str],
    scale: ArrayLike,
    max_ratio: float,
) -> Steadiness:
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
    ratios = (float(scatter.max()), float(step.max()))
    if step[worst_step] > max_ratio:
        k = worst_step
        delta = values[n // 2 :, k].mean() - values[: n // 2, k].mean()
        return Steadiness(
            False,
            f'{names[k]} moved by {delta:+.4g} {units[k]} within the window '
            f'({step[k]:.0f}x its noise {noise[k]:.3g} {units[k]}): a load step or ramp',
            *ratios,
        )
    if scatter[worst_scatter] > max_ratio:
        k = worst_scatter
        return Steadiness(
            False,
            f'{names[k]} scatters by {np.std(values[:, k]):.4g} {units[k]} '
            f'({scatter[k]:.1f}x its sample-to-sample noise {noise[k]:.3g} {units[k]})',
            *ratios,
        )
    return Steadiness(True, '', *ratios)


@dataclass
class TareWindow:
    """Collects the next `samples` accepted raw samples after ~/tare or ~/zero (kind 'tare' or
    'zero').
    """

    samples: int
    kind: str = 'tare'
    outputs_mv: list = field(default_factory=list)
    temperatures_c: list = field(default_factory=list)

    def __post_init__(self) -> None:
        """ValueError for a window of fewer than one sample."""
        if int(self.samples) < 1:
            raise ValueError(f'tare needs at least one sample, not {self.samples}')

    def add(self, outputs_mv: ArrayLike, temperature_c: float | None = None) -> bool:
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
        """True once the window holds `samples` samples."""
        return len(self.outputs_mv) >= self.samples

    @property
    def zero_mv(self) -> np.ndarray:
        """The mean bridge outputs (6,) mV of the window."""
        return tare_zero(np.array(self.outputs_mv))

    @property
    def temperature_c(self) -> float | None:
        """The mean temperature of the window's samples, °C (None: none was given)."""
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
    zero_mv: np.ndarray | None = None,
    zero_temperature_c: float | None = None,
    zero_direction: np.ndarray | None = None,
    load_direction: np.ndarray | None = None,
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
