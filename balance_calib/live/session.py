"""Everything balance_calibrator does between its topics, services and parameters, without rclpy.

The node hands this class serialized samples, temperatures, service calls and parameter changes,
and publishes what comes back; the math is calibrator_core, the state between samples stream.

Threads: samples arrive in the node's reader thread (nodes/_raw_input.py), services, parameters and
diagnostics in the executor's. One lock guards the LiveCalibrator, so a new calibration, zero or
tare is swapped in between two batches of samples.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
import threading
import time
from typing import Any, Callable, TYPE_CHECKING

import numpy as np

from ..calibration_file import ConfigError
from ..config import resolve_config_path
from ..model.active_calibration import activate, ActiveCalibration
from . import sample_kernel
from .calibrator_core import parse_reliability
from .parameters import (
    check_input_units,
    check_parameter,
    input_scale_mv,
    load_calibration_checked,
)
from .raw_codec import decode_wrenches, WrenchEncoder
from .refit_process import (
    is_balance_config,
    make_refit_job,
    RefitJob,
    RefitSettings,
    run_refit_job,
)
from .stream import LiveCalibrator, LiveSettings, Output
from .tare_store import (
    calibration_sha256,
    load_tare,
    restore_refusal,
    save_tare,
    tare_file_for,
    TareOwner,
)

if TYPE_CHECKING:  # the type of LiveCalibrator.report's reports
    from .stream import StatusReport

CALIBRATION_PARAMETERS = {
    'calibration_file',
    'model',
    'installation',
    'envelope_margin',
    'output_range_factor',
}

# (level 'info' | 'warning' | 'error' | 'repeated_error' (throttled), line)
Log = Callable[[str, str], None]


def default_calibration_file() -> Path:
    return resolve_config_path('lmc6522')


def live_settings(value: Callable[[str], object]) -> LiveSettings:
    return LiveSettings(
        float(value('stale_after_s')),
        float(value('overload_fraction')),
        float(value('overload_clear_s')),
        float(value('lowpass_hz')),
        float(value('tare_max_scatter')),
        bool(value('publish_uncertainty')),
    )


def activate_file(path: str, value: Callable[[str], object]) -> ActiveCalibration:
    """The calibration `path` with the parameters `value(name)`; ConfigError/ValueError with a
    reason.
    """
    calibration = load_calibration_checked(path, 10.0)
    check_input_units(calibration, value('input_units'), str(path))
    try:
        return activate(
            calibration,
            value('model'),
            value('installation'),
            float(value('envelope_margin')),
            source=str(path),
            output_range_factor=float(value('output_range_factor')),
        )
    except ConfigError as err:  # named by the file once (activate names it when told)
        message = str(err)
        named = message if message.startswith(f'{path}: ') else f'{path}: {message}'
        raise ConfigError(named) from None


class CalibratorSession:
    """value(name) -> current parameter value; log(level, line); fallback_decode(list[bytes]) ->
    the same as decode_wrenches, for bytes the fast decoder does not know (rclpy's deserializer).
    """

    def __init__(
        self,
        value: Callable[[str], object],
        node_name: str,
        log: Log,
        fallback_decode: Callable[[list[bytes]], tuple[np.ndarray, np.ndarray, list[str]]]
        | None = None,
    ) -> None:
        self.value, self.node_name, self.log, self.fallback_decode = (
            value,
            node_name,
            log,
            fallback_decode,
        )
        path = value('calibration_file') or str(default_calibration_file())
        try:
            self.input_scale = input_scale_mv(value('input_units'), value('excitation_v'))
            active = activate_file(path, value)
            self.reliability = parse_reliability(value('input_reliability'))
        except ConfigError:  # the calibration file: its message names it
            raise
        except ValueError as err:
            raise ConfigError(f'invalid parameter: {err}') from None
        self.lock = threading.Lock()
        self.live = LiveCalibrator(active, live_settings(value))
        self.tare_file = self._tare_path(active)
        self.encoder = WrenchEncoder(value('frame_id'))
        self.stale_after_s = float(value('stale_after_s'))
        self.last_sample_s: float | None = None  # time.monotonic() of the last raw sample
        self.temperature_c: float | None = None
        self.temperature_s: float | None = None
        self.fallback_reason = ''
        # called once the tare window is full
        self.window_complete: Callable[[], None] | None = None
        self.refit_running = False
        self.period_start_s = time.monotonic()
        self.pending: ActiveCalibration | None = None  # checked by validate(), applied by apply()
        self.owner = self._owner(active)
        # why the persisted zero and tare were not restored ('' = nothing refused): a WARN in
        # /diagnostics until a new ~/zero or ~/tare
        self.tare_refused = ''
        self._restore_tare()
        if not sample_kernel.available:
            self.log(
                'warning',
                'the C kernel for lone samples is not built '
                f'({sample_kernel.unavailable_reason}): '
                "every sample takes the pure core's path (slower at low rates; reinstall with a C "
                'compiler)',
            )
        absent = active.absent_components
        unit = active.calibration.output_unit
        self.log(
            'info',
            f'{active.model_name} model of {active.calibration.balance} from {path}, '
            f'{active.installation.name} installation; requires '
            f'{", ".join(active.requires) or "bridge outputs only"}'
            + (
                f'; {", ".join(absent)} absent from the calibration: published as 0, '
                f'uncertainty NaN'
                if absent
                else ''
            )
            + (f'; balance/raw carries bridge outputs in {unit}' if unit != 'mV' else ''),
        )

    @property
    def active(self) -> ActiveCalibration:
        return self.live.active

    # --- the stream -----------------------------------------------------------------------------
    def on_temperature(self, temperature_c: float) -> None:
        if np.isfinite(temperature_c):
            self.temperature_c, self.temperature_s = float(temperature_c), time.monotonic()

    def on_samples(self, messages: list[bytes], uncertainty_wanted: bool = True) -> Output | None:
        """One batch of serialized balance/raw samples -> serialized wrenches (None: nothing can
        run); the uncertainty only when wanted (someone subscribes to it), computed by
        Output.uncertainty(). One call of the live path (LiveCalibrator.process_messages: the C
        kernel where it applies, the pure core for the rest).
        """
        now_s = time.monotonic()
        self.last_sample_s = now_s
        fresh = self.temperature_s is not None and now_s - self.temperature_s <= self.stale_after_s
        with self.lock:
            live = self.live
            try:
                out = live.process_messages(
                    messages,
                    now_s=now_s,
                    decode=self._decode,
                    input_scale=self.input_scale,
                    encoder=self.encoder,
                    temperature_c=self.temperature_c if fresh else None,
                    uncertainty_wanted=uncertainty_wanted,
                )
            except ConfigError as err:  # neither the model nor its base can run: publish nothing
                self.log('repeated_error', str(err))
                return None
            reason = '' if out.batch is None else out.batch.fallback_reason
            out.overload = self._say_changes(reason)
            if (
                self.window_complete is not None
                and live.window is not None
                and live.window.complete
            ):
                done, self.window_complete = self.window_complete, None
                done()
        return out

    def _decode(self, messages: list[bytes]) -> tuple[np.ndarray, np.ndarray, list[str]]:
        """(stamps_ns, outputs, frame ids) of serialized samples; rclpy's deserializer for bytes
        the fast decoder does not know.
        """
        try:
            return decode_wrenches(messages)
        except ValueError:
            if self.fallback_decode is None:
                raise
            return self.fallback_decode(messages)

    def _say_changes(self, fallback_reason: str) -> bool | None:
        """Log overload and model fallback changes; the new overload state if it changed."""
        live = self.live
        if fallback_reason != self.fallback_reason:
            if fallback_reason:
                self.log(
                    'warning',
                    f'{live.active.model_name} model cannot run ({fallback_reason}); '
                    f'using {live.active.base_name}',
                )
            else:
                self.log('info', f'{live.active.model_name} model back in use')
            self.fallback_reason = fallback_reason
        if not live.overload_changed:
            return None
        if live.overload.active:
            self.log(
                'error',
                f'OVERLOAD: {", ".join(live.overload.components)} beyond '
                f'{live.overload.fraction:g} x rated load',
            )
        else:
            self.log(
                'info', f'overload cleared: loads inside the limit for {live.overload.clear_s:g} s'
            )
        return live.overload.active

    # --- ~/tare, ~/zero, ~/clear_tare -----------------------------------------------------------
    def start_window(self, kind: str, on_complete: Callable[[], None]) -> str | None:
        """Collect tare_samples samples for `kind`; None when started, else why not."""
        with self.lock:
            if self.live.window is not None:
                return f'{kind} failed: a {self.live.window.kind} is already collecting samples'
            self.live.start_window(kind, int(self.value('tare_samples')))
            self.window_complete = on_complete
        return None

    def finish_window(self, kind: str, arrived: bool, timeout_s: float) -> tuple[bool, str]:
        """(success, reply) once the window is full (arrived) or the time is up."""
        with self.lock:
            self.window_complete = None
            if not arrived:
                window = self.live.cancel_window()
                got = 0 if window is None else len(window.outputs_mv)
                samples = int(self.value('tare_samples'))
                return False, (
                    f'{kind} failed: only {got} of {samples} valid samples arrived on balance/raw '
                    f'within {timeout_s:g} s; the previous {kind} stays'
                )
            result = self.live.finish_window()
        if not result.ok:
            self.log('warning', result.message)
            return False, result.message
        self.tare_refused = ''
        message = result.message + '; ' + self._persist_tare()
        self.log('info', message)
        return True, message

    def clear_tare(self) -> str:
        with self.lock:
            message = self.live.clear_tare()
        message += '; ' + self._persist_tare()
        self.log('info', message)
        return message

    def _tare_path(self, active: ActiveCalibration) -> Path | None:
        if self.value('tare_file'):
            return Path(self.value('tare_file')).expanduser()
        return tare_file_for(active.source, self.node_name, is_balance_config(active.source))

    def _owner(self, active: ActiveCalibration) -> TareOwner:
        """What a zero or tare taken now belongs to: calibration content, installation, node."""
        return TareOwner.of_node(
            calibration_sha256(active.source), active.installation, self.node_name
        )

    def _restore_tare(self) -> None:
        if self.tare_file is None:
            return
        try:
            state = load_tare(self.tare_file, self.live.active.calibration.balance)
        except ValueError as err:
            self.tare_refused = str(err)
            self.log('warning', f'not restoring zero and tare: {err}')
            return
        if state is None:
            return
        refusal = restore_refusal(state.owner, self.owner)
        if refusal:
            self.tare_refused = f'{self.tare_file}: {refusal}'
            self.log(
                'warning',
                f'not restoring zero and tare from {self.tare_file}: {refusal}; '
                'take ~/zero and ~/tare again',
            )
            return
        self.live.tare = state
        to_tunnel = self.live.active.installation.to_tunnel
        self.log(
            'info',
            f'restored from {self.tare_file}: zero '
            + (
                'none'
                if state.zero_mv is None
                else f'taken {state.zero_taken_at or "at an unknown time"}'
            )
            + '; tare load '
            + (
                'none'
                if state.tare_load is None
                else f'{to_tunnel(state.tare_load).round(3).tolist()} '
                f'N, N·m (tunnel axes) taken {state.tare_taken_at or "at an unknown time"}'
            ),
        )

    def _switch(self, active: ActiveCalibration) -> str:
        """Make `active` the calibration between two samples; the tare load re-read or cleared
        (LiveCalibrator.set_active) and then persisted for its new owner. '' or what happened to
        the tare load.
        """
        owner = self._owner(active)
        loads_changed = (
            not owner.calibration_sha256
            or owner.calibration_sha256 != self.owner.calibration_sha256
            or active.model_name != self.live.active.model_name
        )
        with self.lock:
            said = self.live.set_active(active, loads_changed)
        self.owner = owner
        return f'{said}; {self._persist_tare()}' if said else ''

    def _persist_tare(self) -> str:
        if self.tare_file is None:
            return (
                'not persisted: the calibration is a shipped balance config (set parameter '
                'tare_file to keep zero and tare across restarts)'
            )
        try:
            save_tare(self.tare_file, replace(self.live.tare, owner=self.owner))
            return f'saved to {self.tare_file}'
        except OSError as err:
            self.log('error', f'cannot save zero and tare to {self.tare_file}: {err}')
            return (
                f'NOT saved ({self.tare_file}: {err.strerror or err}): it will not survive a '
                'restart'
            )

    # --- ~/refit --------------------------------------------------------------------------------
    def keep_message(self) -> str:
        active = self.live.active
        return f'the calibration from {active.source} ({active.model_name}) stays in force'

    def refit_job(self) -> RefitJob:
        """The job ~/refit runs; ValueError/OSError naming the parameter that stops it."""
        value, active = self.value, self.live.active
        settings = RefitSettings(
            str(value('balance')),
            str(value('model')),
            active.installation,
            float(value('envelope_margin')),
            float(value('output_range_factor')),
            float(value('refit_timeout_s')),
        )
        return make_refit_job(
            value('calibration_bags') or [], value('report_dir'), active.source, settings
        )

    def start_refit(
        self, refit_function: Callable[..., Any] | None, on_done: Callable[[object], None]
    ) -> str | None:
        """Start ~/refit in a worker thread (the pipeline in its own process unless refit_function,
        run_refit's signature, is given); on_done(outcome) from that thread. None when started,
        else the refusal.
        """
        keep = self.keep_message()
        if self.refit_running:
            return f'refit failed: a refit is already running; {keep}'
        try:
            job = self.refit_job()
        except (OSError, ValueError) as err:
            return f'refit failed: {err}; {keep}'
        self.refit_running = True

        def work() -> None:
            try:
                outcome = run_refit_job(
                    job, refit_function, lambda line: self.log('info', f'refit: {line}')
                )
            # any failure leaves the node and its calibration as they were
            except Exception as err:
                outcome = f'{type(err).__name__}: {err}'
            on_done((job, outcome))

        threading.Thread(target=work, name='refit', daemon=True).start()
        return None

    def finish_refit(
        self, done: tuple[RefitJob, tuple[ActiveCalibration, Path, str] | str]
    ) -> tuple[bool, str, str | None]:
        """start_refit's outcome -> (success, reply, the calibration file to switch to or None). A
        new calibration is swapped in between two batches of samples; zero and tare stay.
        """
        job, outcome = done
        self.refit_running = False
        if isinstance(outcome, str):
            message = f'refit failed: {outcome}; {self.keep_message()}'
            self.log('error', message)
            return False, message, None
        new_active, target, message = outcome
        tare_said = self._switch(new_active)
        if tare_said:
            message = f'{message}; {tare_said}'
        self.log('info', message)
        if str(target) == str(job.calibration_file):
            return True, message, None
        self.pending = None
        return True, message, str(target)

    # --- parameters -----------------------------------------------------------------------------
    def validate(self, changes: dict) -> None:
        """Check a parameter change before rclpy applies it; ConfigError/ValueError/TypeError
        says why.
        """
        for name, item in changes.items():
            check_parameter(name, item)
        if 'balance' in changes:
            resolve_config_path(changes['balance'])

        def value(name: str) -> object:
            return changes.get(name, self.value(name))

        if {'input_units', 'excitation_v'} & set(changes):
            input_scale_mv(value('input_units'), value('excitation_v'))
            if not CALIBRATION_PARAMETERS & set(changes):  # else activate_file checks the new
                active = self.live.active
                check_input_units(active.calibration, value('input_units'), active.source)
        if CALIBRATION_PARAMETERS & set(changes):
            path = changes.get('calibration_file', None)
            path = (
                self.live.active.source
                if path is None
                else (path or str(default_calibration_file()))
            )
            self.pending = activate_file(path, value)

    def apply(self, names: set) -> bool:
        """The parameters after a change; True if diagnostics_period_s changed (the node's
        timer).
        """
        value = self.value
        self.stale_after_s = float(value('stale_after_s'))
        self.input_scale = input_scale_mv(value('input_units'), value('excitation_v'))
        pending, self.pending = self.pending, None
        with self.lock:
            self.live.set_settings(live_settings(value))
            if 'frame_id' in names:
                self.encoder = WrenchEncoder(value('frame_id'))
            before = self.live.active
        # rclpy applies a request of several parameters one by one: say it once, when it changed
        if pending is not None and (
            before.model_name,
            before.source,
            before.installation.name,
        ) != (pending.model_name, pending.source, pending.installation.name):
            self.log(
                'info',
                f'now {pending.model_name} model from {pending.source}, '
                f'{pending.installation.name} installation',
            )
        if 'tare_file' in names or 'calibration_file' in names:
            self.tare_file = self._tare_path(pending or self.live.active)
        if pending is not None:  # a zero or tare taken from now on belongs to this one
            tare_said = self._switch(pending)
            if tare_said:
                self.log('warning' if 'cleared' in tare_said else 'info', tare_said)
        return 'diagnostics_period_s' in names

    # --- /diagnostics ---------------------------------------------------------------------------
    def report(self) -> list[StatusReport]:
        with self.lock:  # the share outside the support is judged out of the samples' way
            live = self.live
            judge = live.support.take(
                live.active, live.tare.zero_mv, live.counters.period_received
            )
        support = judge()
        now_s = time.monotonic()
        with self.lock:
            reports = self.live.report(
                period_s=now_s - self.period_start_s,
                last_sample_age_s=None
                if self.last_sample_s is None
                else now_s - self.last_sample_s,
                temperature_age_s=None
                if self.temperature_s is None
                else now_s - self.temperature_s,
                refit_running=self.refit_running,
                tare_source='not persisted' if self.tare_file is None else str(self.tare_file),
                tare_refused=self.tare_refused,
                node_name=self.node_name.lstrip('/'),
                support=support,
            )
        self.period_start_s = now_s
        return reports
