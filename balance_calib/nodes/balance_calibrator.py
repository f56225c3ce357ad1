"""balance_calibrator: balance/raw (mV) -> balance/wrench (N, N·m, tunnel axes) with the active
calibration.

Topics (relative: `--ros-args -r __ns:=/left` runs a second balance beside the first): in
balance/raw, balance/temperature; out balance/wrench, balance/wrench_uncertainty (when the
calibration carries its covariance and someone subscribes), balance/overload (std_msgs/Bool,
transient local), /diagnostics. Services (std_srvs/Trigger): ~/zero (electrical zero, output space:
only with nothing on the balance), ~/tare (tare load, e.g. the model's weight wind-off: load space,
the calibration on the full outputs), ~/clear_tare, ~/refit. ~/zero and ~/tare refuse a window that
is not steady and say why; both are kept in <calibration>.tare.yaml beside the calibration file and
restored at start-up for the same calibration content, installation, namespace and node
(live/tare_store.py). QoS through the standard overrides, e.g. -p
qos_overrides./balance/raw.subscription.reliability:=best_effort.

This node translates; live/session.py does the work (math in live/calibrator_core.py; each sample
in one C call where it applies, live/sample_kernel.py). balance/raw is read serialized by a thread
of its own (nodes/_raw_input.py) in batches of what is waiting; the executor runs the services,
parameters and timers and never wakes for a sample. ~/tare and ~/zero await a future that the
reader completes once the window is full; ~/refit runs the pipeline in a separate process and the
session swaps the new calibration in between two batches.
"""

from __future__ import annotations

from functools import partial
import gc
import sys

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.exceptions import ParameterException
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
from balance_calib.live.parameters import check_parameter, PARAMETERS
from balance_calib.live.raw_codec import wrench_arrays
from balance_calib.live.session import CalibratorSession

from ._messages import diagnostic_array
from ._parameters import declare_table, value_getter
from ._qos import STREAM_QOS
from ._raw_input import RawInput
from ._run import run_node

OVERLOAD_QOS = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)
MAX_BATCH = 1000
SWITCH_INTERVAL_S = 0.0005


class BalanceCalibrator(Node):
    def __init__(self, *, refit_function=None, **kwargs):
        """refit_function: run_refit's signature, run in a thread; None = the pipeline in its
        own process.
        """
        super().__init__('balance_calibrator', **kwargs)
        try:
            declare_table(self, PARAMETERS, check_parameter)
        except (ParameterException, ValueError) as err:
            raise ConfigError(f'invalid parameter: {err}') from None
        self._refit_function = refit_function
        self.session = CalibratorSession(
            value_getter(self),
            self.get_fully_qualified_name(),
            self._log,
            lambda messages: wrench_arrays(
                [deserialize_message(m, WrenchStamped) for m in messages]
            ),
        )
        value = self.session.value
        overrides = QoSOverridingOptions.with_default_policies()
        self._wrench_pub = self.create_publisher(
            WrenchStamped, 'balance/wrench', STREAM_QOS, qos_overriding_options=overrides
        )
        # who reads the uncertainty, kept by the publisher's matched event: asking rmw at every
        # batch cost 5-15 µs a sample at 1 kHz (cold caches); asked still while the count is 0 (and
        # publish_uncertainty is on), so that the first batch after a subscriber matches does not
        # wait for the executor to deliver the event
        self._uncertainty_readers = 0
        self._uncertainty_pub = self.create_publisher(
            WrenchStamped,
            'balance/wrench_uncertainty',
            STREAM_QOS,
            qos_overriding_options=overrides,
            event_callbacks=PublisherEventCallbacks(matched=self._on_uncertainty_matched),
        )
        self._overload_pub = self.create_publisher(Bool, 'balance/overload', OVERLOAD_QOS)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        qos = QoSProfile(
            depth=int(value('input_depth')),
            reliability=ReliabilityPolicy.RELIABLE
            if self.session.reliability == 'reliable'
            else ReliabilityPolicy.BEST_EFFORT,
        )
        self._raw_input = RawInput(
            self,
            WrenchStamped,
            'balance/raw',
            qos,
            self._on_raw,
            max_batch=MAX_BATCH,
            qos_overriding_options=overrides,
            thread_name='balance_raw',
        )
        self.create_subscription(
            Temperature,
            'balance/temperature',
            lambda msg: self.session.on_temperature(msg.temperature),
            qos,
        )
        # A suspended coroutine keeps its callback group busy: ~/refit must not block ~/tare and
        # the rest
        services = ReentrantCallbackGroup()
        self.create_service(
            Trigger, '~/tare', partial(self._on_window, 'tare'), callback_group=services
        )
        self.create_service(
            Trigger, '~/zero', partial(self._on_window, 'zero'), callback_group=services
        )
        self.create_service(Trigger, '~/clear_tare', self._on_clear_tare, callback_group=services)
        self.create_service(Trigger, '~/refit', self._on_refit, callback_group=services)
        self._diagnostics_timer = self.create_timer(
            value('diagnostics_period_s'), self._on_diagnostics
        )
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self._overload_pub.publish(Bool(data=False))
        self._raw_input.start()

    def _log(self, level: str, line: str) -> None:
        logger = self.get_logger()  # rclpy wants one severity per call site
        if level == 'info':
            logger.info(line)
        elif level == 'warning':
            logger.warning(line)
        elif level == 'error':
            logger.error(line)
        else:
            logger.error(line, throttle_duration_sec=5.0)

    def destroy_node(self):
        self._raw_input.close()
        return super().destroy_node()

    def _on_raw(self, messages: list[bytes]) -> None:
        """In the reader thread: one batch of serialized samples (the uncertainty only for
        subscribers).
        """
        wanted = self._uncertainty_readers > 0 or (
            self.session.live.settings.publish_uncertainty
            and self._uncertainty_pub.get_subscription_count() > 0
        )
        out = self.session.on_samples(messages, wanted)
        if out is None:
            return
        if out.overload is not None:  # an interlock hears it first
            self._overload_pub.publish(Bool(data=out.overload))
        publish = self._wrench_pub.publish
        for data in out.wrench:
            publish(data)
        publish = self._uncertainty_pub.publish
        for data in out.uncertainty():  # computed after the wrenches went out
            publish(data)

    def _on_uncertainty_matched(self, status) -> None:
        self._uncertainty_readers = status.current_count

    def _wakeable_future(self) -> Future:
        """A future whose completion (from any thread) wakes the executor to resume its awaiter."""
        future = Future(executor=self.executor)
        future.add_done_callback(lambda _: None)
        return future

    async def _on_window(self, kind: str, request, response):
        done, timeout_s = self._wakeable_future(), float(self.session.value('tare_timeout_s'))
        refused = self.session.start_window(kind, lambda: done.done() or done.set_result(True))
        if refused:
            response.success, response.message = False, refused
            return response
        timer = self.create_timer(timeout_s, lambda: done.done() or done.set_result(False))
        try:
            arrived = await done
        finally:
            self.destroy_timer(timer)
        response.success, response.message = self.session.finish_window(kind, arrived, timeout_s)
        return response

    def _on_clear_tare(self, request, response):
        response.success, response.message = True, self.session.clear_tare()
        return response

    async def _on_refit(self, request, response):
        done = self._wakeable_future()
        refused = self.session.start_refit(self._refit_function, done.set_result)
        if refused:
            response.success, response.message = False, refused
            return response
        response.success, response.message, new_file = self.session.finish_refit(await done)
        # a balance config stays as it is: the node now reads the new file
        if new_file is not None:
            self.set_parameters([Parameter('calibration_file', value=new_file)])
        return response

    def _validate_parameters(self, parameters) -> SetParametersResult:
        try:
            self.session.validate({p.name: p.value for p in parameters})
        except (ConfigError, ValueError, TypeError) as err:
            return SetParametersResult(successful=False, reason=str(err))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters) -> None:
        if self.session.apply({p.name for p in parameters}):
            self.destroy_timer(self._diagnostics_timer)
            self._diagnostics_timer = self.create_timer(
                self.session.value('diagnostics_period_s'), self._on_diagnostics
            )

    def _on_diagnostics(self):
        self._diagnostics_pub.publish(
            diagnostic_array(self.get_clock().now().to_msg(), self.session.report())
        )


def _before_spin(node) -> None:
    # start-up's objects (numpy, scipy, rclpy) out of the collector's way: shorter pauses
    gc.freeze()
    # a service callback (a refit's new calibration read and checked) holds the GIL for up to
    # the switch interval while a sample waits in the reader thread: 0.5 ms instead of Python's
    # 5 ms
    sys.setswitchinterval(SWITCH_INTERVAL_S)


def main(args=None):
    from ._help import exit_if_help

    exit_if_help(__name__, args)  # --help: print the parameters and exit before rclpy starts
    return run_node(
        'balance_calibrator',
        BalanceCalibrator,
        refused=(ConfigError,),
        refusal_prefix='cannot start: ',
        args=args,
        before_spin=_before_spin,
    )


if __name__ == '__main__':
    sys.exit(main())
