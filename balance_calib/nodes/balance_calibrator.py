"""balance_calibrator: balance/raw (mV) -> balance/wrench (N, N·m, tunnel axes) with the active calibration.

Topics (relative: `--ros-args -r __ns:=/left` runs a second balance beside the first): in balance/raw,
balance/temperature; out balance/wrench, balance/wrench_uncertainty (when the calibration carries
its covariance), balance/overload (std_msgs/Bool, transient local), /diagnostics. Services
(std_srvs/Trigger): ~/zero (electrical zero, output space: only with nothing on the balance),
~/tare (tare load, e.g. the model's weight wind-off: load space, the calibration on the full outputs),
~/clear_tare, ~/refit. ~/zero and ~/tare refuse a window that is not steady and say why; both are
kept in <calibration>.tare.yaml beside the calibration file and restored at start-up. QoS through
the standard overrides, e.g. -p qos_overrides./balance/raw.subscription.reliability:=best_effort.

The math is live/calibrator_core.py, the state between samples live/stream.py, the parameters
live/parameters.py, the refit's process live/refit_process.py; this node translates.

Fast path: balance/raw arrives serialized (`raw=True`); the callback drains what else is already
waiting, decodes the batch with numpy (live/raw_codec.py), evaluates it in one call and publishes
bytes. One executor thread runs every callback, so node state needs no lock. ~/tare, ~/zero and
~/refit are coroutines in their own callback group: ~/tare awaits a future that the sample callback
completes once the window is full; ~/refit runs the pipeline in a separate process (watched by a
worker thread) and the new calibration replaces the old one when the coroutine resumes in the
executor thread, i.e. between two samples.
"""
from __future__ import annotations

import sys
import threading
import time
from functools import partial
from pathlib import Path

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.exceptions import ParameterException, ParameterUninitializedException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.serialization import deserialize_message
from rclpy.task import Future
from sensor_msgs.msg import Temperature
from std_msgs.msg import Bool
from std_srvs.srv import Trigger

from balance_calib.calibration_file import ConfigError
from balance_calib.config import resolve_config_path
from balance_calib.live.calibrator_core import ActiveCalibration, activate, parse_reliability
from balance_calib.live.parameters import (PARAMETERS, STRING_ARRAY, check_parameter, input_scale_mv,
                                           load_calibration_checked)
from balance_calib.live.raw_codec import WrenchEncoder, decode_wrenches
from balance_calib.live.refit_process import RefitJob, is_balance_config, make_refit_job, run_refit_job
from balance_calib.live.stream import LiveCalibrator, LiveSettings
from balance_calib.live.tare_store import load_tare, save_tare, tare_file_for

WRENCH_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
OVERLOAD_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
MAX_BATCH = 1000
CALIBRATION_PARAMETERS = {'calibration_file', 'model', 'installation', 'envelope_margin', 'output_range_factor'}


def default_calibration_file() -> Path:
    return resolve_config_path('lmc6522')


def _descriptor(name, spec) -> ParameterDescriptor:
    descriptor = ParameterDescriptor(description=spec.description, read_only=spec.read_only)
    if spec.low is not None and isinstance(spec.default, int):
        descriptor.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high), step=0)]
    elif spec.low is not None:
        descriptor.floating_point_range = [FloatingPointRange(from_value=float(spec.low), to_value=float(spec.high))]
    return descriptor


class BalanceCalibrator(Node):
    def __init__(self, *, refit_function=None, **kwargs):
        """refit_function: run_refit's signature, run in a thread; None = the pipeline in its own process."""
        super().__init__('balance_calibrator', **kwargs)
        try:
            overrides = getattr(self, '_parameter_overrides', {})     # command line and params files
            for name, spec in PARAMETERS.items():
                if name in overrides and spec.default != STRING_ARRAY:
                    value = overrides[name].value
                    check_parameter(name, value)       # our one-line reason, before rclpy's
                    if type(spec.default) is float and type(value) is int:    # tare_timeout_s:=5 means 5.0
                        overrides[name] = Parameter(name, value=float(value))
            for name, spec in PARAMETERS.items():
                default = Parameter.Type.STRING_ARRAY if spec.default == STRING_ARRAY else spec.default
                self.declare_parameter(name, default, _descriptor(name, spec))
                if spec.default != STRING_ARRAY:
                    check_parameter(name, self.get_parameter(name).value)
            self._input_scale = input_scale_mv(self._param('input_units'), self._param('excitation_v'))
        except (ParameterException, ValueError) as err:
            raise ConfigError(f'invalid parameter: {err}') from None
        self._refit_function = refit_function
        path = self._param('calibration_file') or str(default_calibration_file())
        try:
            active = self._activate(path, {})
            reliability = parse_reliability(self._param('input_reliability'))
        except ValueError as err:
            raise ConfigError(f'invalid parameter: {err}') from None
        self._live = LiveCalibrator(active, self._settings())
        self._tare_file = self._tare_path(active)
        self._restore_tare()
        self._last_sample_s: float | None = None         # time.monotonic() of the last raw sample
        self._temperature_c: float | None = None
        self._temperature_s: float | None = None
        self._fallback_reason = ''
        self._window_done: Future | None = None
        self._refit_running = False
        self._period_start_s = time.monotonic()
        self._pending: ActiveCalibration | None = None   # checked by _validate_parameters, applied after
        self._encoder = WrenchEncoder(self._param('frame_id'))

        qos = QoSProfile(depth=int(self._param('input_depth')),
                         reliability=ReliabilityPolicy.RELIABLE if reliability == 'reliable'
                         else ReliabilityPolicy.BEST_EFFORT)
        overrides = QoSOverridingOptions.with_default_policies()
        self._wrench_pub = self.create_publisher(WrenchStamped, 'balance/wrench', WRENCH_QOS,
                                                 qos_overriding_options=overrides)
        self._uncertainty_pub = self.create_publisher(WrenchStamped, 'balance/wrench_uncertainty', WRENCH_QOS,
                                                      qos_overriding_options=overrides)
        self._overload_pub = self.create_publisher(Bool, 'balance/overload', OVERLOAD_QOS)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._raw_sub = self.create_subscription(WrenchStamped, 'balance/raw', self._on_raw, qos, raw=True,
                                                 qos_overriding_options=overrides)
        self.create_subscription(Temperature, 'balance/temperature', self._on_temperature, qos)
        # A suspended coroutine keeps its callback group busy: the services must not share the
        # subscription's (default) group, or a waiting ~/tare would stop the very samples it waits for.
        services = ReentrantCallbackGroup()
        self.create_service(Trigger, '~/tare', partial(self._on_window, 'tare'), callback_group=services)
        self.create_service(Trigger, '~/zero', partial(self._on_window, 'zero'), callback_group=services)
        self.create_service(Trigger, '~/clear_tare', self._on_clear_tare, callback_group=services)
        self.create_service(Trigger, '~/refit', self._on_refit, callback_group=services)
        self._diagnostics_timer = self.create_timer(self._param('diagnostics_period_s'), self._on_diagnostics)
        self._stale_after_s = self._param('stale_after_s')
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self._overload_pub.publish(Bool(data=False))
        self.get_logger().info(f'{active.model_name} model of {active.calibration.balance} from {path}, '
                               f'{active.installation.name} installation; requires '
                               f'{", ".join(active.requires) or "bridge outputs only"}')

    def _param(self, name):
        try:
            return self.get_parameter(name).value
        except ParameterUninitializedException:    # calibration_bags when never set
            return None

    def _settings(self, changes: dict | None = None) -> LiveSettings:
        value = (lambda n: (changes or {}).get(n, self._param(n)))
        return LiveSettings(float(value('stale_after_s')), float(value('overload_fraction')),
                            float(value('overload_clear_s')), float(value('lowpass_hz')),
                            float(value('tare_max_scatter')), bool(value('publish_uncertainty')))

    def _activate(self, path: str, changes: dict) -> ActiveCalibration:
        """The calibration `path` with the (changed) parameters; ConfigError/ValueError with a reason."""
        value = (lambda n: changes.get(n, self._param(n)))
        calibration = load_calibration_checked(path, 10.0)
        try:
            return activate(calibration, value('model'), value('installation'), float(value('envelope_margin')),
                            source=str(path), output_range_factor=float(value('output_range_factor')))
        except ConfigError as err:
            raise ConfigError(f'{path}: {err}') from None

    def _wakeable_future(self) -> Future:
        """A future whose completion (from any thread) wakes the executor to resume its awaiter."""
        future = Future(executor=self.executor)
        future.add_done_callback(lambda _: None)
        return future

    # --- zero and tare persistence -----------------------------------------------------------
    def _tare_path(self, active: ActiveCalibration) -> Path | None:
        if self._param('tare_file'):
            return Path(self._param('tare_file')).expanduser()
        return tare_file_for(active.source, self.get_fully_qualified_name(), is_balance_config(active.source))

    def _restore_tare(self) -> None:
        if self._tare_file is None:
            return
        try:
            state = load_tare(self._tare_file, self._live.active.calibration.balance)
        except ValueError as err:
            self.get_logger().warning(f'not restoring zero and tare: {err}')
            return
        if state is None:
            return
        self._live.tare = state
        self.get_logger().info(
            f'restored from {self._tare_file}: zero ' + ('none' if state.zero_mv is None else
                                                        f'taken {state.zero_taken_at or "at an unknown time"}')
            + '; tare load ' + ('none' if state.tare_load is None else
                                f'{self._live.active.installation.to_tunnel(state.tare_load).round(3).tolist()} '
                                f'N, N·m (tunnel axes) taken {state.tare_taken_at or "at an unknown time"}'))

    def _persist_tare(self) -> str:
        if self._tare_file is None:
            return ('not persisted: the calibration is a shipped balance config (set parameter tare_file to keep '
                    'zero and tare across restarts)')
        try:
            save_tare(self._tare_file, self._live.tare)
            return f'saved to {self._tare_file}'
        except OSError as err:
            self.get_logger().error(f'cannot save zero and tare to {self._tare_file}: {err}')
            return f'NOT saved ({self._tare_file}: {err.strerror or err}): it will not survive a restart'

    # --- the stream ---------------------------------------------------------------------------
    def _on_temperature(self, msg: Temperature):
        if np.isfinite(msg.temperature):
            self._temperature_c, self._temperature_s = float(msg.temperature), time.monotonic()

    def _fresh_temperature(self, now_s: float) -> float | None:
        if self._temperature_s is None or now_s - self._temperature_s > self._stale_after_s:
            return None
        return self._temperature_c

    def _drain(self, first: bytes) -> list[bytes]:
        """The sample that woke us and whatever else is already waiting (up to MAX_BATCH)."""
        batch = [first]
        handle = self._raw_sub.handle
        with handle:
            while len(batch) < MAX_BATCH:
                taken = handle.take_message(WrenchStamped, True)
                if taken is None:
                    break
                batch.append(taken[0])
        return batch

    def _on_raw(self, first: bytes):
        messages = self._drain(first)
        try:
            stamps_ns, outputs, frame_ids = decode_wrenches(messages)
        except ValueError:             # not the layout the fast path knows: rclpy's deserializer
            decoded = [deserialize_message(m, WrenchStamped) for m in messages]
            stamps_ns = np.array([d.header.stamp.sec * 1_000_000_000 + d.header.stamp.nanosec for d in decoded])
            outputs = np.array([[d.wrench.force.x, d.wrench.force.y, d.wrench.force.z, d.wrench.torque.x,
                                 d.wrench.torque.y, d.wrench.torque.z] for d in decoded])
            frame_ids = [d.header.frame_id for d in decoded]
        if self._input_scale != 1.0:          # ratiometric bridge outputs (input_units) to mV
            outputs = outputs * self._input_scale
        now_s = time.monotonic()
        self._last_sample_s = now_s
        try:
            published = self._live.process(outputs, stamps_ns, frame_ids, now_s=now_s,
                                           temperature_c=self._fresh_temperature(now_s))
        except ConfigError as err:       # neither the model nor its base can run: publish nothing
            self.get_logger().error(str(err), throttle_duration_sec=5.0)
            return
        self._after_batch(published.batch.fallback_reason)
        if self._window_done is not None and self._live.window is not None and self._live.window.complete \
                and not self._window_done.done():
            self._window_done.set_result(True)
        stamps = stamps_ns[published.indices]
        publish = self._wrench_pub.publish
        for data in self._encoder.encode(stamps, published.wrench):
            publish(data)
        if published.uncertainty is not None:
            publish = self._uncertainty_pub.publish
            for data in self._encoder.encode(stamps, published.uncertainty):
                publish(data)

    def _after_batch(self, fallback_reason: str) -> None:
        live = self._live
        if live.overload_changed:
            self._overload_pub.publish(Bool(data=live.overload.active))
            if live.overload.active:
                self.get_logger().error(f'OVERLOAD: {", ".join(live.overload.components)} beyond '
                                        f'{live.overload.fraction:g} x rated load')
            else:
                self.get_logger().info('overload cleared: loads inside the limit for '
                                       f'{live.overload.clear_s:g} s')
        if fallback_reason != self._fallback_reason:
            if fallback_reason:
                self.get_logger().warning(f'{live.active.model_name} model cannot run ({fallback_reason}); '
                                          f'using {live.active.base_name}')
            else:
                self.get_logger().info(f'{live.active.model_name} model back in use')
            self._fallback_reason = fallback_reason

    # --- ~/tare, ~/zero, ~/clear_tare ---------------------------------------------------------
    async def _on_window(self, kind: str, request, response):
        if self._live.window is not None:
            response.success, response.message = False, f'{kind} failed: a {self._live.window.kind} is already ' \
                                                         f'collecting samples'
            return response
        samples, timeout_s = int(self._param('tare_samples')), float(self._param('tare_timeout_s'))
        window, done = self._live.start_window(kind, samples), self._wakeable_future()
        self._window_done = done
        timer = self.create_timer(timeout_s, lambda: done.done() or done.set_result(False))
        try:
            arrived = await done
        finally:
            self._window_done = None
            self.destroy_timer(timer)
        if not arrived:
            self._live.cancel_window()
            response.success = False
            response.message = (f'{kind} failed: only {len(window.outputs_mv)} of {samples} valid samples arrived '
                                 f'on balance/raw within {timeout_s:g} s; the previous {kind} stays')
            return response
        result = self._live.finish_window()
        response.success, response.message = result.ok, result.message
        if result.ok:
            response.message += '; ' + self._persist_tare()
            self.get_logger().info(response.message)
        else:
            self.get_logger().warning(response.message)
        return response

    def _on_clear_tare(self, request, response):
        response.success = True
        response.message = self._live.clear_tare() + '; ' + self._persist_tare()
        self.get_logger().info(response.message)
        return response

    # --- ~/refit ------------------------------------------------------------------------------
    async def _on_refit(self, request, response):
        active = self._live.active
        keep = f'the calibration from {active.source} ({active.model_name}) stays in force'
        if self._refit_running:
            response.success, response.message = False, f'refit failed: a refit is already running; {keep}'
            return response
        try:
            job = self._refit_job()
        except (OSError, ValueError) as err:
            response.success, response.message = False, f'refit failed: {err}; {keep}'
            return response
        done = self._wakeable_future()
        self._refit_running = True
        threading.Thread(target=self._refit_worker, args=(job, done), name='refit', daemon=True).start()
        try:
            outcome = await done
        finally:
            self._refit_running = False
        if isinstance(outcome, str):
            response.success, response.message = False, f'refit failed: {outcome}; {keep}'
            self.get_logger().error(response.message)
            return response
        new_active, target, message = outcome
        self._live.set_active(new_active)            # in the executor thread: between two samples
        if str(target) != str(job.calibration_file):
            self._pending = None
            self.set_parameters([Parameter('calibration_file', value=str(target))])
        response.success, response.message = True, message
        self.get_logger().info(message)
        return response

    def _refit_job(self) -> RefitJob:
        active = self._live.active
        return make_refit_job(self._param('calibration_bags') or [], str(self._param('balance')),
                              self._param('report_dir'), str(self._param('model')), active.installation,
                              float(self._param('envelope_margin')), float(self._param('output_range_factor')),
                              float(self._param('refit_timeout_s')), active.source)

    def _refit_worker(self, job: RefitJob, done: Future) -> None:
        """Runs in its own thread: completes `done` with (active, file, message) or a reason (str)."""
        try:
            outcome = run_refit_job(job, self._refit_function, lambda line: self.get_logger().info(f'refit: {line}'))
        except Exception as err:    # any failure leaves the node and its calibration as they were
            outcome = f'{type(err).__name__}: {err}'
        done.set_result(outcome)

    # --- parameters ---------------------------------------------------------------------------
    def _validate_parameters(self, parameters) -> SetParametersResult:
        changes = {p.name: p.value for p in parameters}
        try:
            for name, value in changes.items():
                check_parameter(name, value)
            if 'balance' in changes:
                resolve_config_path(changes['balance'])
            if {'input_units', 'excitation_v'} & set(changes):
                input_scale_mv(changes.get('input_units', self._param('input_units')),
                               changes.get('excitation_v', self._param('excitation_v')))
            if CALIBRATION_PARAMETERS & set(changes):
                path = changes.get('calibration_file', None)
                path = self._live.active.source if path is None else (path or str(default_calibration_file()))
                self._pending = self._activate(path, changes)
        except (ConfigError, ValueError, TypeError) as err:
            return SetParametersResult(successful=False, reason=str(err))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters) -> None:
        names = {p.name for p in parameters}
        self._stale_after_s = self._param('stale_after_s')
        self._input_scale = input_scale_mv(self._param('input_units'), self._param('excitation_v'))
        self._live.set_settings(self._settings())
        if 'frame_id' in names:
            self._encoder = WrenchEncoder(self._param('frame_id'))
        if 'diagnostics_period_s' in names:
            self.destroy_timer(self._diagnostics_timer)
            self._diagnostics_timer = self.create_timer(self._param('diagnostics_period_s'), self._on_diagnostics)
        pending, self._pending = self._pending, None
        if pending is not None:
            before = self._live.active
            self._live.set_active(pending)
            # rclpy applies a request of several parameters one by one: say it once, when it changed
            if (before.model_name, before.source, before.installation.name) != \
                    (pending.model_name, pending.source, pending.installation.name):
                self.get_logger().info(f'now {pending.model_name} model from {pending.source}, '
                                       f'{pending.installation.name} installation')
        if 'tare_file' in names or 'calibration_file' in names:
            self._tare_file = self._tare_path(self._live.active)

    # --- /diagnostics -------------------------------------------------------------------------
    def _on_diagnostics(self):
        now_s = time.monotonic()
        reports = self._live.report(
            period_s=now_s - self._period_start_s,
            last_sample_age_s=None if self._last_sample_s is None else now_s - self._last_sample_s,
            temperature_age_s=None if self._temperature_s is None else now_s - self._temperature_s,
            refit_running=self._refit_running,
            tare_source='not persisted' if self._tare_file is None else str(self._tare_file),
            node_name=self.get_fully_qualified_name().lstrip('/'))
        self._period_start_s = now_s
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        for report in reports:
            array.status.append(DiagnosticStatus(
                level=bytes([report.level]), name=report.name, message=report.message,
                hardware_id=report.hardware_id, values=[KeyValue(key=k, value=v) for k, v in report.values]))
        self._diagnostics_pub.publish(array)


def main(args=None):
    from ._help import exit_if_help
    exit_if_help(__name__, args)     # --help: print the parameters and exit before rclpy starts
    rclpy.init(args=args)
    node = None
    status = 0
    try:
        node = BalanceCalibrator()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ConfigError as err:
        rclpy.logging.get_logger('balance_calibrator').error(f'cannot start: {err}')
        status = 1
    except RuntimeError:
        # a signal landing while spin() builds its wait set surfaces as RCLError "context is not
        # valid" (ros2/ros2cli#854): that is a shutdown, not a failure
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return status


if __name__ == '__main__':
    sys.exit(main())
