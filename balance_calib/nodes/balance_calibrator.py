"""balance_calibrator: /balance/raw (mV) -> /balance/wrench (N, N·m, tunnel axes) with the active calibration.

The math is live/calibrator_core.py; this node translates messages, parameters and services.

Concurrency: one executor thread runs every callback, so node state needs no lock. ~/tare and
~/refit are coroutines (async service callbacks, in their own callback group): ~/tare awaits a
future that the raw-sample callback completes once the window is full; ~/refit hands the slow
work (run_refit, checking the result, writing calibration_file atomically) to a worker thread
and awaits its future. While a service awaits, the executor goes on serving samples; the new
calibration (an immutable ActiveCalibration) replaces the old one when the coroutine resumes in
the executor thread, i.e. between two samples. (rclpy's MultiThreadedExecutor would do as well
but costs three times the CPU per sample.)
"""
from __future__ import annotations

import datetime as _dt
import importlib
import sys
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import rclpy
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.exceptions import ParameterUninitializedException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from sensor_msgs.msg import Temperature
from std_srvs.srv import Trigger

from balance_calib.calibration_file import Calibration, ConfigError, load_calibration, save_calibration
from balance_calib.config import resolve_config_path
from balance_calib.live.calibrator_core import (ActiveCalibration, InputCounters, LiveState, LoadHistory,
                                                TareWindow, activate, compute_wrench, describe_tare, diagnostics,
                                                parse_reliability, six_axis_loads)
from balance_calib.tunnel_axes import Installation, parse_installation

PARAMETERS = {   # name: (default, description)
    'calibration_file': (None, 'calibration.yaml or balance config (default: the shipped config/lmc6522.yaml)'),
    'model': ('adopted', 'linear | quadratic | cubic | adopted (or any model name in the file)'),
    'installation': ('upright', 'upright (TM-663 §10.2.1) | inverted (§10.2.2) | e.g. "-FX,FY,-FZ,MX,MY,MZ"'),
    'frame_id': ('tunnel', 'frame_id of /balance/wrench'),
    'tare_samples': (100, 'samples averaged by ~/tare'),
    'tare_timeout_s': (10.0, '~/tare fails if the samples do not arrive within this time'),
    'calibration_bags': (Parameter.Type.STRING_ARRAY, 'bags (directories or .mcap) that ~/refit fits'),
    'balance': ('lmc6522', 'balance config for the refit (schedule, body, capacity)'),
    'report_dir': ('~/.balance_calib/reports', '~/refit writes each run into a new directory here'),
    'input_reliability': ('reliable', 'QoS of the /balance/raw subscription: reliable | best_effort'),
    'input_depth': (1000, 'queue depth of the /balance/raw subscription'),
    'stale_after_s': (1.0, 'an input silent this long is stale'),
    'diagnostics_period_s': (1.0, 'period of /diagnostics'),
    'envelope_margin': (1.1, 'loads beyond this times capacity are flagged as outside the envelope'),
}
READ_ONLY = ('input_reliability', 'input_depth')     # QoS is fixed when the subscription is made
WRENCH_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)


def default_calibration_file() -> Path:
    return resolve_config_path('lmc6522')


def is_balance_config(path: str | Path) -> bool:
    """True for a balance description (config/*.yaml); a refit must not overwrite one of those."""
    try:
        data = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError):
        return False
    return isinstance(data, dict) and 'matrices' in data and 'models' not in data


def load_refit_function():
    """The refit pipeline behind `balance-calib refit` (imported when first needed)."""
    return importlib.import_module('balance_calib.refit.pipeline').run_refit


@dataclass(frozen=True)
class RefitJob:
    """What a refit needs, fixed when ~/refit is called (the worker thread touches no node state)."""

    bags: tuple[Path, ...]
    balance: str
    out_dir: Path
    model: str                    # the `model` parameter
    installation: Installation
    envelope_margin: float
    calibration_file: Path        # replaced by the result (unless it is a balance config)


@dataclass(frozen=True)
class RefitOutcome:
    success: bool
    message: str
    active: ActiveCalibration | None = None
    calibration_file: Path | None = None


class BalanceCalibrator(Node):
    def __init__(self, *, refit_function=None, **kwargs):
        """refit_function: run_refit's signature; None = balance_calib.refit.pipeline.run_refit."""
        super().__init__('balance_calibrator', **kwargs)
        for name, (default, description) in PARAMETERS.items():
            if name == 'calibration_file':
                default = str(default_calibration_file())
            self.declare_parameter(name, default, ParameterDescriptor(
                description=description, read_only=name in READ_ONLY))
        self._refit_function = refit_function
        path = self._param('calibration_file') or str(default_calibration_file())
        calibration = load_calibration(path)            # ConfigError naming the file: main() exits 1
        try:
            self._active = activate(calibration, self._param('model'), self._param('installation'),
                                    self._param('envelope_margin'), source=str(path))
            reliability = parse_reliability(self._param('input_reliability'))
        except ConfigError as err:
            raise ConfigError(f'{path}: {err}') from None
        except ValueError as err:
            raise ConfigError(f'invalid parameter: {err}') from None
        self._history = LoadHistory(self._active.capacity)
        self._counters = InputCounters()
        self._tare_zero_mv: np.ndarray | None = None     # wind-off bridge outputs subtracted, mV
        self._tare_temperature_c: float | None = None    # temperature and load direction at that tare
        self._tare_direction: np.ndarray | None = None
        self._collecting: tuple[TareWindow, Future] | None = None
        self._last_sample_s: float | None = None         # time.monotonic() of the last raw sample
        self._temperature_c: float | None = None
        self._temperature_s: float | None = None
        self._fallback_reason = ''
        self._refit_running = False
        self._period_start_s = time.monotonic()
        self._pending: ActiveCalibration | None = None   # checked by _validate_parameters, applied after

        qos = QoSProfile(depth=int(self._param('input_depth')),
                         reliability=ReliabilityPolicy.RELIABLE if reliability == 'reliable'
                         else ReliabilityPolicy.BEST_EFFORT)
        self._wrench_pub = self.create_publisher(WrenchStamped, '/balance/wrench', WRENCH_QOS)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_subscription(WrenchStamped, '/balance/raw', self._on_raw, qos)
        self.create_subscription(Temperature, '/balance/temperature', self._on_temperature, qos)
        # A suspended coroutine keeps its callback group busy: the services must not share the
        # subscription's (default) group, or a waiting ~/tare would stop the very samples it waits for.
        services = ReentrantCallbackGroup()
        self.create_service(Trigger, '~/tare', self._on_tare, callback_group=services)
        self.create_service(Trigger, '~/refit', self._on_refit, callback_group=services)
        self._diagnostics_timer = self.create_timer(self._param('diagnostics_period_s'), self._on_diagnostics)
        self._frame_id = self._param('frame_id')
        self._stale_after_s = self._param('stale_after_s')
        self._out = WrenchStamped()
        self._last_warning_s: dict[str, float] = {}
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self.get_logger().info(f'{self._active.model_name} model of {calibration.balance} from {path}, '
                               f'{self._active.installation.name} installation; requires '
                               f'{", ".join(self._active.requires) or "bridge outputs only"}')

    def _due(self, what: str, now_s: float, every_s: float = 5.0) -> bool:
        """A cheap log throttle for the per-sample path (rclpy's throttle inspects the call stack)."""
        if now_s - self._last_warning_s.get(what, -1e9) < every_s:
            return False
        self._last_warning_s[what] = now_s
        return True

    def _param(self, name):
        try:
            return self.get_parameter(name).value
        except ParameterUninitializedException:    # calibration_bags when never set
            return None

    def _wakeable_future(self) -> Future:
        """A future whose completion (from any thread) wakes the executor to resume its awaiter."""
        future = Future(executor=self.executor)
        future.add_done_callback(lambda _: None)
        return future

    # --- the stream ---------------------------------------------------------------------------
    def _on_temperature(self, msg: Temperature):
        if np.isfinite(msg.temperature):
            self._temperature_c, self._temperature_s = float(msg.temperature), time.monotonic()

    def _fresh_temperature(self, now_s: float) -> float | None:
        if self._temperature_s is None or now_s - self._temperature_s > self._stale_after_s:
            return None
        return self._temperature_c

    def _on_raw(self, msg: WrenchStamped):
        f, t = msg.wrench.force, msg.wrench.torque
        outputs = np.array([[f.x, f.y, f.z, t.x, t.y, t.z]])
        now_s = time.monotonic()
        active = self._active
        self._last_sample_s = now_s
        temperature = self._fresh_temperature(now_s)
        direction = None
        if 'load_history' in active.requires and np.all(np.isfinite(outputs)):
            tared = outputs - (0.0 if self._tare_zero_mv is None else self._tare_zero_mv)
            direction = self._history.update(six_axis_loads(active.base_model, tared))
        try:
            batch = compute_wrench(active, outputs, zero_mv=self._tare_zero_mv, temperature_c=temperature,
                                   load_direction=direction, tare_temperature_c=self._tare_temperature_c,
                                   tare_direction=self._tare_direction)
        except ConfigError as err:       # neither the model nor its base can run: publish nothing
            self.get_logger().error(str(err), throttle_duration_sec=5.0)
            return
        self._counters.count(batch)
        if not batch.accepted[0]:
            if self._due('nonfinite', now_s):
                self.get_logger().warning(f'rejected a /balance/raw sample with NaN/inf outputs '
                                          f'({self._counters.rejected_nonfinite} so far)')
            return
        if batch.fallback_reason != self._fallback_reason:
            if batch.fallback_reason:
                self.get_logger().warning(f'{active.model_name} model cannot run ({batch.fallback_reason}); '
                                          f'using {active.base_name}')
            else:
                self.get_logger().info(f'{active.model_name} model back in use')
            self._fallback_reason = batch.fallback_reason
        if batch.out_of_envelope[0] and self._due('envelope', now_s):
            self.get_logger().warning(f'load outside the calibrated envelope ({self._counters.out_of_envelope}'
                                      f' samples so far)')
        if self._collecting is not None:
            window, done = self._collecting
            if window.add(outputs) and not done.done():
                done.set_result(True)
        out = self._out          # one message, reused: publish() serializes it before returning
        out.header.stamp = msg.header.stamp
        out.header.frame_id = self._frame_id
        force, torque = out.wrench.force, out.wrench.torque
        force.x, force.y, force.z, torque.x, torque.y, torque.z = batch.wrench_tunnel[0].tolist()
        self._wrench_pub.publish(out)

    # --- ~/tare -------------------------------------------------------------------------------
    async def _on_tare(self, request, response):
        if self._collecting is not None:
            response.success, response.message = False, 'tare failed: a tare is already collecting samples'
            return response
        samples, timeout_s = int(self._param('tare_samples')), float(self._param('tare_timeout_s'))
        window, done = TareWindow(samples), self._wakeable_future()
        self._collecting = (window, done)
        timer = self.create_timer(timeout_s, lambda: done.done() or done.set_result(False))
        try:
            arrived = await done
        finally:
            self._collecting = None
            self.destroy_timer(timer)
        if not arrived:
            response.success = False
            response.message = (f'tare failed: only {len(window.outputs_mv)} of {samples} valid samples arrived on '
                                f'/balance/raw within {timeout_s:g} s; the previous tare stays')
            return response
        previous, self._tare_zero_mv = self._tare_zero_mv, window.zero_mv
        # the conditions of the zero, for models with temperature or load-direction terms
        self._tare_temperature_c = self._fresh_temperature(time.monotonic())
        self._tare_direction = self._history.direction.copy()
        response.success = True
        response.message = f'tare: averaged {samples} samples; bridge zero now subtracted: ' \
                           f'{describe_tare(self._tare_zero_mv, self._active)}'
        if previous is not None:
            response.message += '; change from the previous tare: ' + ', '.join(
                f'{c}={v:+.5f} mV' for c, v in zip(self._active.calibration.bridge_outputs,
                                                   self._tare_zero_mv - previous))
        self.get_logger().info(response.message)
        return response

    # --- ~/refit ------------------------------------------------------------------------------
    async def _on_refit(self, request, response):
        keep = f'the calibration from {self._active.source} ({self._active.model_name}) stays in force'
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
        worker = threading.Thread(target=self._refit_worker, args=(job, keep, done), name='refit', daemon=True)
        worker.start()
        try:
            outcome: RefitOutcome = await done
        finally:
            self._refit_running = False
        if outcome.success:            # in the executor thread: between two samples
            self._active = outcome.active
            self._history = LoadHistory(outcome.active.capacity)
            if str(outcome.calibration_file) != str(job.calibration_file):
                self._pending = None
                self.set_parameters([Parameter('calibration_file', value=str(outcome.calibration_file))])
        response.success, response.message = outcome.success, outcome.message
        (self.get_logger().info if outcome.success else self.get_logger().error)(outcome.message)
        return response

    def _refit_job(self) -> RefitJob:
        bags = tuple(Path(b).expanduser() for b in (self._param('calibration_bags') or []) if b)
        if not bags:
            raise ValueError('parameter calibration_bags is empty')
        missing = [str(b) for b in bags if not b.exists()]
        if missing:
            raise ValueError(f'calibration bag {", ".join(missing)} does not exist')
        root = Path(self._param('report_dir')).expanduser()
        root.mkdir(parents=True, exist_ok=True)
        out_dir = root / ('refit-' + _dt.datetime.now(_dt.timezone.utc).strftime('%Y%m%dT%H%M%SZ'))
        for k in range(1, 1000):
            if not out_dir.exists():
                break
            out_dir = out_dir.with_name(f'{out_dir.name.split("+")[0]}+{k}')
        return RefitJob(bags, str(self._param('balance')), out_dir, str(self._param('model')),
                        self._active.installation, float(self._param('envelope_margin')),
                        Path(self._active.source))

    def _refit_worker(self, job: RefitJob, keep: str, done: Future) -> None:
        """Runs in its own thread; completes `done` with a RefitOutcome whatever happens."""
        try:
            outcome = self._refit(job, keep)
        except Exception as err:    # any failure leaves the node and its calibration as they were
            outcome = RefitOutcome(False, f'refit failed: {type(err).__name__}: {err}; {keep}')
        done.set_result(outcome)

    def _refit(self, job: RefitJob, keep: str) -> RefitOutcome:
        try:
            refit = self._refit_function or load_refit_function()
        except ImportError as err:
            return RefitOutcome(False, f'refit failed: the refit pipeline is not available ({err}); {keep}')
        base = job.model if job.model in ('linear', 'quadratic', 'cubic') else 'cubic'
        try:
            result = refit(list(job.bags), job.balance, job.out_dir, model=base, diagnose=True,
                           progress=lambda line: self.get_logger().info(f'refit: {line}'))
            calibration = result.calibration
            if not isinstance(calibration, Calibration):
                raise TypeError(f'the refit returned {type(calibration).__name__}, not a Calibration')
            active = activate(calibration, job.model, job.installation, job.envelope_margin)
        except ValueError as err:   # RefitError, BagError, ConfigError: their message names the file
            return RefitOutcome(False, f'refit failed: {err}; {keep}')
        except Exception as err:    # a bug rather than bad input: say what kind
            return RefitOutcome(False, f'refit failed: {type(err).__name__}: {err}; {keep}')
        target = job.calibration_file
        try:
            if is_balance_config(target):
                # never overwrite a balance description: it carries the schedule the refit needs
                target = Path(getattr(result, 'calibration_path', None) or job.out_dir / 'calibration.yaml')
                if not target.exists():
                    save_calibration(target, calibration)
                note = (f'{job.calibration_file} is a balance config and stays as it is; '
                        f'calibration_file is now {target}')
            else:
                save_calibration(target, calibration)       # atomic replace
                note = f'{target} replaced'
        except OSError as err:
            return RefitOutcome(False, f'refit failed: cannot write {target}: {err}; {keep}')
        summary = getattr(result, 'summary', '') or 'done'
        return RefitOutcome(True, f'refit OK: {summary}; now {active.model_name} model; {note}; '
                                  f'report in {job.out_dir}', replace(active, source=str(target)), target)

    # --- parameters ---------------------------------------------------------------------------
    def _candidate(self, changes: dict) -> ActiveCalibration:
        """The calibration the changed parameters would give; raises with a message if none."""
        path = changes.get('calibration_file', None)
        if path is None or path == self._active.source:
            calibration, source = self._active.calibration, self._active.source
        else:
            source = path or str(default_calibration_file())
            calibration = load_calibration(source)
        return activate(calibration, changes.get('model', self._param('model')),
                        changes.get('installation', self._param('installation')),
                        changes.get('envelope_margin', self._param('envelope_margin')), source=source)

    def _validate_parameters(self, parameters) -> SetParametersResult:
        changes = {p.name: p.value for p in parameters}
        try:
            for name in ('tare_samples', 'input_depth'):
                if name in changes and int(changes[name]) < 1:
                    raise ValueError(f'{name} must be at least 1')
            for name in ('stale_after_s', 'diagnostics_period_s', 'tare_timeout_s'):
                if name in changes and not float(changes[name]) > 0:
                    raise ValueError(f'{name} must be positive')
            if 'installation' in changes:
                parse_installation(changes['installation'])
            if 'balance' in changes:
                resolve_config_path(changes['balance'])
            if {'calibration_file', 'model', 'installation', 'envelope_margin'} & set(changes):
                self._pending = self._candidate(changes)
        except (ConfigError, ValueError, TypeError) as err:
            return SetParametersResult(successful=False, reason=str(err))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters) -> None:
        self._frame_id = self._param('frame_id')      # read per sample: kept as attributes
        self._stale_after_s = self._param('stale_after_s')
        if 'diagnostics_period_s' in {p.name for p in parameters}:
            self.destroy_timer(self._diagnostics_timer)
            self._diagnostics_timer = self.create_timer(self._param('diagnostics_period_s'), self._on_diagnostics)
        pending, self._pending = self._pending, None
        if pending is not None:
            self._active = pending
            self.get_logger().info(f'now {pending.model_name} model from {pending.source}, '
                                   f'{pending.installation.name} installation')

    # --- /diagnostics -------------------------------------------------------------------------
    def _on_diagnostics(self):
        now_s = time.monotonic()
        state = LiveState(
            period_s=now_s - self._period_start_s, counters=self._counters,
            last_sample_age_s=None if self._last_sample_s is None else now_s - self._last_sample_s,
            stale_after_s=float(self._param('stale_after_s')),
            temperature_age_s=None if self._temperature_s is None else now_s - self._temperature_s,
            fallback_reason=self._fallback_reason, tare_zero_mv=self._tare_zero_mv,
            refit_running=self._refit_running)
        reports = diagnostics(self._active, state, self.get_name())
        self._counters.start_period()
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
