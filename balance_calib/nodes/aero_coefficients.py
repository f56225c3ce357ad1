"""aero_coefficients: calibrated loads -> aerodynamic coefficients, live (TM-663 §10.3-10.4).

Subscribes (relative names, reliable):
  balance/wrench            geometry_msgs/WrenchStamped   calibrated loads, tunnel axes of §10.2
                                                          (no tare: the weight tare and offsets are
                                                          taken here, in load space)
  model/attitude            geometry_msgs/Vector3Stamped  support angles x = φ, y = α, z = β, rad
  tunnel/dynamic_pressure   sensor_msgs/FluidPressure     q∞, Pa
Publishes, per wind-on sample (stamp of the wrench sample):
  aero/coefficients         force = (C_AF, C_Y, C_N), torque = (C_l, C_m, C_n) about the MRC; frame
                            body
  aero/wind_coefficients    force = (C_D, C_Y,w, C_L), torque = stability-axis (C_l, C_m, C_n);
                            frame wind
and per held attitude (the averaged data point; stamp of its last sample):
  aero/point, aero/point_wind          the point's coefficients (loads averaged, then reduced)
  aero/point_scatter                   sample standard deviation of the per-sample body
                                       coefficients
  aero/point_uncertainty               standard uncertainty (k = 1) of the body coefficients from
                                       the calibration σ and the weight tare
  aero/point_attitude                  the deflection-corrected (φ, α, β) of the point, rad
  /diagnostics                         samples, stale inputs, points, the weight tare in force
Service ~/take_point (std_srvs/Trigger): a point on demand, the next `take_point_samples` wind-on
samples of the current hold, published on the point topics like the automatic ones; the reply
gives its coefficients ± scatter, or why there is none (attitude moved, wind off, no tare,
timeout).

The steps are aero/live.py's, the same as `balance-calib reduce` (aero/run.py). The parameters
(the model, the calibration for the σ that weights the tare fit and gives the uncertainty, what
makes a hold, a point and a stale sample) are aero/live_parameters.py's table.
"""

from __future__ import annotations

import sys

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Vector3Stamped, WrenchStamped
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.task import Future
from rclpy.time import Time
from sensor_msgs.msg import FluidPressure
from std_srvs.srv import Trigger

from balance_calib.aero.held_points import HoldSettings
from balance_calib.aero.live import LiveReduction
from balance_calib.aero.live_parameters import PARAMETERS
from balance_calib.aero.model_file import load_model
from balance_calib.aero.pipeline import calibration_sigma
from balance_calib.calibration_file import load_calibration
from balance_calib.config import ConfigError
from balance_calib.tunnel_axes import parse_installation

from ._messages import set_wrench
from ._parameters import declare_table
from ._qos import STREAM_QOS
from ._run import run_node


class StartupError(ValueError):
    pass


def _ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def _wrench(stamp_ns: int, frame: str, values) -> WrenchStamped:
    msg = WrenchStamped()
    msg.header.stamp = Time(nanoseconds=stamp_ns).to_msg()
    msg.header.frame_id = frame
    set_wrench(msg.wrench, values)
    return msg


class AeroCoefficients(Node):
    def __init__(self, **kwargs):
        super().__init__('aero_coefficients', **kwargs)
        try:
            p = declare_table(self, PARAMETERS)  # read once, here (read-only)
            model = load_model(p['model'])
            if p['estimate_weight']:
                model = model.with_estimated_weight()
            installation = parse_installation(p['installation'])
            calibration = load_calibration(p['calibration_file'])
            sigma, self._sigma_source = calibration_sigma(calibration, installation)
            settings = HoldSettings(
                float(p['attitude_tolerance_rad']),
                float(p['q_tolerance_pa']),
                float(p['q_tolerance_fraction']),
                float(p['wind_off_q_pa']),
                int(p['settle_samples']),
                int(p['point_samples']),
                int(p['min_samples']),
            )
            self.core = LiveReduction(
                model, settings, sigma, float(p['max_input_age_s']), float(p['match_wait_s'])
            )
        except (ConfigError, ValueError) as err:
            raise StartupError(f'aero_coefficients: {err}') from None
        self._max_age_s = float(p['max_input_age_s'])
        self._take_samples, self._take_timeout_s = (
            int(p['take_point_samples']),
            float(p['take_point_timeout_s']),
        )
        self._request = None  # (core request, Future, deadline)
        out = {
            name: self.create_publisher(WrenchStamped, f'aero/{name}', STREAM_QOS)
            for name in (
                'coefficients',
                'wind_coefficients',
                'point',
                'point_wind',
                'point_scatter',
                'point_uncertainty',
            )
        }
        self._out = out
        self._point_attitude = self.create_publisher(
            Vector3Stamped, 'aero/point_attitude', STREAM_QOS
        )
        self._diagnostics = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_subscription(WrenchStamped, 'balance/wrench', self._on_wrench, STREAM_QOS)
        self.create_subscription(Vector3Stamped, 'model/attitude', self._on_attitude, STREAM_QOS)
        self.create_subscription(FluidPressure, 'tunnel/dynamic_pressure', self._on_q, STREAM_QOS)
        self.create_timer(0.1, self._on_flush)
        self.create_timer(float(p['diagnostics_period_s']), self._on_diagnostics)
        # a coroutine in its own group, so the sample callbacks keep running while it awaits its
        # point
        self.create_service(
            Trigger, '~/take_point', self._on_take_point, callback_group=ReentrantCallbackGroup()
        )
        self.get_logger().info(
            f'{model.name}: S = {model.reference_area_m2} m², weight '
            f'{"estimated from the wind-off sweep" if model.weight_n is None else model.weight_n}'
        )

    # --- inputs -> core -> outputs --------------------------------------------------------------
    def _on_wrench(self, msg: WrenchStamped):
        w = msg.wrench
        self._publish(
            *self.core.add_wrench(
                _ns(msg.header.stamp),
                (w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z),
                self.get_clock().now().nanoseconds,
            )
        )

    def _on_attitude(self, msg: Vector3Stamped):
        self._publish(
            *self.core.add_attitude(
                _ns(msg.header.stamp), (msg.vector.x, msg.vector.y, msg.vector.z)
            )
        )

    def _on_q(self, msg: FluidPressure):
        self._publish(*self.core.add_dynamic_pressure(_ns(msg.header.stamp), msg.fluid_pressure))

    def _on_flush(self):
        stale_before = self.core.counters.stale
        self._publish(*self.core.flush(self.get_clock().now().nanoseconds))
        if self.core.counters.stale > stale_before:
            self.get_logger().warn(
                f'{self.core.counters.stale - stale_before} wrench sample(s) dropped: '
                f'{self.core.counters.last_stale_reason}',
                throttle_duration_sec=5.0,
            )

    async def _on_take_point(self, request, response):
        if self._request is not None:
            response.success, response.message = False, 'a point is being taken already'
            return response
        future = Future(executor=self.executor)  # its completion wakes the executor to resume us
        future.add_done_callback(lambda _: None)
        deadline = self.get_clock().now().nanoseconds + int(self._take_timeout_s * 1e9)
        self._request = (self.core.request_point(self._take_samples), future, deadline)
        success, message = await future
        response.success, response.message = success, message
        return response

    def _check_request(self):
        if self._request is None:
            return
        core_request, future, deadline = self._request
        if not core_request.done and self.get_clock().now().nanoseconds > deadline:
            core_request.finish(
                False,
                f'timed out after {self._take_timeout_s:g} s with '
                f'{len(core_request.rows)} of {core_request.samples} samples',
            )
        if not core_request.done:
            return
        self._request = None
        point = core_request.point
        if core_request.success:
            from balance_calib.aero.live import LivePoint

            self._publish([], [LivePoint(core_request.stamp_ns, point)])
            body = ', '.join(
                f'{name} {value:+.5f} ± {scatter:.5f}'
                for name, value, scatter in zip(
                    ('C_AF', 'C_Y', 'C_N', 'C_l', 'C_m', 'C_n'),
                    point.reduced.body,
                    point.scatter_body,
                )
            )
            message = (
                f'{point.samples} samples at α = {float(point.reduced.alpha_deg):.3f}°, '
                f'q∞ = {point.q_pa:.0f} Pa: {body} (± sample scatter)'
            )
        else:
            message = core_request.message
        future.set_result((core_request.success, message))

    def _publish(self, samples, points):
        self._check_request()
        for sample in samples:
            self._out['coefficients'].publish(
                _wrench(sample.stamp_ns, 'body', sample.reduced.body)
            )
            self._out['wind_coefficients'].publish(
                _wrench(sample.stamp_ns, 'wind', sample.reduced.wind)
            )
        for live_point in points:
            point, stamp = live_point.point, live_point.stamp_ns
            if point.wind_off or point.reduced is None:
                continue
            self._out['point'].publish(_wrench(stamp, 'body', point.reduced.body))
            self._out['point_wind'].publish(_wrench(stamp, 'wind', point.reduced.wind))
            self._out['point_scatter'].publish(_wrench(stamp, 'body', point.scatter_body))
            self._out['point_uncertainty'].publish(_wrench(stamp, 'body', point.uncertainty_body))
            attitude = Vector3Stamped()
            attitude.header.stamp = Time(nanoseconds=stamp).to_msg()
            attitude.header.frame_id = 'tunnel'
            attitude.vector.x, attitude.vector.y, attitude.vector.z = (
                float(v) for v in point.reduced.attitude
            )
            self._point_attitude.publish(attitude)

    def _on_diagnostics(self):
        c, tare = self.core.counters, self.core.tracker.tare
        level = DiagnosticStatus.OK
        message = 'reducing'
        if tare is None:
            level, message = (
                DiagnosticStatus.WARN,
                'no weight tare yet: waiting for a wind-off sweep',
            )
        if c.stale:
            level, message = (
                DiagnosticStatus.WARN,
                f'{c.stale} stale sample(s): {c.last_stale_reason}',
            )
        values = {
            'samples': c.samples,
            'stale_samples': c.stale,
            'wind_off_samples': c.wind_off,
            'wind_on_samples_without_tare': c.not_reduced,
            'points': c.points,
            'tare_fits': self.core.tracker.fits,
            'load_sigma_source': self._sigma_source,
        }
        if tare is not None:
            values.update(
                {
                    'weight_n': f'{tare.weight_n:.4f}',
                    'weight_sigma_n': f'{tare.weight_sigma_n:.4f}',
                    'cg_m': ' '.join(f'{v:.5f}' for v in tare.cg_m),
                    'tare_source': tare.source,
                }
            )
        if self.core.tracker.warnings:
            values['last_warning'] = self.core.tracker.warnings[-1]
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        array.status.append(
            DiagnosticStatus(
                level=level,
                name='aero_coefficients: coefficients',
                message=message,
                hardware_id=self.core.model.name,
                values=[KeyValue(key=k, value=str(v)) for k, v in values.items()],
            )
        )
        self._diagnostics.publish(array)


def main(args=None):
    from ._help import exit_if_help

    exit_if_help(__name__, args)  # --help: print the parameters and exit before rclpy starts
    return run_node('aero_coefficients', AeroCoefficients, refused=(StartupError,), args=args)


if __name__ == '__main__':
    sys.exit(main())
