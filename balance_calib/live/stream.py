"""The live calibrator's state between samples, without rclpy: what balance_calibrator orchestrates.

`LiveCalibrator.process()` takes a batch of raw samples (outputs, stamps, frame ids) and returns the
wrenches to publish; around the math of calibrator_core it keeps the electrical zero and the tare
load (with their ~/zero and ~/tare windows), the overload state, the optional low-pass filter, the
load history of hysteresis models and the input's health (stamps, frame ids, gaps). The node only
turns messages into arrays and back.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

from typing import Callable

import numpy as np

from ..units import BRIDGE_OUTPUTS, COMPONENTS
from .calibrator_core import (ActiveCalibration, InputCounters, LiveState, LoadHistory, StatusReport, TareResult,
                              TareWindow, WrenchBatch, _extra_variables, compute_wrench, diagnostics, evaluate_window,
                              six_axis_loads)
from . import lone_sample
from .tare_store import TareState, now_iso


@dataclass(frozen=True)
class LiveSettings:
    stale_after_s: float = 1.0
    overload_fraction: float = 1.0      # x rated load
    overload_clear_s: float = 1.0
    lowpass_hz: float = 0.0             # 0 = off
    tare_max_ratio: float = 4.0         # steadiness: scatter and step limit, x the window's own noise
    publish_uncertainty: bool = True


class InputMonitor:
    """Stamps out of order, duplicated or zero, frame ids naming another balance, and gaps (lost samples).

    The nominal sample interval is the median of the last 256 positive stamp differences (re-taken
    every 64 samples); a gap of d > 1.5 intervals counts round(d / interval) - 1 samples lost.
    """

    KINDS = ('stamps out of order', 'duplicate stamps', 'zero stamps', 'samples from another balance',
             'samples lost (gaps in the stamps)')

    def __init__(self, balance: str):
        self.balance = balance.lower()
        self.total = dict.fromkeys(self.KINDS, 0)
        self.period = dict.fromkeys(self.KINDS, 0)
        self.foreign_frames: set[str] = set()
        self.last_stamp_ns: int | None = None
        self.interval_ns: float | None = None
        self._differences = np.zeros(256, dtype=np.int64)
        self._filled = 0
        self._since_estimate = 0

    def _add(self, kind: str, count: int) -> None:
        if count:
            self.total[kind] += count
            self.period[kind] += count

    def update(self, stamps_ns: np.ndarray, frame_ids=None) -> None:
        if len(stamps_ns) == 1:
            self.update_one(int(stamps_ns[0]), frame_ids[0] if frame_ids else '')
            return
        stamps = np.asarray(stamps_ns, dtype=np.int64)
        if frame_ids is not None:
            foreign = [f for f in frame_ids if f and f.lower() != self.balance]
            if foreign:
                self._add('samples from another balance', len(foreign))
                if len(self.foreign_frames) < 8:
                    self.foreign_frames.update(foreign[:8])
        zero = stamps == 0
        self._add('zero stamps', int(np.count_nonzero(zero)))
        stamps = stamps[~zero]
        if not len(stamps):
            return
        first = self.last_stamp_ns is None
        prior = int(stamps[0]) if first else self.last_stamp_ns
        before = np.maximum.accumulate(np.concatenate([[prior], stamps]))[:-1]
        differences = stamps - before
        if first:
            differences = differences[1:]
        self._add('stamps out of order', int(np.count_nonzero(differences < 0)))
        self._add('duplicate stamps', int(np.count_nonzero(differences == 0)))
        self.last_stamp_ns = int(max(prior, stamps.max()))
        positive = differences[differences > 0]
        if self.interval_ns is None and len(positive) >= 3:     # a first batch: its own median
            self.interval_ns = float(np.median(positive))
        if self.interval_ns is not None and len(positive):
            gaps = positive[positive > 1.5 * self.interval_ns]
            if len(gaps):
                self._add('samples lost (gaps in the stamps)', int(np.sum(np.rint(gaps / self.interval_ns) - 1)))
        take = positive[-256:]
        start = self._filled % 256
        indices = (start + np.arange(len(take))) % 256
        self._differences[indices] = take
        self._filled += len(take)
        self._since_estimate += len(take)
        if self._filled and (self.interval_ns is None or self._since_estimate >= 64):
            self.interval_ns = float(np.median(self._differences[:min(self._filled, 256)]))
            self._since_estimate = 0

    def update_one(self, stamp: int, frame_id: str) -> None:
        """update() for one sample, in plain Python (the live path at low rates)."""
        if frame_id and frame_id.lower() != self.balance:
            self._add('samples from another balance', 1)
            if len(self.foreign_frames) < 8:
                self.foreign_frames.add(frame_id)
        if stamp == 0:
            self._add('zero stamps', 1)
            return
        if self.last_stamp_ns is None:
            self.last_stamp_ns = stamp
            return
        difference = stamp - self.last_stamp_ns
        if difference <= 0:
            self._add('stamps out of order' if difference < 0 else 'duplicate stamps', 1)
            return
        if self.interval_ns is not None and difference > 1.5 * self.interval_ns:
            self._add('samples lost (gaps in the stamps)', int(round(difference / self.interval_ns)) - 1)
        self.last_stamp_ns = stamp
        self._differences[self._filled % 256] = difference
        self._filled += 1
        self._since_estimate += 1
        if self.interval_ns is None or self._since_estimate >= 64:
            self.interval_ns = float(np.median(self._differences[:min(self._filled, 256)]))
            self._since_estimate = 0

    def problems(self) -> tuple[tuple[str, int, int], ...]:
        return tuple((kind, self.total[kind], self.period[kind]) for kind in self.KINDS)

    def start_period(self) -> None:
        self.period = dict.fromkeys(self.KINDS, 0)


class OverloadMonitor:
    """True as soon as any component's load exceeds capacity x fraction (or a bridge saturates); false
    again once the samples have stayed inside for clear_s."""

    def __init__(self, capacity: np.ndarray, fraction: float, clear_s: float):
        self.capacity = capacity
        self.fraction = fraction
        self.clear_s = clear_s
        self.active = False
        self.components: tuple[str, ...] = ()
        self.inside_since_s: float | None = None
        self.peak_fraction = np.zeros(6)
        self.events = 0

    @property
    def capacity(self) -> np.ndarray:
        return self._capacity

    @capacity.setter
    def capacity(self, value) -> None:
        self._capacity = np.asarray(value, dtype=float)
        self.capacity_list = self._capacity.tolist()

    def _exceeds_one(self, loads: list | tuple) -> bool:
        """One sample's loads (6 floats): its peak noted; True if any exceeds the limit."""
        ratios = [abs(v) / c for v, c in zip(loads, self.capacity_list)]
        peak = self.peak_fraction
        if any(r > p for r, p in zip(ratios, peak.tolist())):
            np.maximum(peak, ratios, out=peak)
        return any(r > self.fraction for r in ratios)

    def update(self, loads_total: np.ndarray, saturated: np.ndarray, now_s: float) -> bool:
        """Feed a batch (loads of the accepted samples (N, 6), saturated flags); True if the state changed."""
        if len(loads_total) == 1 and len(saturated) == 1 and not self.active and not saturated[0]:   # lone sample
            if not self._exceeds_one(loads_total[0].tolist()):
                return False
        if len(loads_total):
            ratio = np.abs(loads_total).max(axis=0) / self.capacity
            np.maximum(self.peak_fraction, ratio, out=self.peak_fraction)
            exceeded = ratio > self.fraction
        else:
            exceeded = np.zeros(6, bool)
        if exceeded.any() or saturated.any():
            names = tuple(COMPONENTS[k] for k in np.flatnonzero(exceeded)) + (('saturated bridge',)
                                                                               if np.any(saturated) else ())
            changed = not self.active
            self.active, self.inside_since_s = True, None
            self.components = names if changed else tuple(dict.fromkeys(self.components + names))
            self.events += changed
            return changed
        if self.active and len(loads_total):
            if self.inside_since_s is None:
                self.inside_since_s = now_s
            elif now_s - self.inside_since_s >= self.clear_s:
                self.active, self.components, self.inside_since_s = False, (), None
                return True
        return False

    def values(self) -> tuple[tuple[str, str], ...]:
        return (('overload', str(self.active)), ('overload_fraction', f'{self.fraction:g}'),
                ('overload_events', str(self.events)),
                ('peak_load_fraction_of_rated', ', '.join(f'{c}={v:.3f}' for c, v in
                                                          zip(COMPONENTS, self.peak_fraction))))


class LowPass:
    """First-order low-pass on each component, y += a (x - y) with a = 1 - exp(-2π f_c Δt), state carried
    across batches (scipy.signal.lfilter for a batch)."""

    def __init__(self, cutoff_hz: float):
        self.cutoff_hz = cutoff_hz
        self.state: np.ndarray | None = None

    def reset(self) -> None:
        self.state = None

    def apply(self, values: np.ndarray, interval_s: float | None) -> np.ndarray:
        if self.cutoff_hz <= 0 or not len(values):
            return values
        if self.state is None:
            self.state = values[0].copy()
        if interval_s is None:
            self.state = values[-1].copy()
            return values
        a = 1.0 - np.exp(-2.0 * np.pi * self.cutoff_hz * interval_s)
        if len(values) == 1:
            self.state = self.state + a * (values[0] - self.state)
            return self.state[None, :].copy()
        from scipy.signal import lfilter
        out, _ = lfilter([a], [1.0, a - 1.0], values, axis=0, zi=((1.0 - a) * self.state)[None, :])
        self.state = out[-1].copy()
        return out


@dataclass
class Published:
    """The samples of a batch to publish: their indices in the batch and their wrenches (M, 6)."""

    indices: np.ndarray
    wrench: np.ndarray
    batch: WrenchBatch
    uncertainty: np.ndarray | None = None     # (M, 6) standard uncertainty, tunnel axes; None = not available
    uncertainty_later: Callable[[], np.ndarray | None] | None = None   # with defer_uncertainty: computes it


def wrench_uncertainty(active: ActiveCalibration, zeroed_outputs: np.ndarray, tare_sigma, *, model=None,
                       extra=None, loads_balance=None, design=None) -> np.ndarray | None:
    """Standard uncertainty (k = 1) of each published load (M, 6), N / N·m, tunnel axes: the calibration's
    coefficient covariance and residual σ (model/uncertainty.py) at these outputs, and the tare's own
    scatter. `model`: the one that gave the loads (default the active model; the base model after a
    fallback); `extra`: its variables besides the outputs (dT, dir_*) for these samples, as for its
    loads(); `loads_balance` (M, 6): the loads it gave, balance axes, so that an iterative model is not
    solved twice; `design` (M, n_terms): its design rows, if computed already. None when the model has no covariance (the memo's matrices) or needs an input it
    was not given. A component the calibration lacks (a 1-, 3- or 5-component balance) is NaN:
    its 0 is not a measurement."""
    from ..model.uncertainty import design_row_uncertainty, has_uncertainty, load_standard_uncertainty
    model = active.model if model is None else model
    positions = [COMPONENTS.index(c) for c in model.components]
    tare = None if tare_sigma is None else np.asarray(tare_sigma)[positions]
    iterative = getattr(model, 'form', 'direct') == 'iterative'
    if design is not None and len(zeroed_outputs) == 1 and not iterative and not model.extra_variables:
        per_component = design_row_uncertainty(model, design, tare)      # a lone sample: its row is known
        if per_component is None:
            return None
    else:
        if (model.extra_variables and extra is None) or not has_uncertainty(model):
            return None
        columns = [BRIDGE_OUTPUTS.index(v) for v in model.inputs]
        per_component = load_standard_uncertainty(
            model, zeroed_outputs[:, columns], extra, tare_sigma=tare,
            loads=None if loads_balance is None or not iterative else np.asarray(loads_balance)[:, positions],
            design=design)
    six = np.full((len(zeroed_outputs), 6), np.nan)     # NaN: a component the calibration lacks
    six[:, positions] = per_component
    return np.abs(active.installation.to_tunnel(six))       # a signed permutation: magnitudes carry over


@dataclass
class LiveCalibrator:
    active: ActiveCalibration
    settings: LiveSettings = field(default_factory=LiveSettings)
    tare: TareState | None = None

    def __post_init__(self):
        self.tare = self.tare or TareState(self.active.calibration.balance)
        self.counters = InputCounters()
        self.inputs = InputMonitor(self.active.calibration.balance)
        self.overload = OverloadMonitor(self.active.capacity, self.settings.overload_fraction,
                                        self.settings.overload_clear_s)
        self.lowpass = LowPass(self.settings.lowpass_hz)
        self.history = LoadHistory(self.active.capacity)
        self.window: TareWindow | None = None
        self.fallback_reason = ''
        self.overload_changed = False
        self.uncertainty_wanted = True
        self._lone_plan, self._lone_plan_for = None, None

    # --- configuration --------------------------------------------------------------------------
    def set_active(self, active: ActiveCalibration) -> None:
        """A new calibration (refit, parameters), between two samples; zero and tare stay."""
        self.active = active
        self.history = LoadHistory(active.capacity)
        self.overload.capacity = active.capacity
        self.inputs.balance = active.calibration.balance.lower()

    def set_settings(self, settings: LiveSettings) -> None:
        if settings.lowpass_hz != self.settings.lowpass_hz:
            self.lowpass = LowPass(settings.lowpass_hz)
        self.overload.fraction, self.overload.clear_s = settings.overload_fraction, settings.overload_clear_s
        self.settings = settings

    # --- the stream -----------------------------------------------------------------------------
    def process(self, outputs_mv: np.ndarray, stamps_ns: np.ndarray, frame_ids=None, *, now_s: float,
                temperature_c: float | None = None, uncertainty_wanted: bool = True,
                defer_uncertainty: bool = False) -> Published:
        """A batch of raw samples (N, 6) mV in arrival order -> what to publish. uncertainty_wanted: False
        when nobody subscribes to it (the node asks its publisher): not computed then. defer_uncertainty:
        leave it to Published.uncertainty_later(), so that the wrench goes out first."""
        self.uncertainty_wanted = uncertainty_wanted
        outputs = np.atleast_2d(np.asarray(outputs_mv, dtype=float))
        self.inputs.update(stamps_ns, frame_ids)
        active, tare = self.active, self.tare
        direction = None
        if 'load_history' in active.requires:
            finite = active.inputs_finite(outputs)
            zeroed = outputs[finite] - (0.0 if tare.zero_mv is None else tare.zero_mv)
            direction = np.ones((len(outputs), 6))
            direction[finite] = self.history.update(six_axis_loads(active.base_model, zeroed))
        batch = compute_wrench(active, outputs, zero_mv=tare.zero_mv, tare_load=tare.tare_load,
                               temperature_c=temperature_c, load_direction=direction,
                               zero_temperature_c=tare.zero_temperature_c, zero_direction=tare.zero_direction)
        self.counters.count(batch)
        self.fallback_reason = batch.fallback_reason
        accepted = batch.accepted
        all_accepted = bool(accepted.all())
        indices = np.arange(len(outputs)) if all_accepted else np.flatnonzero(accepted)
        loads_total = batch.loads_total if all_accepted else batch.loads_total[indices]
        self.overload_changed = self.overload.update(loads_total, batch.saturated, now_s)
        if self.window is not None and len(indices):
            self.window.add(outputs[indices], temperature_c)
        wrench = batch.wrench_tunnel if all_accepted else batch.wrench_tunnel[indices]
        if self.lowpass.cutoff_hz > 0:
            interval = None if self.inputs.interval_ns is None else self.inputs.interval_ns * 1e-9
            wrench = self.lowpass.apply(wrench, interval)
        if not (self.settings.publish_uncertainty and uncertainty_wanted and len(indices)):
            return Published(indices, wrench, batch)

        def uncertainty():      # of this batch, with this calibration and tare (immutable: safe to run later)
            accepted_outputs = outputs if all_accepted else outputs[indices]
            zeroed = accepted_outputs if tare.zero_mv is None else accepted_outputs - tare.zero_mv
            model = active.model if batch.model_used == active.model_name else active.base_model
            extra = None
            if model.extra_variables:       # the same variables the loads were computed with
                extra = _extra_variables(
                    model, len(indices),
                    None if temperature_c is None or batch.fallback_reason else np.asarray(temperature_c, float),
                    active.calibration.reference_temperature_c, None if direction is None else direction[indices])
                extra = None if isinstance(extra, str) else extra
            return wrench_uncertainty(active, zeroed, tare.tare_sigma, model=model, extra=extra,
                                      loads_balance=loads_total, design=batch.design_row)
        if defer_uncertainty:
            return Published(indices, wrench, batch, uncertainty_later=uncertainty)
        return Published(indices, wrench, batch, uncertainty())

    def process_lone(self, data: bytes, *, now_s: float, input_scale: float, middle: bytes,
                     uncertainty_wanted: bool) -> tuple[bytes, bytes | None] | None:
        """One serialized sample by the C kernel (lone_sample.py) -> (wrench bytes, uncertainty bytes or
        None), with the same bookkeeping as process(); None: process() must take it (the kernel does not
        apply here, or declined this sample)."""
        if self.window is not None or self.lowpass.cutoff_hz > 0 or self.overload.active:
            return None
        made_for = self._lone_plan_for     # (calibration, zero and tare, input scale, frame): made again on a change
        if made_for is None or made_for[0] is not self.active or made_for[1] is not self.tare \
                or made_for[2] != input_scale or made_for[3] is not middle:
            self._lone_plan = lone_sample.make_plan(self.active, self.tare, input_scale, middle)
            self._lone_plan_for = (self.active, self.tare, input_scale, middle)
        if self._lone_plan is None:
            return None
        overload = self.overload
        result = lone_sample.run(self._lone_plan, data, uncertainty_wanted and self.settings.publish_uncertainty,
                                 overload.fraction, overload.peak_fraction)
        if result is None:
            return None
        stamp_ns, frame_id, loads_total, outside, exceeds, wrench, uncertainty = result
        self.uncertainty_wanted = uncertainty_wanted
        self.inputs.update_one(stamp_ns, frame_id.decode('utf-8', 'replace'))
        self.counters.count_one(outside)
        self.fallback_reason = ''
        self.overload_changed = exceeds and overload.update(np.array([loads_total]), np.zeros(1, bool), now_s)
        return wrench, uncertainty

    # --- ~/tare, ~/zero, ~/clear_tare ------------------------------------------------------------
    def start_window(self, kind: str, samples: int) -> TareWindow:
        self.window = TareWindow(samples, kind)
        return self.window

    def finish_window(self) -> TareResult:
        """Evaluate the full window: adopt the zero or tare load if steady, else keep the old one."""
        window, self.window = self.window, None
        tare = self.tare
        result = evaluate_window(window, self.active, max_ratio=self.settings.tare_max_ratio, zero_mv=tare.zero_mv,
                                 zero_temperature_c=tare.zero_temperature_c, zero_direction=tare.zero_direction,
                                 load_direction=self.history.direction)
        if not result.ok:
            return replace(result, message=result.message + f'; the previous {window.kind} stays')
        if window.kind == 'zero':
            # a tare load was taken above the old zero: it no longer holds once the zero moves
            cleared = '; the tare load was cleared (take ~/tare again with the model on)' \
                if tare.tare_load is not None else ''
            self.tare = TareState(tare.balance, result.zero_mv, window.temperature_c, self.history.direction.copy(),
                                  now_iso())
            result = replace(result, message=result.message + cleared)
        else:
            self.tare = replace(tare, tare_load=result.tare_load, tare_taken_at=now_iso(),
                                tare_sigma=result.tare_sigma)
        self.lowpass.reset()
        return result

    def cancel_window(self) -> TareWindow | None:
        window, self.window = self.window, None
        return window

    def clear_tare(self) -> str:
        had = self.tare.tare_load
        self.tare = replace(self.tare, tare_load=None, tare_taken_at='', tare_sigma=None)
        self.lowpass.reset()
        if had is None:
            return 'clear_tare: there was no tare load; the electrical zero stays'
        return 'clear_tare: tare load removed (it was ' + \
            ', '.join(f'{c}={v:+.3f}' for c, v in zip(COMPONENTS, self.active.installation.to_tunnel(had))) + \
            ' in tunnel axes); the electrical zero stays'

    # --- /diagnostics ---------------------------------------------------------------------------
    def _uncertainty_state(self) -> str:
        from ..model.uncertainty import has_uncertainty
        if not self.settings.publish_uncertainty:
            return 'off (publish_uncertainty false)'
        if not has_uncertainty(self.active.model):
            return 'not available: the calibration carries no coefficient covariance (e.g. the memo matrices)'
        return 'published' if self.uncertainty_wanted else 'no subscriber: not computed until one subscribes'

    def report(self, *, period_s: float, last_sample_age_s: float | None, temperature_age_s: float | None,
               refit_running: bool, tare_source: str, node_name: str,
               tare_refused: str = '') -> list[StatusReport]:
        interval = self.inputs.interval_ns
        state = LiveState(
            period_s=period_s, counters=self.counters, last_sample_age_s=last_sample_age_s,
            stale_after_s=self.settings.stale_after_s, temperature_age_s=temperature_age_s,
            fallback_reason=self.fallback_reason, tare_zero_mv=self.tare.zero_mv, refit_running=refit_running,
            tare_load=self.tare.tare_load, tare_source=tare_source, tare_refused=tare_refused,
            input_problems=self.inputs.problems(),
            input_values=(('nominal_interval_ms', 'unknown' if interval is None else f'{interval * 1e-6:.4g}'),
                          ('wrench_uncertainty', self._uncertainty_state()),
                          ('frame_ids_seen_from_other_balances', ', '.join(sorted(self.inputs.foreign_frames))
                           or 'none')),
            overload=self.overload.components if self.overload.active else None,
            overload_values=self.overload.values(), lowpass_hz=self.settings.lowpass_hz)
        reports = diagnostics(self.active, state, node_name)
        self.counters.start_period()
        self.inputs.start_period()
        return reports
