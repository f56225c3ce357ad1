"""A simulated thrust stand (lab manual, seed 003) for `bridge_publisher`'s `thrust_stand` mode.

No rclpy here: the node asks `ThrustStandSimulator.sample(t)` for the three signals at time t
and publishes them; `applied_load_events()` gives what goes on /calibration/applied_load.

One cycle, as the manual runs the experiment (calibration *after* the firings, footnote 12):

    idle | (firing, idle while venting) x firings | pressurise |
    loaded 0, unloaded 0, ..., loaded n, unloaded n | depressurise

- firing: the solenoid valve opens, the chamber gauge pressure rises to `firing_gauge_pa` with
  time constant `pressure_rise_s`; thrust = `efficiency` x the ideal thrust of eq. (5) at the
  instantaneous p_c (the manual warns measured and theory differ a lot). After the valve closes
  the chamber vents through the nozzle with time constant `pressure_decay_s`, still thrusting.
  Below the chamber pressure at which a normal shock enters the nozzle eq. (5) does not hold;
  the thrust there is interpolated linearly to zero at p_c = p_a.
- calibration: nozzle plugged and chamber held at `firing_gauge_pa` (§4.2: the pressurised
  piping stiffens the stand); step k hangs the pan and the first k weights, then takes the pan
  down again. The leaf spring takes a set under each load: the zero moves by
  `hysteresis_fraction` of that load's reading and stays there after unloading, so the manual's
  correction (loaded minus the residual zero read after it) recovers the true sensitivity.
- each cycle starts with the strain meter rebalanced: the accumulated set is gone.
- every abrupt force change rings the stand (second order, `ring_frequency_hz`,
  `ring_damping_ratio`): "wait until the chamber's vibration has decayed" (§4.1).

Signals: strain channel in mV (`force.x` of /balance/raw, the other five 0), chamber gauge
pressure p_G in Pa (/thrust_stand/chamber_pressure) and ambient pressure p_a in Pa
(/thrust_stand/ambient_pressure).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..thrust_stand.calibration import CalibrationReadings
from ..thrust_stand.nozzle import (
    DEFAULT_CHAMBER_K,
    Nozzle,
    shock_free_ambient_ratio,
    STANDARD_ATMOSPHERE_PA,
)
from ..thrust_stand.nozzle import (
    thrust_n as ideal_thrust_n,
)
from ..units import STANDARD_GRAVITY_M_S2

# five lead fishing sinkers of "about 85 g", not identical (§3.1 item 12, §4.2)
DEFAULT_WEIGHT_MASSES_KG = (0.0852, 0.0847, 0.0861, 0.0839, 0.0856)
# overshoot of the stand when the valve opens, fraction of the firing thrust
FIRING_RING_AMPLITUDE = 0.3


@dataclass(frozen=True)
class Segment:
    """A stretch of the cycle with one valve / load state."""

    kind: str  # idle, firing, pressurise, loaded, unloaded, depressurise
    start_s: float
    end_s: float
    nozzle_open: bool  # False while plugged for the calibration
    gauge_target_pa: float  # the chamber gauge pressure approaches this
    applied_load_n: float  # weights + pan hanging on the stand (calibration), else 0
    weights: int = 0  # how many weights on the pan (loaded steps)


@dataclass(frozen=True)
class ThrustStandSample:
    strain_mv: float | np.ndarray  # strain channel, mV
    chamber_gauge_pa: float | np.ndarray  # p_G, gauge (manual footnote 5)
    ambient_pa: float | np.ndarray  # p_a, absolute

    def bridge_outputs_mv(self) -> np.ndarray:
        """(6,) or (N, 6): FXV = strain channel, the other five bridge outputs 0 (/balance/raw)."""
        strain = np.asarray(self.strain_mv, dtype=float)
        outputs = np.zeros(strain.shape + (6,))
        outputs[..., 0] = strain
        return outputs


@dataclass(frozen=True)
class StandBuild:
    """The stand as built (SI; the defaults give about 3.4 N ideal thrust at p_G = 0.5 MPa).

    nozzle: the manual's D_t 2.5 mm, D_e 3.3 mm, γ 1.402, R 287.1 by default; efficiency:
    measured / ideal thrust during firing, < 1; calibration_slope_n_per_mv: the true sensitivity a
    of the stand, N per mV; zero_offset_mv: the strain reading with nothing applied;
    weight_masses_kg: the calibration weights in loading order (five of ~85 g); pan_mass_kg: pan
    and thread, always hanging during a calibration step; hysteresis_fraction: the leaf spring's
    set per load, a fraction of that load's reading; ring_frequency_hz, ring_damping_ratio: the
    stand's ringing after a force step.
    """

    nozzle: Nozzle = Nozzle()
    efficiency: float = 0.75
    calibration_slope_n_per_mv: float = 5.0
    zero_offset_mv: float = 0.05
    weight_masses_kg: tuple[float, ...] = DEFAULT_WEIGHT_MASSES_KG
    pan_mass_kg: float = 0.015
    hysteresis_fraction: float = 0.01
    ring_frequency_hz: float = 10.0
    ring_damping_ratio: float = 0.15


@dataclass(frozen=True)
class FiringCycle:
    """One cycle of the experiment (module docstring), SI.

    firing_gauge_pa: the regulator fully open, p_G during firing and calibration; ambient_pa: p_a;
    chamber_k: T_c, for the record (the thrust does not depend on it, eq. (5)); firings per cycle;
    idle_s, firing_s, step_s: durations of idle/venting, of a firing and of each calibration step;
    settle_s: time after a change before the reading counts as steady; pressure_rise_s,
    pressure_decay_s: first-order time constants of p_G; repeat: True, the cycle repeats forever;
    False, idle after its end.
    """

    firing_gauge_pa: float = 0.5e6
    ambient_pa: float = STANDARD_ATMOSPHERE_PA
    chamber_k: float = DEFAULT_CHAMBER_K
    firings: int = 2
    idle_s: float = 2.0
    firing_s: float = 3.0
    step_s: float = 2.0
    settle_s: float = 0.5
    pressure_rise_s: float = 0.1
    pressure_decay_s: float = 0.6
    repeat: bool = True


@dataclass(frozen=True)
class SignalNoise:
    """White noise σ on the three signals: strain mV, chamber gauge and ambient pressure Pa."""

    strain_noise_mv: float = 0.001
    gauge_noise_pa: float = 1500.0
    ambient_noise_pa: float = 10.0


class ThrustStandSimulator:
    """The manual's stand: one strain channel, chamber and ambient pressure, in simulated time.

    stand: the stand as built (StandBuild); cycle: the experiment's sequence and timing
    (FiringCycle); noise: the signals' white noise (SignalNoise); seed: the noise generator's seed.
    """

    def __init__(
        self,
        *,
        stand: StandBuild = StandBuild(),
        cycle: FiringCycle = FiringCycle(),
        noise: SignalNoise = SignalNoise(),
        seed: int | None = 0,
    ) -> None:
        efficiency, idle_s, firing_s, step_s, settle_s = (
            stand.efficiency,
            cycle.idle_s,
            cycle.firing_s,
            cycle.step_s,
            cycle.settle_s,
        )
        if not 0 < efficiency <= 1:
            raise ValueError(f'efficiency must be in (0, 1], got {efficiency}')
        if stand.calibration_slope_n_per_mv <= 0:
            raise ValueError('calibration_slope_n_per_mv must be positive')
        if (
            min(idle_s, firing_s, step_s, cycle.pressure_rise_s, cycle.pressure_decay_s) <= 0
            or not 0 <= settle_s < step_s
        ):
            raise ValueError(
                'durations and time constants must be positive, settle_s shorter than step_s'
            )
        if cycle.firing_gauge_pa <= 0 or cycle.ambient_pa <= 0 or cycle.firings < 0:
            raise ValueError('firing_gauge_pa and ambient_pa must be positive, firings >= 0')
        self.nozzle = nozzle = stand.nozzle
        self.efficiency = float(efficiency)
        self.calibration_slope_n_per_mv = float(stand.calibration_slope_n_per_mv)
        self.zero_offset_mv = float(stand.zero_offset_mv)
        self.weight_masses_kg = np.asarray(stand.weight_masses_kg, dtype=float)
        self.pan_mass_kg = float(stand.pan_mass_kg)
        self.hysteresis_fraction = float(stand.hysteresis_fraction)
        self.firing_gauge_pa = float(cycle.firing_gauge_pa)
        self.ambient_pa = float(cycle.ambient_pa)
        self.chamber_k = float(cycle.chamber_k)
        self.settle_s = float(settle_s)
        self.pressure_rise_s = float(cycle.pressure_rise_s)
        self.pressure_decay_s = float(cycle.pressure_decay_s)
        self.ring_frequency_hz = float(stand.ring_frequency_hz)
        self.ring_damping_ratio = float(stand.ring_damping_ratio)
        self.strain_noise_mv = float(noise.strain_noise_mv)
        self.gauge_noise_pa = float(noise.gauge_noise_pa)
        self.ambient_noise_pa = float(noise.ambient_noise_pa)
        self.repeat = bool(cycle.repeat)
        self._rng = np.random.default_rng(seed)
        self._shock_free_ratio = shock_free_ambient_ratio(nozzle.area_ratio, nozzle.gamma)
        self.segments = self._schedule(
            int(cycle.firings), float(idle_s), float(firing_s), float(step_s)
        )
        self.duration_s = self.segments[-1].end_s
        self._start_gauge_pa = self._segment_start_pressures()
        self._set_mv = self._segment_sets()

    # --- the schedule -------------------------------------------------------------------------
    def _schedule(self, firings, idle_s, firing_s, step_s) -> tuple[Segment, ...]:
        segments, t = [], 0.0

        def add(kind, duration, nozzle_open, gauge_pa, load_n=0.0, weights=0):
            nonlocal t
            segments.append(Segment(kind, t, t + duration, nozzle_open, gauge_pa, load_n, weights))
            t += duration

        add('idle', idle_s, True, 0.0)
        for _ in range(firings):
            add('firing', firing_s, True, self.firing_gauge_pa)
            add('idle', idle_s, True, 0.0)
        add('pressurise', idle_s, False, self.firing_gauge_pa)
        for k in range(self.weight_masses_kg.size + 1):
            load_n = (self.pan_mass_kg + self.weight_masses_kg[:k].sum()) * STANDARD_GRAVITY_M_S2
            add('loaded', step_s, False, self.firing_gauge_pa, float(load_n), k)
            add('unloaded', step_s, False, self.firing_gauge_pa, 0.0, k)
        # long enough to bleed the chamber nearly to zero before the next cycle
        add('depressurise', max(idle_s, 8.0 * self.pressure_decay_s), False, 0.0)
        return tuple(segments)

    def _segment_start_pressures(self) -> np.ndarray:
        start = 0.0
        # repeating: each cycle starts where the previous one's venting ended; a few passes reach
        # that fixed point to rounding (every firing and the final bleed forget the start value)
        for _ in range(3 if self.repeat else 1):
            pressures = []
            for segment in self.segments:
                pressures.append(start)
                start = float(self._pressure_in(segment, start, segment.end_s - segment.start_s))
        return np.array(pressures, dtype=float)

    def _pressure_in(self, segment: Segment, start_pa, elapsed_s):
        tau = self.pressure_rise_s if segment.gauge_target_pa > start_pa else self.pressure_decay_s
        return segment.gauge_target_pa + (start_pa - segment.gauge_target_pa) * np.exp(
            -elapsed_s / tau
        )

    def _segment_sets(self) -> np.ndarray:
        """Leaf-spring set (mV) during each segment: grows at each loaded step, then stays."""
        sets, total = [], 0.0
        for segment in self.segments:
            if segment.kind == 'loaded':
                total += (
                    self.hysteresis_fraction
                    * segment.applied_load_n
                    / self.calibration_slope_n_per_mv
                )
            sets.append(total)
        return np.array(sets)

    # --- physics ------------------------------------------------------------------------------
    def thrust_at_gauge_pa(self, chamber_gauge_pa):
        """Thrust (N) of the real (inefficient) nozzle at steady p_G, nozzle open."""
        gauge = np.asarray(chamber_gauge_pa, dtype=float)
        chamber = gauge + self.ambient_pa
        shock_free_chamber_pa = self.ambient_pa / self._shock_free_ratio
        ratio = self.nozzle.pe_over_pc()
        ideal = ideal_thrust_n(
            np.maximum(chamber, shock_free_chamber_pa),
            self.ambient_pa,
            self.nozzle.throat_area_m2,
            self.nozzle.exit_area_m2,
            ratio,
            self.nozzle.gamma,
        )
        ramp = np.clip(
            (chamber - self.ambient_pa) / (shock_free_chamber_pa - self.ambient_pa), 0.0, 1.0
        )
        thrust = np.where(chamber >= shock_free_chamber_pa, ideal, ideal * ramp)
        return self.efficiency * thrust

    @property
    def firing_thrust_n(self) -> float:
        """Steady thrust during a firing, N."""
        return float(self.thrust_at_gauge_pa(self.firing_gauge_pa))

    @property
    def firing_cf(self) -> float:
        """The C_F a perfect measurement of a steady firing gives: efficiency x eq. (12)."""
        return self.firing_thrust_n / (
            (self.firing_gauge_pa + self.ambient_pa) * self.nozzle.throat_area_m2
        )

    def _cycle_time(self, time_s: np.ndarray) -> np.ndarray:
        if self.repeat:
            return np.mod(time_s, self.duration_s)
        return np.clip(time_s, 0.0, self.duration_s - 1e-12)

    def _noise_free(self, time_s):
        t = self._cycle_time(np.asarray(time_s, dtype=float))
        index = np.clip(
            np.searchsorted([s.start_s for s in self.segments], t, side='right') - 1,
            0,
            len(self.segments) - 1,
        )
        gauge = np.zeros_like(t)
        force = np.zeros_like(t)
        strain_extra = self._set_mv[index]
        for i, segment in enumerate(self.segments):
            mask = index == i
            if not np.any(mask):
                continue
            gauge[mask] = self._pressure_in(
                segment, self._start_gauge_pa[i], t[mask] - segment.start_s
            )
            if segment.nozzle_open:
                force[mask] = self.thrust_at_gauge_pa(gauge[mask])
            else:
                force[mask] = segment.applied_load_n
        strain_extra = strain_extra + self._ringing_mv(t)
        strain = self.zero_offset_mv + strain_extra + force / self.calibration_slope_n_per_mv
        return strain, gauge, force

    def _ringing_mv(self, t: np.ndarray) -> np.ndarray:
        """Deviation from the final value of a second-order step response, summed over force
        steps.
        """
        omega = 2 * np.pi * self.ring_frequency_hz
        zeta = self.ring_damping_ratio
        omega_d = omega * np.sqrt(1 - zeta**2)
        ringing = np.zeros_like(t)
        last_load_n = 0.0
        for segment in self.segments:
            if segment.kind == 'firing':
                step = self.firing_thrust_n  # the valve opens fast; closing vents slowly, no ring
            elif segment.kind == 'loaded':
                step = last_load_n = segment.applied_load_n
            elif segment.kind == 'unloaded':
                step = -last_load_n
            else:
                continue
            elapsed = t - segment.start_s
            active = elapsed >= 0
            decay = np.exp(-zeta * omega * elapsed[active])
            if segment.kind == 'firing':
                # thrust builds with the chamber pressure, not as a step: an overshoot from zero
                shape = FIRING_RING_AMPLITUDE * decay * np.sin(omega_d * elapsed[active])
            else:
                # step response minus final value
                shape = -decay * np.cos(omega_d * elapsed[active])
            ringing[active] += step / self.calibration_slope_n_per_mv * shape
        return ringing

    # --- what the node calls ------------------------------------------------------------------
    def sample(self, time_s) -> ThrustStandSample:
        """The three signals at time_s (s from the start of the run; scalar or (N,) array), with
        noise.
        """
        scalar = np.ndim(time_s) == 0
        strain, gauge, _ = self._noise_free(np.atleast_1d(time_s))
        strain = strain + self.strain_noise_mv * self._rng.standard_normal(strain.shape)
        gauge = gauge + self.gauge_noise_pa * self._rng.standard_normal(gauge.shape)
        ambient = self.ambient_pa + self.ambient_noise_pa * self._rng.standard_normal(strain.shape)
        if scalar:
            return ThrustStandSample(float(strain[0]), float(gauge[0]), float(ambient[0]))
        return ThrustStandSample(strain, gauge, ambient)

    def true_force_n(self, time_s):
        """Noise-free force on the stand (thrust or weights + pan), N."""
        return self._noise_free(np.atleast_1d(time_s))[2]

    def applied_load_events(self) -> tuple[tuple[float, float], ...]:
        """(time_s, F_X in N) for /calibration/applied_load during one cycle: NaN when a step
        begins (weights being changed), the load hanging (weights + pan; 0 for the unloaded,
        zero points) once it has settled. Add k·duration_s in the k-th repetition.
        """
        events = []
        for segment in self.segments:
            if segment.kind in ('loaded', 'unloaded'):
                events.append((segment.start_s, float('nan')))
                events.append((segment.start_s + self.settle_s, segment.applied_load_n))
        return tuple(events)

    def firing_windows(self) -> tuple[tuple[float, float], ...]:
        """(start_s, end_s) of the steady part of each firing in one cycle."""
        return tuple(
            (s.start_s + self.settle_s, s.end_s) for s in self.segments if s.kind == 'firing'
        )

    def calibration_readings(self, sample_rate_hz: float = 200.0) -> CalibrationReadings:
        """What the student writes down in §4.2: each step's steady strain reading (averaged),
        with the weights' true masses. Uses (and advances) the noise generator.
        """
        loaded, unloaded = [], []
        for segment in self.segments:
            if segment.kind not in ('loaded', 'unloaded'):
                continue
            times = np.arange(segment.start_s + self.settle_s, segment.end_s, 1.0 / sample_rate_hz)
            reading = float(np.mean(self.sample(times).strain_mv))
            (loaded if segment.kind == 'loaded' else unloaded).append(reading)
        return CalibrationReadings(self.weight_masses_kg, np.array(loaded), np.array(unloaded))
