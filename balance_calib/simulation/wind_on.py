"""Wind-on load profiles for the simulated balance: an angle-of-attack sweep or a CSV of loads.

The sweep imitates TM-663 §10.3 (α = -2° ... 22°, a longitudinal test): a simple wing-body
(lift slope 0.7·2π per rad, limited smoothly at CL_max; parabolic drag polar CD = CD0 + k·CL²;
linear pitching moment; small side loads from a slight asymmetry). Only the shape of each
coefficient against α is physical: each tunnel-axis component is scaled so that its largest
magnitude over the sweep is a set fraction of the balance capacity (50 % for the longitudinal
components F_X, F_Z, M_Y, 5 % for the lateral ones), which keeps every point inside the
calibrated envelope for any balance.

Tunnel-axis components here: F_X axial force, F_Y side force, F_Z normal force, M_X rolling,
M_Y pitching, M_Z yawing moment, N and N·m, turned into balance axes by the installation
(TM-663 §10.2). The model weight is a constant load (-W on tunnel F_Z) present wind-off and
wind-on alike, which the calibrator's tare removes; its change with α is deliberately not modelled.

`aero_run_profile` is the physical run of TM-663 §10.3 for the data reduction (aero/): a model
file's reference lengths and moment reference centre, a dynamic pressure, the model's weight acting
at its centre of gravity at each attitude, and the sting's deflection under the total load, so the
balance feels what a real one does; a wind-off α/φ sweep first, the wind-on α sweep, the same
wind-off sweep again.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from ..aero.axes import wind_coefficients
from ..aero.coefficients import air_loads_from_coefficients
from ..aero.deflection import iterate_attitude
from ..aero.model_file import ModelDescription
from ..aero.weight_tare import weight_loads
from ..model.balance_model import BalanceModel
from ..model.inverse import outputs_for_loads
from ..tunnel_axes import Installation
from ..units import COMPONENTS
from .effects import Effect, SampleContext

LONGITUDINAL_FRACTION = 0.5
LATERAL_FRACTION = 0.05


@dataclass(frozen=True)
class AeroModel:
    lift_slope_per_rad: float = 0.7 * 2.0 * np.pi
    cl_max: float = 1.3
    cd0: float = 0.02
    induced_drag_factor: float = 0.09
    cm0: float = 0.02
    cm_per_rad: float = -0.35
    side_per_cl: tuple[float, float, float] = (0.02, 0.004, -0.006)  # CY, Cl, Cn per unit CL

    def coefficients(self, alpha_deg) -> np.ndarray:
        """(N, 6) body-axis coefficients [CA, CY, CN, Cl, Cm, Cn] at each α (degrees)."""
        alpha = np.radians(np.atleast_1d(np.asarray(alpha_deg, dtype=float)))
        lift = self.cl_max * np.tanh(self.lift_slope_per_rad * alpha / self.cl_max)
        drag = self.cd0 + self.induced_drag_factor * lift**2
        normal = lift * np.cos(alpha) + drag * np.sin(alpha)
        axial = drag * np.cos(alpha) - lift * np.sin(alpha)
        pitch = self.cm0 + self.cm_per_rad * alpha
        side, roll, yaw = (k * lift for k in self.side_per_cl)
        return np.column_stack([axial, side, normal, roll, pitch, yaw])


def sweep_loads_tunnel(
    alpha_deg,
    capacity_tunnel,
    aero: AeroModel = AeroModel(),
    fractions=(
        LONGITUDINAL_FRACTION,
        LATERAL_FRACTION,
        LONGITUDINAL_FRACTION,
        LATERAL_FRACTION,
        LONGITUDINAL_FRACTION,
        LATERAL_FRACTION,
    ),
) -> np.ndarray:
    """Tunnel-axis loads (N, 6), N / N·m, each component scaled to fraction x capacity at its
    peak.
    """
    coefficients = aero.coefficients(alpha_deg)
    peak = np.max(np.abs(coefficients), axis=0)
    peak[peak == 0] = 1.0
    return (
        coefficients
        / peak
        * np.asarray(fractions)
        * np.abs(np.asarray(capacity_tunnel, dtype=float))
    )


@dataclass(frozen=True)
class WindOnProfile:
    """Per-sample loads of a wind-on run."""

    times_s: np.ndarray  # (S,) sample times from the start of the run
    condition: np.ndarray  # (S,) index into `label`; 0 is wind-off for a sweep
    label: tuple[str, ...]  # per condition, e.g. 'wind off', 'alpha=+4.0 deg'
    # (S, 6) aerodynamic loads, tunnel axes (what a tared calibrator reads)
    aero_tunnel: np.ndarray
    # (S, 6) everything on the balance (aero + model weight), balance axes
    loads_balance: np.ndarray


def aoa_sweep_profile(
    capacity,
    installation: Installation,
    rate_hz: float,
    *,
    alphas_deg=tuple(range(-2, 23, 2)),
    hold_s: float = 1.0,
    wind_off_s: float = 2.0,
    model_weight_n: float = 0.0,
    aero: AeroModel = AeroModel(),
) -> WindOnProfile:
    """Wind-off for wind_off_s, then each α held for hold_s, sampled at rate_hz."""
    if rate_hz <= 0 or hold_s <= 0 or wind_off_s < 0:
        raise ValueError('rate_hz and hold_s must be positive, wind_off_s not negative')
    alphas = np.asarray(alphas_deg, dtype=float)
    capacity_tunnel = installation.to_tunnel(np.asarray(capacity, dtype=float))
    conditions = np.vstack([np.zeros((1, 6)), sweep_loads_tunnel(alphas, capacity_tunnel, aero)])
    counts = np.array(
        [round(wind_off_s * rate_hz)] + [max(1, round(hold_s * rate_hz))] * len(alphas)
    )
    condition = np.repeat(np.arange(len(conditions)), counts)
    times = (np.arange(len(condition)) + 0.5) / rate_hz
    aero_tunnel = conditions[condition]
    weight_tunnel = np.array([0.0, 0.0, -float(model_weight_n), 0.0, 0.0, 0.0])
    labels = ('wind off',) + tuple(f'alpha={a:+.1f} deg' for a in alphas)
    return WindOnProfile(
        times,
        condition,
        labels,
        aero_tunnel,
        installation.from_tunnel(aero_tunnel + weight_tunnel),
    )


@dataclass(frozen=True)
class AeroRunProfile:
    """Per-sample state of a simulated tunnel run (aero_run_profile)."""

    times_s: np.ndarray  # (S,)
    condition: np.ndarray  # (S,) hold index
    label: tuple[str, ...]  # per hold
    # (S, 3) (φ, α, β) rad as the support reports it (/model/attitude)
    support_attitude: np.ndarray
    q_pa: np.ndarray  # (S,) /tunnel/dynamic_pressure
    attitude: np.ndarray  # (S, 3) the model's true attitude: support + deflection
    # (S, 6) true C_AF, C_Y, C_N, C_l, C_m, C_n about the MRC (NaN wind-off)
    body_coefficients: np.ndarray
    # (S, 6) true C_D, C_Y,w, C_L, C_l,s, C_m,s, C_n,s (NaN wind-off)
    wind_coefficients: np.ndarray
    aero_tunnel: np.ndarray  # (S, 6) air loads about the balance centre, tunnel axes of §10.2
    loads_tunnel: np.ndarray  # (S, 6) everything the balance carries (air + weight), tunnel axes
    loads_balance: np.ndarray  # (S, 6) the same in balance calibration axes


DEFAULT_WIND_OFF_ATTITUDES_DEG = tuple(
    (roll, alpha) for roll in (0.0, 90.0, 180.0, 270.0) for alpha in (-2.0, 10.0, 22.0)
)


@dataclass(frozen=True)
class TunnelRun:
    """How the tunnel drives a run (aero_run_profile): q∞ of the wind-on sweep (Pa), the sample
    rate (Hz), the wind-on α sweep (degrees, φ = β = 0) and how long each of its attitudes is
    held (s), the wind-off (φ, α) pairs (degrees) swept before and after it and their hold (s).
    """

    q_pa: float
    rate_hz: float
    alphas_deg: Sequence[float] | np.ndarray = tuple(range(-2, 23, 2))
    hold_s: float = 0.5
    wind_off_attitudes_deg: Sequence[tuple[float, float]] | np.ndarray = (
        DEFAULT_WIND_OFF_ATTITUDES_DEG
    )
    wind_off_hold_s: float = 0.3


def aero_run_profile(
    model: ModelDescription,
    installation: Installation,
    run: TunnelRun,
    *,
    weight_n: float,
    cg_m,
    aero: AeroModel = AeroModel(),
) -> AeroRunProfile:
    """A tunnel run: wind-off holds at (φ, α) pairs (degrees), the wind-on α sweep at q_pa (φ = β =
    0), then the same wind-off holds again (the tunnel shut down): the pre-run and post-run zeros
    that bracket the run, between which `reduce` interpolates a drifting zero. Each hold sampled at
    rate_hz (all of them as `run` says).

    The model's true attitude solves attitude = support + deflection(air + weight loads at that
    attitude) (aero/deflection.py); the air loads are the AeroModel's coefficients at the true α
    (about the model file's moment reference centre), the weight is weight_n at cg_m.
    """
    q_pa, rate_hz, hold_s, wind_off_hold_s = run.q_pa, run.rate_hz, run.hold_s, run.wind_off_hold_s
    if rate_hz <= 0 or hold_s <= 0 or wind_off_hold_s <= 0:
        raise ValueError('rate_hz, hold_s and wind_off_hold_s must be positive')
    if not q_pa > 0 or not weight_n >= 0:
        raise ValueError(
            f'dynamic pressure must be positive and weight not negative (q {q_pa} Pa, W '
            f'{weight_n} N)'
        )
    off = np.radians(np.asarray(run.wind_off_attitudes_deg, float).reshape(-1, 2))
    alphas = np.radians(np.asarray(run.alphas_deg, float))
    support_holds = np.vstack(
        [
            np.column_stack([off[:, 0], off[:, 1], np.zeros(len(off))]),
            np.column_stack([np.zeros(len(alphas)), alphas, np.zeros(len(alphas))]),
            np.column_stack([off[:, 0], off[:, 1], np.zeros(len(off))]),
        ]
    )
    q_holds = np.concatenate(
        [np.zeros(len(off)), np.full(len(alphas), float(q_pa)), np.zeros(len(off))]
    )
    wind_off_samples = np.full(len(off), max(1, round(wind_off_hold_s * rate_hz)))
    counts = np.concatenate(
        [wind_off_samples, np.full(len(alphas), max(1, round(hold_s * rate_hz))), wind_off_samples]
    )
    wind_off_labels = tuple(
        f'roll={np.degrees(r):+.0f} deg, alpha={np.degrees(a):+.1f} deg' for r, a in off
    )
    labels = (
        tuple(f'wind off, {label}' for label in wind_off_labels)
        + tuple(f'alpha={np.degrees(a):+.1f} deg' for a in alphas)
        + tuple(f'wind off after the run, {label}' for label in wind_off_labels)
    )

    def body_at(attitude):
        body = aero.coefficients(np.degrees(attitude[:, 1]))
        return np.where(q_holds[:, None] > 0, body, 0.0)

    def total_at(attitude):
        return air_loads_from_coefficients(body_at(attitude), q_holds, model) + weight_loads(
            attitude, weight_n, cg_m
        )

    attitude = iterate_attitude(support_holds, model.deflection, total_at)
    body = body_at(attitude)
    aero_loads = air_loads_from_coefficients(body, q_holds, model)
    total = aero_loads + weight_loads(attitude, weight_n, cg_m)
    wind = wind_coefficients(body, attitude[:, 1], attitude[:, 2])
    body[q_holds <= 0] = np.nan
    wind[q_holds <= 0] = np.nan
    condition = np.repeat(np.arange(len(q_holds)), counts)
    times = (np.arange(len(condition)) + 0.5) / rate_hz
    return AeroRunProfile(
        times,
        condition,
        labels,
        support_holds[condition],
        q_holds[condition],
        attitude[condition],
        body[condition],
        wind[condition],
        aero_loads[condition],
        total[condition],
        installation.from_tunnel(total[condition]),
    )


def csv_profile(path: str | Path, installation: Installation, rate_hz: float) -> WindOnProfile:
    """Loads from a CSV with columns time_s,FX,FY,FZ,MX,MY,MZ (balance axes, N / N·m), linearly
    interpolated at rate_hz. Repeat a time to make a step. ValueError names file and line.
    """
    path = Path(path)
    try:
        with open(path, newline='') as handle:
            rows = list(csv.DictReader(handle))
    except OSError as err:
        raise ValueError(f'{path}: cannot read load profile: {err.strerror or err}') from None
    columns = ('time_s',) + COMPONENTS
    if not rows or any(c not in rows[0] for c in columns):
        raise ValueError(f'{path}: load profile needs a header with columns {",".join(columns)}')
    table = np.empty((len(rows), len(columns)))
    for line, row in enumerate(rows, start=2):
        try:
            table[line - 2] = [float(row[c]) for c in columns]
        except (TypeError, ValueError):
            raise ValueError(
                f'{path}: line {line}: expected numbers in {",".join(columns)}'
            ) from None
    if not np.all(np.isfinite(table)) or np.any(np.diff(table[:, 0]) < 0):
        raise ValueError(f'{path}: load profile must be finite with non-decreasing time_s')
    times = np.arange(table[0, 0], table[-1, 0], 1.0 / rate_hz) + 0.5 / rate_hz
    loads = np.column_stack([np.interp(times, table[:, 0], table[:, 1 + k]) for k in range(6)])
    _, condition = np.unique(loads, axis=0, return_inverse=True)
    return WindOnProfile(
        times - table[0, 0], condition.ravel(), (), installation.to_tunnel(loads), loads
    )


@dataclass(frozen=True)
class BalanceEffects:
    """The balance's own effects (simulation/effects.py) and what they depend on: the samples'
    times (s; None: 0, 1, 2, ...), the temperature (°C, one or per sample), the rated outputs (6,)
    mV (None: 1 each) and the reference temperature (°C).
    """

    effects: Sequence[Effect] = ()
    times_s: np.ndarray | None = None
    temperature_c: float | np.ndarray = 20.0
    rated_output_mv: Sequence[float] | np.ndarray | None = None
    reference_temperature_c: float = 20.0


def wind_on_outputs(
    truth: BalanceModel,
    loads_balance,
    *,
    electrical_zero_mv=0.04,
    noise_mv=0.0,
    seed: int = 0,
    balance_effects: BalanceEffects = BalanceEffects(),
) -> np.ndarray:
    """Raw bridge outputs (S, 6) mV for loads (S, 6): inverse of the truth without constants
    (§10.1), plus the effects the balance has (balance_effects: temperature, hysteresis from the
    load history, ...), the electrical zero and Gaussian noise (σ noise_mv per bridge).
    """
    from ..simulation.balance_sim import _direction_history

    conditions = balance_effects
    effects = conditions.effects
    loads = np.atleast_2d(np.asarray(loads_balance, dtype=float))
    model = truth.without_constant()
    for effect in effects:
        model = effect.truth(model)
    unique, inverse = np.unique(loads, axis=0, return_inverse=True)
    outputs = outputs_for_loads(model, unique)[inverse.ravel()]
    if effects:
        n = len(loads)
        ctx = SampleContext(
            np.arange(n, dtype=float)
            if conditions.times_s is None
            else np.asarray(conditions.times_s, float),
            np.broadcast_to(np.asarray(conditions.temperature_c, float), (n,)),
            loads,
            outputs,
            _direction_history(loads),
            np.ones(6)
            if conditions.rated_output_mv is None
            else np.asarray(conditions.rated_output_mv, float),
            conditions.reference_temperature_c,
        )
        for effect in effects:
            outputs = effect.outputs(outputs, ctx)
    rng = np.random.default_rng(seed)
    noise = rng.normal(size=outputs.shape) * np.asarray(noise_mv, float)
    return outputs + np.asarray(electrical_zero_mv, float) + noise
