"""The zero drifting during a run, bracketed by wind-off sweeps before and after it.

The bridges' zero moves during a tunnel run (temperature, creep); a laboratory brackets the run by
wind-off zeros at the same attitudes before and after the wind-on part (TM-663 §10.3 practice; JAXA
does the same) and takes the zero at a wind-on point as the linear interpolation in time between
the two (interfaces.md, "Check loads, and comparing two calibrations", `reduce`'s zero drift).

Here the zero is the wind-off sweep's constant load offsets (weight_tare.py), in load space.
The post-run sweep's offsets are fitted with the weight and centre of gravity of the pre-run sweep
held fixed, so their difference from the pre-run offsets is the shift of the zero alone. The shift
belongs to the mean times of the two sweeps; a ramp through them,

    d(t) = shift · (t − t_pre) / (t_post − t_pre),

is subtracted from every reading of the run (wind-off ones too: a drift within the pre-run sweep
would otherwise leak into the fitted weight and CG) and the run reduced again. What the sweeps
then still disagree by is added to the shift until nothing changes (once, for a declared weight).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from .held_points import HoldSettings
from .model_file import ModelDescription
from .run import HeldPoint, reduce_run, RunResult
from .weight_tare import fit_weight_tare, WeightTareError

ZERO_DRIFT_MODES = ('linear', 'none')
# post-run holds count as "the same attitudes" as a pre-run hold within this, rad (0.06°)
SAME_ATTITUDE_RAD = 1e-3
WARN_BEYOND_SIGMA = 2.0  # interfaces.md: report.md warns beyond twice the calibration's σ
MAX_ITERATIONS = 6


@dataclass(frozen=True)
class ZeroDrift:
    """The zero's shift over a run and whether it was taken out.

    shift (6,): post-run minus pre-run wind-off offsets, N and N·m, tunnel axes (None: the run
    has no usable pair of sweeps; `reason` says why). sigma (6,): its standard uncertainty from
    the two fits. pre_s / post_s: the sweeps' mean times, s from the run's first sample.
    """

    mode: str
    shift: np.ndarray | None = None
    sigma: np.ndarray | None = None
    pre_s: float = float('nan')
    post_s: float = float('nan')
    reason: str = ''

    @property
    def corrected(self) -> bool:
        return self.mode == 'linear' and self.shift is not None

    def ramp(self, times_s) -> np.ndarray:
        """(S, 6) the drift of the zero at times_s (s from the run's first sample), N / N·m."""
        times = np.asarray(times_s, float)
        if self.shift is None:
            return np.zeros((len(times), 6))
        share = (times - self.pre_s) / (self.post_s - self.pre_s)
        return share[:, None] * self.shift[None, :]


def _sweeps(points: Sequence[HeldPoint]) -> tuple[list[HeldPoint], list[HeldPoint]]:
    """The wind-off points before the first wind-on point and after the last one."""
    wind_on = [i for i, p in enumerate(points) if not p.wind_off]
    if not wind_on:
        return [], []
    return list(points[: wind_on[0]]), list(points[wind_on[-1] + 1 :])


def _mean_time_s(points: Sequence[HeldPoint], times_s: np.ndarray) -> float:
    """The mean time of the points' samples, each point weighted alike (as the tare fit does)."""
    return float(
        np.mean([times_s[p.first_sample : p.first_sample + p.samples].mean() for p in points])
    )


def measure_drift(
    result: RunResult,
    times_s,
    model: ModelDescription,
    sigma_loads,
    mode: str = 'linear',
) -> ZeroDrift:
    """The shift of the zero between the run's pre-run and post-run wind-off sweeps.

    result: the run reduced (run.py); times_s (S,): sample times, s, in the indexing of the
    points' first_sample; sigma_loads (6,): σ of a held point's mean load, tunnel axes.
    """
    times_s = np.asarray(times_s, float)
    pre, post = _sweeps(result.points)
    first_on = next((p for p in result.points if not p.wind_off), None)
    tare = first_on.tare if first_on is not None else None
    if not post:
        return ZeroDrift(mode, reason='the run has no wind-off hold after its wind-on part')
    if not pre or tare is None or tare.points != len(pre):
        return ZeroDrift(
            mode, reason='the run has no usable wind-off sweep before its wind-on part'
        )
    pre_attitudes = np.array([p.support_attitude for p in pre])
    strangers = [
        p
        for p in post
        if np.min(np.max(np.abs(pre_attitudes - p.support_attitude), axis=1)) > SAME_ATTITUDE_RAD
    ]
    if strangers:
        phi, alpha = np.degrees(strangers[0].support_attitude[:2])
        return ZeroDrift(
            mode,
            reason=f'{len(strangers)} post-run wind-off hold(s) at attitudes the pre-run sweep '
            f'does not have (first: φ {phi:+.2f}°, α {alpha:+.2f}°)',
        )
    try:
        after = fit_weight_tare(
            np.array([p.readings for p in post]),
            np.array([p.support_attitude for p in post]),
            sigma_loads=sigma_loads,
            deflection=model.deflection,
            weight_n=tare.weight_n,
            cg_m=tare.cg_m,
        )
    except WeightTareError as err:
        return ZeroDrift(mode, reason=f'the post-run wind-off sweep gives no offsets: {err}')
    sigma = np.sqrt(np.maximum(np.diag(tare.covariance)[4:] + np.diag(after.covariance)[4:], 0))
    return ZeroDrift(
        mode,
        after.offsets - tare.offsets,
        sigma,
        _mean_time_s(pre, times_s),
        _mean_time_s(post, times_s),
    )


def reduce_run_with_drift(
    readings,
    support_attitude,
    q_pa,
    times_s,
    model: ModelDescription,
    settings: HoldSettings,
    sigma_loads,
    mode: str = 'linear',
) -> tuple[RunResult, ZeroDrift]:
    """reduce_run (run.py) with the zero's drift between the bracketing wind-off sweeps.

    mode 'linear': the offsets interpolated linearly in time between the pre-run and post-run
    sweeps; 'none': the pre-run offsets throughout (the shift is still measured and reported).
    A run without both sweeps is reduced as reduce_run does and the ZeroDrift says why.
    times_s (S,): sample times, s (any origin).
    """
    if mode not in ZERO_DRIFT_MODES:
        raise ValueError(f'zero drift {mode!r}: choose {" or ".join(ZERO_DRIFT_MODES)}')
    readings = np.asarray(readings, float)
    times = np.asarray(times_s, float)
    times = times - times[0] if len(times) else times
    result = reduce_run(readings, support_attitude, q_pa, model, settings, sigma_loads)
    drift = measure_drift(result, times, model, sigma_loads, mode)
    if mode == 'none' or drift.shift is None or not drift.post_s > drift.pre_s:
        return result, drift
    assert drift.sigma is not None
    tolerance = 1e-6 * np.asarray(sigma_loads, float)
    for _ in range(MAX_ITERATIONS):
        result = reduce_run(
            readings - drift.ramp(times), support_attitude, q_pa, model, settings, sigma_loads
        )
        left = measure_drift(result, times, model, sigma_loads, mode)
        if left.shift is None:  # cannot happen: the same holds as before
            break
        drift = replace(drift, shift=drift.shift + left.shift, pre_s=left.pre_s)
        if np.all(np.abs(left.shift) <= tolerance):
            break
    return result, drift


def drift_pct_fs(shift_tunnel, capacity, installation) -> np.ndarray:
    """(6,) a load-space shift (tunnel axes) in % FS of the calibration's components (balance
    axes).
    """
    balance = installation.from_tunnel(np.asarray(shift_tunnel, float))
    return 100.0 * balance / np.asarray(capacity, float)


def drift_warnings(
    drift: ZeroDrift,
    components: Sequence[str],
    shift_pct_fs,
    sigma_pct_fs,
    model_name: str,
) -> list[str]:
    """One line when the shift exceeds WARN_BEYOND_SIGMA × the calibration's σ somewhere."""
    if drift.shift is None:
        return []
    shift, sigma = np.asarray(shift_pct_fs, float), np.asarray(sigma_pct_fs, float)
    over = [int(k) for k in np.flatnonzero(np.abs(shift) > WARN_BEYOND_SIGMA * sigma)]
    if not len(over):
        return []
    listed = ', '.join(
        f'{components[k]} {shift[k]:+.3f} % FS ({abs(shift[k]) / sigma[k]:.1f}σ)' for k in over
    )
    what = (
        'interpolated linearly in time between them'
        if drift.corrected
        else 'NOT corrected (--zero-drift none: the pre-run zero throughout)'
    )
    return [
        f"{model_name}: the zero drifted between the pre-run and post-run wind-off sweeps beyond "
        f"{WARN_BEYOND_SIGMA:g}× the calibration's σ: {listed}; {what}"
    ]
