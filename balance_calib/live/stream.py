"""The live calibrator's state between samples, without rclpy: what balance_calibrator
orchestrates.

`LiveCalibrator.process()` takes a batch of raw samples (outputs, stamps, frame ids) and returns
the wrenches to publish; around the math of calibrator_core it keeps the electrical zero and the
tare load (with their ~/zero and ~/tare windows), the overload state, the optional low-pass filter,
the load history of hysteresis models and the input's health (stamps, frame ids, gaps). The node
only turns messages into arrays and back.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable, Mapping, Sequence

import numpy as np

from ..model.active_calibration import ActiveCalibration, six_axis_loads
from ..model.balance_model import BalanceModel
from ..model.r091 import IterativeModel
from ..model.uncertainty import covariance_and_sigma, has_uncertainty, load_standard_uncertainty
from ..units import COMPONENTS
from . import sample_kernel
from .calibrator_core import _extra_variables, _rows, compute_wrench, LoadHistory, WrenchBatch
from .diagnostics_status import diagnostics, InputCounters, LiveState, StatusReport
from .load_text import describe_loads, describe_tare
from .raw_codec import WrenchEncoder
from .support_share import SupportSampler, SupportShare
from .tare_store import now_iso, TareState
from .tare_window import evaluate_window, TareResult, TareWindow


@dataclass(frozen=True)
class LiveSettings:
    stale_after_s: float = 1.0
    overload_fraction: float = 1.0  # x rated load
    overload_clear_s: float = 1.0
    lowpass_hz: float = 0.0  # 0 = off
    tare_max_ratio: float = 4.0  # steadiness: scatter and step limit, x the window's own noise
    publish_uncertainty: bool = True


class InputMonitor:
    """Stamps out of order, duplicated or zero, frame ids naming another balance, and gaps (lost
    samples).

    The nominal sample interval is the median of the last 256 positive stamp differences (re-taken
    every 64 samples); a gap of d > 1.5 intervals counts round(d / interval) - 1 samples lost.
    """

    KINDS = (
        'stamps out of order',
        'duplicate stamps',
        'zero stamps',
        'samples from another balance',
        'samples lost (gaps in the stamps)',
    )

    def __init__(self, balance: str) -> None:
        self.balance = balance.lower()
        self.total = dict.fromkeys(self.KINDS, 0)
        self.period = dict.fromkeys(self.KINDS, 0)
        self.foreign_frames: set[str] = set()
        self.last_stamp_ns: int | None = None
        self.interval_ns: float | None = None
        self._differences = [0] * 256  # the last 256 positive differences, a ring
        self._filled = 0
        self._since_estimate = 0

    def _add(self, kind: str, count: int) -> None:
        if count:
            self.total[kind] += count
            self.period[kind] += count

    def update(
        self, stamps_ns: np.ndarray | Sequence[int], frame_ids: Sequence[str] | None = None
    ) -> None:
        """A batch of stamps (N,) ns in arrival order (array or list) and their frame ids.

        One pass in plain Python: a sequential state machine (the latest stamp so far), and at
        1 kHz every batch is one sample, where numpy's per-call cost would be most of the work. The
        interval is estimated before the batch's gaps are counted (from the batch's own differences
        when there is none yet) and re-taken after it.
        """
        if frame_ids is not None:
            foreign = [f for f in frame_ids if f and f.lower() != self.balance]
            if foreign:
                self._add('samples from another balance', len(foreign))
                if len(self.foreign_frames) < 8:
                    self.foreign_frames.update(foreign[:8])
        stamps = stamps_ns.tolist() if isinstance(stamps_ns, np.ndarray) else stamps_ns
        if 0 in stamps:
            nonzero = [v for v in stamps if v != 0]
            self._add('zero stamps', len(stamps) - len(nonzero))
            stamps = nonzero
        if not len(stamps):
            return
        first = self.last_stamp_ns is None
        latest = stamps[0] if first else self.last_stamp_ns
        positive, out_of_order, duplicates = [], 0, 0
        for stamp in stamps[1:] if first else stamps:  # each against the latest stamp before it
            difference = stamp - latest
            if difference > 0:
                positive.append(difference)
                latest = stamp
            elif difference < 0:
                out_of_order += 1
            else:
                duplicates += 1
        if out_of_order or duplicates:
            self._add('stamps out of order', out_of_order)
            self._add('duplicate stamps', duplicates)
        self.last_stamp_ns = latest
        if self.interval_ns is None and len(positive) >= 3:  # a first batch: its own median
            self.interval_ns = float(np.median(positive))
        if self.interval_ns is not None and positive:
            interval = self.interval_ns
            gaps = [d for d in positive if d > 1.5 * interval]
            if gaps:
                self._add(
                    'samples lost (gaps in the stamps)', sum(round(d / interval) - 1 for d in gaps)
                )
        ring, filled = self._differences, self._filled
        for difference in positive[-256:]:
            ring[filled % 256] = difference
            filled += 1
        self._since_estimate += filled - self._filled
        self._filled = filled
        if filled and (self.interval_ns is None or self._since_estimate >= 64):
            self.interval_ns = float(np.median(ring[: min(filled, 256)]))
            self._since_estimate = 0

    def problems(self) -> tuple[tuple[str, int, int], ...]:
        return tuple((kind, self.total[kind], self.period[kind]) for kind in self.KINDS)

    def start_period(self) -> None:
        self.period = dict.fromkeys(self.KINDS, 0)


class OverloadMonitor:
    """True as soon as any component's load exceeds capacity x fraction (or a bridge saturates);
    false again once the samples have stayed inside for clear_s.
    """

    def __init__(self, capacity: np.ndarray, fraction: float, clear_s: float) -> None:
        self.capacity = np.asarray(capacity, dtype=float)
        self.fraction = fraction
        self.clear_s = clear_s
        self.active = False
        self.components: tuple[str, ...] = ()
        self.inside_since_s: float | None = None
        self.peak_fraction = np.zeros(6)
        self.events = 0

    def update(self, loads_total: np.ndarray, saturated: np.ndarray, now_s: float) -> bool:
        """Feed a batch (loads of the accepted samples (N, 6), saturated flags); True if the
        state changed.
        """
        # ufunc reductions: what .max() and .any() run, without their Python wrappers
        if len(loads_total):
            ratio = np.maximum.reduce(np.abs(loads_total), axis=0) / self.capacity
            np.maximum(self.peak_fraction, ratio, out=self.peak_fraction)
            exceeded = ratio > self.fraction
        else:
            exceeded = np.zeros(6, bool)
        if np.logical_or.reduce(exceeded) or np.logical_or.reduce(saturated):
            names = tuple(COMPONENTS[k] for k in np.flatnonzero(exceeded)) + (
                ('saturated bridge',) if np.any(saturated) else ()
            )
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
        return (
            ('overload', str(self.active)),
            ('overload_fraction', f'{self.fraction:g}'),
            ('overload_events', str(self.events)),
            (
                'peak_load_fraction_of_rated',
                ', '.join(f'{c}={v:.3f}' for c, v in zip(COMPONENTS, self.peak_fraction)),
            ),
        )


class LowPass:
    """First-order low-pass on each component, y += a (x - y) with a = 1 - exp(-2π f_c Δt), state
    carried across batches (scipy.signal.lfilter).
    """

    def __init__(self, cutoff_hz: float) -> None:
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
        from scipy.signal import lfilter

        out, _ = lfilter([a], [1.0, a - 1.0], values, axis=0, zi=((1.0 - a) * self.state)[None, :])
        self.state = out[-1].copy()
        return out


class Output:
    """What one batch of samples gives the node to publish (serialized): the wrenches in arrival
    order; overload: the new overload state if it changed (None: unchanged; the session sets it,
    see LiveCalibrator.overload_changed); uncertainty() -> the uncertainties, computed when asked
    (after the wrenches went out). accelerated: how many of the leading samples the C kernel took;
    batch: the pure core's WrenchBatch of the rest (None if the kernel took all).
    """

    __slots__ = (
        'wrench',
        'overload',
        'accelerated',
        'batch',
        '_ready',
        '_later',
        '_stamps',
        '_encoder',
    )

    def __init__(
        self,
        wrench: list[bytes],
        ready: list[bytes],
        later: Callable[[], np.ndarray | None] | None = None,
        stamps: np.ndarray | None = None,
        encoder: WrenchEncoder | None = None,
        *,
        accelerated: int = 0,
        batch: WrenchBatch | None = None,
    ) -> None:
        self.wrench, self.accelerated, self.batch, self.overload = wrench, accelerated, batch, None
        self._ready, self._later, self._stamps, self._encoder = ready, later, stamps, encoder

    def uncertainty(self) -> list[bytes]:
        values = None if self._later is None else self._later()
        if values is None:
            return self._ready
        return self._ready + self._encoder.encode(self._stamps, values)


@dataclass
class Published:
    """The samples of a batch to publish: their indices in the batch and their wrenches (M, 6)."""

    indices: np.ndarray
    wrench: np.ndarray
    batch: WrenchBatch
    # (M, 6) standard uncertainty, tunnel axes; None = not available
    uncertainty: np.ndarray | None = None
    # with defer_uncertainty: computes it
    uncertainty_later: Callable[[], np.ndarray | None] | None = None


def wrench_uncertainty(
    active: ActiveCalibration,
    zeroed_outputs: np.ndarray,
    tare_sigma: np.ndarray | None,
    *,
    model: BalanceModel | IterativeModel | None = None,
    extra: Mapping[str, np.ndarray] | None = None,
    loads_balance: np.ndarray | None = None,
    design: np.ndarray | None = None,
) -> np.ndarray | None:
    """Standard uncertainty (k = 1) of each published load (M, 6), N / N·m, tunnel axes: the
    calibration's coefficient covariance and residual σ (model/uncertainty.py) at these outputs,
    and the tare's own scatter. `model`: the one that gave the loads (default the active model; the
    base model after a fallback); `extra`: its variables besides the outputs (dT, dir_*) for these
    samples, as for its loads(); `loads_balance` (M, 6): the loads it gave, balance axes, so that
    an iterative model is not solved twice; `design` (M, n_terms): its design rows, if computed
    already. None when the model has no covariance (the memo's matrices) or needs an input it was
    not given. A component the calibration lacks (a 1-, 3- or 5-component balance) is NaN: its 0 is
    not a measurement.
    """
    model = active.model if model is None else model
    if (model.extra_variables and extra is None) or covariance_and_sigma(model) is None:
        return None
    columns, positions = active.layout(model)  # positions None: all six components, in order
    tare = None if tare_sigma is None else np.asarray(tare_sigma)
    tare = tare if tare is None or positions is None else tare[positions]
    loads = None
    if loads_balance is not None and getattr(model, 'form', 'direct') == 'iterative':
        loads = np.asarray(loads_balance)
        loads = loads if positions is None else loads[:, positions]
    per_component = load_standard_uncertainty(
        model,
        zeroed_outputs.take(columns, axis=1),
        extra,
        tare_sigma=tare,
        loads=loads,
        design=design,
    )
    if positions is None:
        six = per_component
    else:
        six = np.full((len(zeroed_outputs), 6), np.nan)  # NaN: a component the calibration lacks
        six[:, positions] = per_component
    # a signed permutation: magnitudes carry over
    return np.abs(active.installation.to_tunnel(six))


@dataclass
class LiveCalibrator:
    active: ActiveCalibration
    settings: LiveSettings = field(default_factory=LiveSettings)
    tare: TareState | None = None

    def __post_init__(self) -> None:
        self.tare = self.tare or TareState(self.active.calibration.balance)
        self.counters = InputCounters()
        self.inputs = InputMonitor(self.active.calibration.balance)
        self.overload = OverloadMonitor(
            self.active.capacity, self.settings.overload_fraction, self.settings.overload_clear_s
        )
        self.lowpass = LowPass(self.settings.lowpass_hz)
        self.history = LoadHistory(self.active.capacity)
        self.window: TareWindow | None = None
        self.fallback_reason = ''
        self.overload_changed = False
        self.uncertainty_wanted = True
        self._single_plan, self._single_plan_for = None, None
        self.support = SupportSampler()  # the share outside the calibration's support

    # --- configuration --------------------------------------------------------------------------
    def set_active(self, active: ActiveCalibration, loads_changed: bool = True) -> str:
        """A new calibration (refit, parameters), between two samples. The electrical zero stays
        (output space, nothing on the balance). The tare load is the old calibration's reading of
        the model's weight in the old installation's balance axes, so it does not simply stay:
        another installation clears it (the weight loads the balance another way), and another
        calibration or model (`loads_changed`) re-reads it from the wind-off outputs it was
        taken at; else the wind-off reading would be f_new(V) - f_old(V_tare), not zero. Returns
        what happened to the tare load ('' when nothing did).
        """
        before, self.active = self.active, active
        self.history = LoadHistory(active.capacity)
        self.overload.capacity = np.asarray(active.capacity, dtype=float)
        self.inputs.balance = active.calibration.balance.lower()
        tare = self.tare
        if tare.tare_load is None:
            return ''
        if active.installation.spec != before.installation.spec:
            self.tare = _without_tare_load(tare)
            self.lowpass.reset()
            return (
                f'tare load cleared: taken in the {before.installation.name} installation, now '
                f'{active.installation.name} (take ~/tare again with the model on)'
            )
        if not loads_changed:
            return ''
        reread = self._reread_tare(active)
        self.lowpass.reset()
        if isinstance(reread, str):
            self.tare = _without_tare_load(tare)
            return f'tare load cleared: {reread} (take ~/tare again with the model on)'
        self.tare = replace(tare, tare_load=reread)
        return (
            f'tare load re-read by the new calibration from its wind-off outputs: '
            f'{describe_tare(reread, active)} (was {describe_loads(tare.tare_load, active)})'
        )

    def _reread_tare(self, active: ActiveCalibration) -> np.ndarray | str:
        """The tare load (6,) of `active` at the recorded wind-off outputs, or why there is
        none.
        """
        tare = self.tare
        if tare.tare_outputs_mv is None:
            return 'its wind-off outputs are not recorded (restored from an older tare file)'
        needs = active.requires
        if 'temperature' in needs and tare.tare_temperature_c is None:
            return 'the new model has temperature terms and no temperature was read at the tare'
        batch = compute_wrench(
            active,
            tare.tare_outputs_mv[None],
            zero_mv=tare.zero_mv,
            temperature_c=tare.tare_temperature_c,
            load_direction=(
                None
                if 'load_history' not in needs or tare.tare_direction is None
                else tare.tare_direction[None]
            ),
            zero_temperature_c=tare.zero_temperature_c,
            zero_direction=tare.zero_direction,
        )
        loads = batch.loads_total[0]
        if not np.all(np.isfinite(loads)):
            return f'the new {batch.model_used} model gives no load at its wind-off outputs'
        return loads

    def set_settings(self, settings: LiveSettings) -> None:
        if settings.lowpass_hz != self.settings.lowpass_hz:
            self.lowpass = LowPass(settings.lowpass_hz)
        self.overload.fraction, self.overload.clear_s = (
            settings.overload_fraction,
            settings.overload_clear_s,
        )
        self.settings = settings

    # --- the stream -----------------------------------------------------------------------------
    def process(
        self,
        outputs_mv: np.ndarray,
        stamps_ns: np.ndarray,
        frame_ids: Sequence[str] | None = None,
        *,
        now_s: float,
        temperature_c: float | None = None,
        uncertainty_wanted: bool = True,
        defer_uncertainty: bool = False,
    ) -> Published:
        """A batch of raw samples (N, 6) mV in arrival order -> what to publish.
        uncertainty_wanted: False when nobody subscribes to it (the node asks its publisher): not
        computed then. defer_uncertainty: leave it to Published.uncertainty_later(), so that the
        wrench goes out first.
        """
        self.uncertainty_wanted = uncertainty_wanted
        outputs = _rows(outputs_mv)
        self.inputs.update(stamps_ns, frame_ids)
        active, tare = self.active, self.tare
        direction = None
        if 'load_history' in active.requires:
            finite = active.inputs_finite(outputs)
            zeroed = outputs[finite] - (0.0 if tare.zero_mv is None else tare.zero_mv)
            direction = np.ones((len(outputs), 6))
            direction[finite] = self.history.update(six_axis_loads(active.base_model, zeroed))
        batch = compute_wrench(
            active,
            outputs,
            zero_mv=tare.zero_mv,
            tare_load=tare.tare_load,
            temperature_c=temperature_c,
            load_direction=direction,
            zero_temperature_c=tare.zero_temperature_c,
            zero_direction=tare.zero_direction,
        )
        self.counters.count(batch)
        self.fallback_reason = batch.fallback_reason
        accepted = batch.accepted
        all_accepted = bool(np.logical_and.reduce(accepted))
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

        # of this batch, with this calibration and tare (immutable: safe to run later)
        def uncertainty() -> np.ndarray | None:
            accepted_outputs = outputs if all_accepted else outputs[indices]
            zeroed = accepted_outputs if tare.zero_mv is None else accepted_outputs - tare.zero_mv
            model = active.model if batch.model_used == active.model_name else active.base_model
            extra = None
            if model.extra_variables:  # the same variables the loads were computed with
                extra = _extra_variables(
                    model,
                    len(indices),
                    None
                    if temperature_c is None or batch.fallback_reason
                    else np.asarray(temperature_c, float),
                    active.calibration.reference_temperature_c,
                    None if direction is None else direction[indices],
                )
                extra = None if isinstance(extra, str) else extra
            return wrench_uncertainty(
                active,
                zeroed,
                tare.tare_sigma,
                model=model,
                extra=extra,
                loads_balance=loads_total,
                design=batch.design_row,
            )

        if defer_uncertainty:
            return Published(indices, wrench, batch, uncertainty_later=uncertainty)
        return Published(indices, wrench, batch, uncertainty())

    def process_messages(
        self,
        messages: list[bytes],
        *,
        now_s: float,
        decode: Callable,
        input_scale: float,
        encoder: WrenchEncoder,
        temperature_c: float | None = None,
        uncertainty_wanted: bool = True,
    ) -> Output:
        """A batch of serialized balance/raw samples -> the serialized wrenches to publish
        (Output), with the same state as process() on the decoded batch: the one call of the live
        path.

        The C kernel (sample_kernel.py), the pure core's only accelerator, takes the samples from
        the first while it applies (no tare window, no low-pass, no overload held; a calibration it
        knows) and accepts them -- 2-3 µs a sample, where the vectorised path costs tens of µs a
        call, which at 1 kHz (one sample a wake-up) is every sample. The rest of the batch, from
        the first sample it declines (or the one that raised an overload), goes through process().
        decode(messages) -> (stamps_ns (N,), outputs (N, 6) in the input's unit, frame ids);
        input_scale: to mV.
        """
        self.support.keep(messages, decode, input_scale)
        wrench, ready = self._through_kernel(
            messages, now_s, input_scale, encoder.middle, uncertainty_wanted
        )
        if len(wrench) == len(messages):
            return Output(wrench, ready, accelerated=len(wrench))
        changed = self.overload_changed
        stamps_ns, outputs, frame_ids = decode(messages[len(wrench) :] if wrench else messages)
        if input_scale != 1.0:  # ratiometric bridge outputs (input_units) to mV
            outputs = outputs * input_scale
        published = self.process(
            outputs,
            stamps_ns,
            frame_ids,
            now_s=now_s,
            temperature_c=temperature_c,
            uncertainty_wanted=uncertainty_wanted,
            defer_uncertainty=True,
        )
        self.overload_changed = changed or self.overload_changed
        stamps = stamps_ns[published.indices]
        return Output(
            wrench + encoder.encode(stamps, published.wrench),
            ready,
            published.uncertainty_later,
            stamps,
            encoder,
            accelerated=len(wrench),
            batch=published.batch,
        )

    def _through_kernel(
        self,
        messages: list[bytes],
        now_s: float,
        input_scale: float,
        middle: bytes,
        uncertainty_wanted: bool,
    ) -> tuple[list, list]:
        """The leading samples the C kernel takes: (wrench bytes, uncertainty bytes), with the
        input monitor, counters and overload fed as process() feeds them.
        """
        self.overload_changed = False
        if (
            not sample_kernel.available
            or self.window is not None
            or self.lowpass.cutoff_hz > 0
            or self.overload.active
        ):
            return [], []
        # the plan, for (calibration, zero and tare, input scale, frame): made again on a change
        made_for = self._single_plan_for
        if (
            made_for is None
            or made_for[0] is not self.active
            or made_for[1] is not self.tare
            or made_for[2] != input_scale
            or made_for[3] is not middle
        ):
            self._single_plan = sample_kernel.make_plan(
                self.active, self.tare, input_scale, middle
            )
            self._single_plan_for = (self.active, self.tare, input_scale, middle)
        plan = self._single_plan
        if plan is None:
            return [], []
        overload, run = self.overload, sample_kernel.run
        want = uncertainty_wanted and self.settings.publish_uncertainty
        wrench, ready, stamps, frames, outside = [], [], [], [], 0
        for data in messages:
            result = run(plan, data, want, overload.fraction, overload.peak_fraction)
            if result is None:
                break
            stamp_ns, frame_id, loads_total, out, exceeds, wrench_bytes, uncertainty_bytes = result
            wrench.append(wrench_bytes)
            if uncertainty_bytes is not None:
                ready.append(uncertainty_bytes)
            stamps.append(stamp_ns)
            frames.append(frame_id.decode('utf-8', 'replace'))
            outside += out
            if exceeds:  # the overload is raised: held from here, the pure core takes the rest
                self.overload_changed = overload.update(
                    np.array([loads_total]), np.zeros(1, bool), now_s
                )
                break
        if wrench:
            self.uncertainty_wanted = uncertainty_wanted
            self.inputs.update(stamps, frames)
            self.counters.add(len(wrench), len(wrench), out=outside)
            self.fallback_reason = ''
        return wrench, ready

    # --- ~/tare, ~/zero, ~/clear_tare ------------------------------------------------------------
    def start_window(self, kind: str, samples: int) -> TareWindow:
        self.window = TareWindow(samples, kind)
        return self.window

    def finish_window(self) -> TareResult:
        """Evaluate the full window: adopt the zero or tare load if steady, else keep the old
        one.
        """
        window, self.window = self.window, None
        tare = self.tare
        result = evaluate_window(
            window,
            self.active,
            max_ratio=self.settings.tare_max_ratio,
            zero_mv=tare.zero_mv,
            zero_temperature_c=tare.zero_temperature_c,
            zero_direction=tare.zero_direction,
            load_direction=self.history.direction,
        )
        if not result.ok:
            return replace(result, message=result.message + f'; the previous {window.kind} stays')
        if window.kind == 'zero':
            # a tare load was taken above the old zero: it no longer holds once the zero moves
            cleared = (
                '; the tare load was cleared (take ~/tare again with the model on)'
                if tare.tare_load is not None
                else ''
            )
            self.tare = TareState(
                tare.balance,
                result.zero_mv,
                window.temperature_c,
                self.history.direction.copy(),
                now_iso(),
            )
            result = replace(result, message=result.message + cleared)
        else:
            self.tare = replace(
                tare,
                tare_load=result.tare_load,
                tare_taken_at=now_iso(),
                tare_sigma=result.tare_sigma,
                tare_outputs_mv=result.tare_outputs_mv,
                tare_temperature_c=window.temperature_c,
                tare_direction=self.history.direction.copy(),
            )
        self.lowpass.reset()
        return result

    def cancel_window(self) -> TareWindow | None:
        window, self.window = self.window, None
        return window

    def clear_tare(self) -> str:
        had = self.tare.tare_load
        self.tare = _without_tare_load(self.tare)
        self.lowpass.reset()
        if had is None:
            return 'clear_tare: there was no tare load; the electrical zero stays'
        return (
            'clear_tare: tare load removed (it was '
            + ', '.join(
                f'{c}={v:+.3f}'
                for c, v in zip(COMPONENTS, self.active.installation.to_tunnel(had))
            )
            + ' in tunnel axes); the electrical zero stays'
        )

    # --- /diagnostics ---------------------------------------------------------------------------
    def _uncertainty_state(self) -> str:
        if not self.settings.publish_uncertainty:
            return 'off (publish_uncertainty false)'
        if not has_uncertainty(self.active.model):
            return (
                'not available: the calibration carries no coefficient covariance (e.g. the '
                'memo matrices)'
            )
        return (
            'published'
            if self.uncertainty_wanted
            else 'no subscriber: not computed until one subscribes'
        )

    def report(
        self,
        *,
        period_s: float,
        last_sample_age_s: float | None,
        temperature_age_s: float | None,
        refit_running: bool,
        tare_source: str,
        node_name: str,
        tare_refused: str = '',
        support: SupportShare | None = None,
    ) -> list[StatusReport]:
        """support: the period's share outside the support, judged by the caller out of its lock
        (SupportSampler.take); None: judged here.
        """
        interval = self.inputs.interval_ns
        state = LiveState(
            period_s=period_s,
            counters=self.counters,
            last_sample_age_s=last_sample_age_s,
            stale_after_s=self.settings.stale_after_s,
            temperature_age_s=temperature_age_s,
            fallback_reason=self.fallback_reason,
            tare_zero_mv=self.tare.zero_mv,
            refit_running=refit_running,
            tare_load=self.tare.tare_load,
            tare_source=tare_source,
            tare_refused=tare_refused,
            input_problems=self.inputs.problems(),
            input_values=(
                (
                    'nominal_interval_ms',
                    'unknown' if interval is None else f'{interval * 1e-6:.4g}',
                ),
                ('wrench_uncertainty', self._uncertainty_state()),
                (
                    'frame_ids_seen_from_other_balances',
                    ', '.join(sorted(self.inputs.foreign_frames)) or 'none',
                ),
            ),
            overload=self.overload.components if self.overload.active else None,
            overload_values=self.overload.values(),
            lowpass_hz=self.settings.lowpass_hz,
            support=support
            or self.support.judge(self.active, self.tare.zero_mv, self.counters.period_received),
        )
        reports = diagnostics(self.active, state, node_name)
        self.counters.start_period()
        self.inputs.start_period()
        return reports


def _without_tare_load(tare: TareState) -> TareState:
    """The state with the electrical zero kept and no tare load."""
    return replace(
        tare,
        tare_load=None,
        tare_taken_at='',
        tare_sigma=None,
        tare_outputs_mv=None,
        tare_temperature_c=None,
        tare_direction=None,
    )
