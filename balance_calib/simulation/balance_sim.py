"""A simulated balance and calibration campaign.

Any of the memo's matrices (or any BalanceModel) is the truth: the outputs a load produces are
found by inverting it (model/inverse.py). On top come the electrical zero, a slow zero drift that
the zero points of §5(4) can follow, per-sample noise, the temperature of the balance, and any
effects from simulation/effects.py. A campaign plays a load schedule (Appendix A/B) with its
orientation changes: every point has a settled window of samples, and between points the weights
are being changed (samples that belong to no point).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..config import BalanceConfig, CalibrationBody, LoadSchedule
from ..model.balance_model import BalanceModel
from ..model.inverse import linear_part, outputs_for_loads
from ..tare.calibration_body import tare_loads
from .effects import Effect, SampleContext


@dataclass(frozen=True)
class Campaign:
    """A simulated calibration campaign: the truth per point and the raw samples."""

    balance: str
    point: np.ndarray  # (P,) point labels
    orientation: np.ndarray  # (P,) I_g
    gravity: np.ndarray  # (P, 3) unit vector of gravity, balance axes
    applied_loads: np.ndarray  # (P, 6) hung by the loading hardware (no body weight), N / N·m
    true_loads: np.ndarray  # (P, 6) applied + true body weight
    start_s: np.ndarray  # (P,) time the point settled (applied_load published)
    end_s: np.ndarray  # (P,) end of its settled window
    times_s: np.ndarray  # (S,) sample times
    sample_point: np.ndarray  # (S,) index of the point a sample belongs to, -1 between points
    raw_mv: np.ndarray  # (S, 6) bridge outputs as the amplifier gives them
    temperature_c: np.ndarray  # (S,)
    effects: tuple[str, ...] = ()

    @property
    def is_zero_point(self) -> np.ndarray:
        return np.all(self.applied_loads == 0.0, axis=1)

    def point_means(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(P, 6) mean outputs, (P,) mean time, (P,) mean temperature of each point's samples."""
        inside = self.sample_point >= 0
        index = self.sample_point[inside]
        counts = np.bincount(index, minlength=len(self.point)).astype(float)
        counts[counts == 0] = np.nan
        means = (
            np.column_stack(
                [
                    np.bincount(index, self.raw_mv[inside, k], len(self.point))
                    for k in range(self.raw_mv.shape[1])
                ]
            )
            / counts[:, None]
        )
        times = np.bincount(index, self.times_s[inside], len(self.point)) / counts
        temps = np.bincount(index, self.temperature_c[inside], len(self.point)) / counts
        return means, times, temps

    def point_scatter(self) -> tuple[np.ndarray, np.ndarray]:
        """(P, 6) variance of each point's mean output (sample variance / n), (P,) samples per
        point.
        """
        inside = self.sample_point >= 0
        index = self.sample_point[inside]
        counts = np.bincount(index, minlength=len(self.point)).astype(float)
        means, _, _ = self.point_means()
        deviations = self.raw_mv[inside] - means[index]
        squares = np.column_stack(
            [
                np.bincount(index, deviations[:, k] ** 2, len(self.point))
                for k in range(self.raw_mv.shape[1])
            ]
        )
        with np.errstate(invalid='ignore', divide='ignore'):
            variance = squares / (counts - 1)[:, None] / counts[:, None]
        variance[counts < 2] = np.nan
        return variance, counts


@dataclass(frozen=True)
class SimulationSettings:
    """How the simulated balance and campaign behave. Defaults: a quiet, modern amplifier."""

    samples_per_point: int = 1
    sample_rate_hz: float = 100.0
    point_duration_s: float = 60.0  # weights hang still for this long before the next change
    transition_s: float = 30.0  # weights being changed (samples belong to no point)
    transition_samples: int = 0  # samples taken while weights change (outputs ramp between points)
    noise_mv: ArrayLike | None = None  # per-sample σ per bridge; None -> noise_sigma_pct_fs
    noise_sigma_pct_fs: ArrayLike | None = None  # point noise as load σ in % FS
    electrical_zero_mv: ArrayLike = 0.04
    slow_drift_mv_per_hour: ArrayLike = 0.002
    temperature_mean_c: float = 20.0
    temperature_swing_c: float = 2.5  # diurnal swing amplitude
    reference_temperature_c: float = 20.0
    axial_jig: bool = False  # add the ±2.94 N F_X jig of Tables 9/13 to applied loads
    seed: int = 0
    # Physical seconds per second of the simulated timeline: a campaign played fast over DDS (0.1 s
    # a point) still drifts and warms as one that takes 90 s a point does (time_scale 90 / 0.13).
    time_scale: float = 1.0


def paced_settings(
    rate_hz: float,
    point_duration_s: float,
    transition_s: float,
    noise_sigma_pct_fs,
    seed: int,
    physical_seconds_per_point: float,
) -> SimulationSettings:
    """A campaign played in real time (bridge_publisher's calibration mode).

    Parameters
    ----------
    rate_hz : samples per second, also while the weights change (transition samples)
    point_duration_s, transition_s : s a point is held, s its weights take to change
    noise_sigma_pct_fs : (6,) or float, σ of a held point's mean, % FS
    seed : of the noise
    physical_seconds_per_point : s of a real campaign's point, which temperature and drift follow
    """
    return SimulationSettings(
        samples_per_point=max(1, round(point_duration_s * rate_hz)),
        sample_rate_hz=rate_hz,
        point_duration_s=point_duration_s,
        transition_s=transition_s,
        transition_samples=round(transition_s * rate_hz),
        noise_sigma_pct_fs=noise_sigma_pct_fs,
        seed=seed,
        time_scale=physical_seconds_per_point / max(point_duration_s + transition_s, 1e-9),
    )


def noise_mv_for_load_sigma(truth: BalanceModel, capacity, sigma_pct_fs) -> np.ndarray:
    """Per-bridge output noise (mV) that gives a load noise of sigma_pct_fs (% FS) per
    component.
    """
    from scipy.optimize import nnls

    sigma_load = (
        np.broadcast_to(np.asarray(sigma_pct_fs, float), (len(truth.components),))
        * np.asarray(capacity, float)
        / 100.0
    )
    # independent bridge noise n adds up in load k as sum_i C_ki² n_i² (C the linear part)
    variance, _ = nnls(linear_part(truth) ** 2, sigma_load**2)
    return np.sqrt(variance)


def _direction_history(loads: np.ndarray) -> np.ndarray:
    """+1 where the load on a bridge last rose, -1 where it last fell (starts rising)."""
    direction = np.ones_like(loads)
    for k in range(1, len(loads)):
        change = np.sign(loads[k] - loads[k - 1])
        direction[k] = np.where(np.abs(loads[k] - loads[k - 1]) > 1e-9, change, direction[k - 1])
    return direction


def simulate_campaign(
    config: BalanceConfig,
    truth: BalanceModel | None = None,
    *,
    schedule: LoadSchedule | None = None,
    settings: SimulationSettings = SimulationSettings(),
    effects: Sequence[Effect] = (),
    true_body: CalibrationBody | None = None,
) -> Campaign:
    """Play a load schedule on a simulated balance; truth defaults to the config's cubic matrix."""
    rng = np.random.default_rng(settings.seed)
    truth = (truth or config.matrices['cubic']).without_constant()
    for effect in effects:
        truth = effect.truth(truth)
    schedule = schedule or config.schedule
    if schedule is None:
        raise ValueError(f'{config.name}: no load schedule to simulate')
    body = true_body or config.calibration_body
    factor = np.prod([e.body_weight_factor() for e in effects]) if effects else 1.0
    body = replace(body, weight_n=body.weight_n * factor)

    n_points = len(schedule)
    gravity = np.array([config.gravity(i) for i in schedule.orientation])
    applied = np.array(schedule.loads, dtype=float)
    if settings.axial_jig:
        applied[:, 0] += np.sign(applied[:, 0]) * body.axial_jig_weight_n
    true_loads = applied + tare_loads(body, gravity)
    point_outputs = outputs_for_loads(truth, true_loads)

    # timeline: each point = transition (no point) then a settled window
    period = settings.transition_s + settings.point_duration_s
    start = np.arange(n_points) * period + settings.transition_s
    end = start + settings.point_duration_s
    per_point = max(int(settings.samples_per_point), 1)
    offsets = (np.arange(per_point) + 0.5) / per_point * settings.point_duration_s
    times = (start[:, None] + offsets[None, :]).reshape(-1)
    sample_point = np.repeat(np.arange(n_points), per_point)
    outputs_clean = point_outputs[sample_point]
    direction = _direction_history(true_loads)[sample_point]
    loads_at_sample = true_loads[sample_point]
    gravity_at_sample = gravity[sample_point]
    settled_at_sample = start[sample_point]
    if settings.transition_samples > 0:
        # weights being changed: outputs and loads ramp from the previous point to the next
        n_tr = int(settings.transition_samples)
        fraction = (np.arange(n_tr) + 0.5) / n_tr
        prev = np.maximum(np.arange(n_points) - 1, 0)
        tr_times = (
            start[:, None] - settings.transition_s + fraction[None, :] * settings.transition_s
        ).reshape(-1)
        w = np.tile(fraction, n_points)[:, None]
        tr_outputs = (1 - w) * point_outputs[np.repeat(prev, n_tr)] + w * point_outputs[
            np.repeat(np.arange(n_points), n_tr)
        ]
        tr_loads = (1 - w) * true_loads[np.repeat(prev, n_tr)] + w * true_loads[
            np.repeat(np.arange(n_points), n_tr)
        ]
        tr_direction = _direction_history(true_loads)[np.repeat(np.arange(n_points), n_tr)]
        order = np.argsort(np.concatenate([times, tr_times]), kind='stable')
        times = np.concatenate([times, tr_times])[order]
        sample_point = np.concatenate([sample_point, np.full(len(tr_times), -1)])[order]
        outputs_clean = np.vstack([outputs_clean, tr_outputs])[order]
        direction = np.vstack([direction, tr_direction])[order]
        loads_at_sample = np.vstack([loads_at_sample, tr_loads])[order]
        gravity_at_sample = np.vstack(
            [gravity_at_sample, gravity[np.repeat(np.arange(n_points), n_tr)]]
        )[order]
        settled_at_sample = np.concatenate([settled_at_sample, tr_times])[order]

    physical_s = times * settings.time_scale  # what temperature, drift and effects follow
    hours = physical_s / 3600.0
    temperature = (
        settings.temperature_mean_c
        + settings.temperature_swing_c * np.sin(2 * np.pi * hours / 24.0 - 1.0)
        + 0.3 * np.sin(2 * np.pi * hours / 3.1)
    )
    ctx = SampleContext(
        physical_s,
        temperature,
        loads_at_sample,
        outputs_clean,
        direction,
        config.rated_output_mv,
        settings.reference_temperature_c,
        np.asarray(config.capacity, float),
        gravity_at_sample,
        settled_at_sample * settings.time_scale,
    )
    outputs = outputs_clean.copy()
    for effect in effects:
        outputs = effect.outputs(outputs, ctx)

    if settings.noise_mv is not None:
        noise_mv = np.broadcast_to(np.asarray(settings.noise_mv, float), (6,))
    elif settings.noise_sigma_pct_fs is not None:
        noise_mv = noise_mv_for_load_sigma(
            truth, config.capacity, settings.noise_sigma_pct_fs
        ) * np.sqrt(per_point)
    else:
        noise_mv = np.zeros(6)
    zero = np.broadcast_to(np.asarray(settings.electrical_zero_mv, float), (6,))
    drift = np.broadcast_to(np.asarray(settings.slow_drift_mv_per_hour, float), (6,))
    raw = outputs + zero + drift * hours[:, None] + rng.normal(size=outputs.shape) * noise_mv
    return Campaign(
        config.name,
        np.asarray(schedule.point),
        np.asarray(schedule.orientation),
        gravity,
        applied,
        true_loads,
        start,
        end,
        times,
        sample_point,
        raw,
        temperature,
        tuple(e.name for e in effects),
    )


def table17_noise(
    config: BalanceConfig, settings: SimulationSettings = SimulationSettings()
) -> np.ndarray:
    """Point noise (% FS) that makes a cubic fit after zero points scatter as Table 17's cubic row.

    The memo's cubic σ is its noise floor. The zero points of §5(4) add the noise of the brackets
    to every loaded point (factor ~1.11, zero_point_noise_factor), so the point noise is a little
    smaller than the table's σ.
    """
    from ..zero_points import zero_point_noise_factor

    row = config.table17_sigma_pct_fs.get('cubic', {})
    target = np.array([float(row.get(c, 0.0)) for c in config.components])
    schedule = config.schedule
    if schedule is None:
        return target
    period = settings.transition_s + settings.point_duration_s
    factor = zero_point_noise_factor(
        np.arange(len(schedule)) * period, schedule.is_zero_point, schedule.orientation
    )
    return target / factor
