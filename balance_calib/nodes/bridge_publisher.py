"""bridge_publisher: a simulated balance (or a recorded bag) on /balance/raw, in real time.

Modes (parameter `mode`):
  calibration   plays the balance config's load schedule (Appendix A/B), or the one of parameter
                `schedule_file`, like a real campaign:
                /calibration/gravity when the body is rotated, /calibration/applied_load when a
                point settles (all NaN while weights are changed), /balance/raw (mV) and
                /balance/temperature (°C). Simulated by simulation.balance_sim.simulate_campaign.
  wind_on       an angle-of-attack sweep (simulation/wind_on.py) or a CSV of balance-axis loads;
                also /balance/truth: the true aerodynamic load in tunnel axes, N / N·m, stamped
                like the raw sample it belongs to (a test and diagnostic topic, not a public
                interface). With `aero_model` (a config/models file) the run is physical (TM-663
                §10.3): a wind-off α/φ sweep, the wind-on α sweep at `dynamic_pressure_pa`,
                wind-off again; the balance feels the air loads plus the model's weight at each
                attitude, at the attitude the sting's deflection gives; /model/attitude (support
                angles) and /tunnel/dynamic_pressure with every raw sample, and the true
                coefficients on /aero/truth (body) and /aero/truth_wind (wind axes), also not
                public interfaces.
  replay        the messages of bag(s) as `ros2 bag play` sends them (header stamps as recorded).
  thrust_stand  the lab manual's thrust stand (simulation/thrust_stand.py): strain channel on
                /balance/raw force.x (mV), /thrust_stand/chamber_pressure (gauge) and
                /thrust_stand/ambient_pressure (sensor_msgs/FluidPressure, Pa), and the
                calibration weights on /calibration/applied_load (force.x, N).

The node precomputes a timeline of events (simulation/timeline.py) and a timer publishes the events
that are due; events of one sampling instant share the header stamp: the node clock when the
first of them is published. Parameters are read at start-up.
"""

from __future__ import annotations

import importlib
import sys
import time

from geometry_msgs.msg import Vector3Stamped, WrenchStamped
import numpy as np
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from rclpy.time import Time
from sensor_msgs.msg import FluidPressure, Temperature

from balance_calib.aero.model_file import load_model
from balance_calib.bags.errors import BagError
from balance_calib.config import ConfigError, load_balance_config
from balance_calib.gates.limits import acceptance_limits
from balance_calib.parameter_table import defaults
from balance_calib.schedule_file import schedule_for
from balance_calib.simulation import timeline as tl
from balance_calib.simulation.balance_sim import (
    noise_mv_for_load_sigma,
    paced_settings,
    simulate_campaign,
    table17_noise,
)
from balance_calib.simulation.effects import parse_effects
from balance_calib.simulation.publisher_parameters import PARAMETERS as TABLE
from balance_calib.simulation.replay import read_recorded_messages
from balance_calib.simulation.wind_on import (
    aero_run_profile,
    aoa_sweep_profile,
    BalanceEffects,
    csv_profile,
    TunnelRun,
    wind_on_outputs,
)
from balance_calib.tunnel_axes import parse_installation

from ._messages import set_wrench
from ._parameters import declare_table
from ._qos import STREAM_QOS
from ._run import run_node

# name -> default, as tests and tools read them; the table (type, range, description) is the
# pure simulation/publisher_parameters.py's
PARAMETERS = defaults(TABLE)
# timeline kinds of the physical wind-on run, after simulation/timeline.py's
ATTITUDE, DYNAMIC_PRESSURE, AERO_TRUTH, AERO_TRUTH_WIND = 7, 8, 9, 10
EVENT_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
TAIL_ACK_TIMEOUT_S = 10.0  # exit_when_done: how long the subscribers may take to acknowledge


class StartupError(ValueError):
    """A parameter or input that makes the requested mode impossible; the message says which."""


class BridgePublisher(Node):
    def __init__(self, node_name: str = 'bridge_publisher', **kwargs):
        super().__init__(node_name, **kwargs)
        try:  # every parameter read once, here (read-only); mode, rate_hz, speed... checked
            self._settings = declare_table(self, TABLE)
        except ValueError as err:
            raise StartupError(str(err)) from None
        self.mode = str(self._settings['mode'])
        self.done = Future()  # completes when the run is over and exit_when_done
        self._outputs = {}
        self._frame_id = ''
        self._recorded = None
        builder = {
            'calibration': self._calibration,
            'wind_on': self._wind_on,
            'replay': self._replay,
            'thrust_stand': self._thrust_stand,
        }[self.mode]
        try:
            self._build = builder()
            self._timeline = self._build(0)
        # Newton: loads out of range
        except (ConfigError, BagError, ValueError, KeyError, ArithmeticError) as err:
            raise StartupError(f'{self.mode} mode: {err}') from None
        self._cycle = 0
        self._cursor = 0
        self._start = None
        self._last_time_s = None
        self._stamp_ns = 0
        self._waiting_since = None
        self._ready_at = None
        self.failure = ''  # why the run gave up (then done completes too)
        tick_hz = min(max(float(self._settings['rate_hz']), 20.0), 250.0)
        self._timer = self.create_timer(1.0 / tick_hz, self._on_tick)
        self.get_logger().info(
            f'{self.mode}: {len(self._timeline)} events over '
            f'{self._timeline.duration_s / self._settings["speed"]:.1f} s'
        )

    # --- modes: each returns build(cycle) -> Timeline -----------------------------------------
    def _publisher(self, kind, msg_type, topic, qos=EVENT_QOS):
        self._outputs[kind] = self.create_publisher(msg_type, topic, qos)

    def _balance(self):
        config = load_balance_config(self._settings['balance'])
        truth_name = str(self._settings['truth_model'])
        if truth_name not in config.matrices:
            raise ConfigError(
                f'truth_model {truth_name!r}: {config.name} has {", ".join(config.matrices)}'
            )
        noise = self._settings['noise_sigma_pct_fs']
        noise = table17_noise(config) if noise < 0 else np.full(6, float(noise))
        self._frame_id = config.name
        self._publisher(tl.RAW, WrenchStamped, '/balance/raw', STREAM_QOS)
        self._publisher(tl.TEMPERATURE, Temperature, '/balance/temperature', STREAM_QOS)
        return config, config.matrices[truth_name], noise

    def _temperature_every(self) -> int:
        return max(
            1, round(self._settings['rate_hz'] / max(self._settings['temperature_rate_hz'], 1e-9))
        )

    def _calibration(self):
        config, truth, noise = self._balance()
        schedule_file = str(self._settings['schedule_file'])
        schedule = config.schedule
        if schedule_file:  # within capacity as the refit's capacity gate will judge it
            schedule = schedule_for(
                config, schedule_file, acceptance_limits(config).capacity_margin
            )
        schedule = tl.select_points(schedule, self._settings['points'])
        effects = parse_effects(self._settings['effects'])
        rate, duration, transition = (
            float(self._settings['rate_hz']),
            float(self._settings['point_duration_s']),
            float(self._settings['transition_s']),
        )
        self._publisher(tl.GRAVITY, Vector3Stamped, '/calibration/gravity')
        self._publisher(tl.APPLIED_LOAD, WrenchStamped, '/calibration/applied_load')

        def build(cycle):
            settings = paced_settings(
                rate,
                duration,
                transition,
                noise,
                int(self._settings['seed']) + cycle,
                float(self._settings['physical_seconds_per_point']),
            )
            campaign = simulate_campaign(
                config, truth, schedule=schedule, settings=settings, effects=effects
            )
            return tl.campaign_timeline(campaign, transition, self._temperature_every())

        return build

    def _wind_on(self):
        config, truth, noise = self._balance()
        installation = parse_installation(self._settings['installation'])
        rate = float(self._settings['rate_hz'])
        if self._settings['aero_model']:
            return self._aero_run(config, truth, noise, installation, rate)
        if self._settings['profile_csv']:
            profile = csv_profile(self._settings['profile_csv'], installation, rate)
            samples_per_condition = 1
        else:
            step = float(self._settings['alpha_step_deg'])
            alphas = np.arange(
                self._settings['alpha_start_deg'], self._settings['alpha_end_deg'] + step / 2, step
            )
            profile = aoa_sweep_profile(
                config.capacity,
                installation,
                rate,
                alphas_deg=alphas,
                hold_s=self._settings['hold_s'],
                wind_off_s=self._settings['wind_off_s'],
                model_weight_n=self._settings['model_weight_n'],
            )
            samples_per_condition = max(1, round(self._settings['hold_s'] * rate))
        # noise_sigma_pct_fs is the σ of a held point's mean, as in calibration mode
        noise_mv = noise_mv_for_load_sigma(
            truth.without_constant(), config.capacity, noise
        ) * np.sqrt(samples_per_condition)
        # the balance's own effects, wind-on too
        effects = self._balance_effects(profile.times_s, config)
        self._publisher(tl.TRUTH, WrenchStamped, '/balance/truth', STREAM_QOS)

        def build(cycle):
            raw = self._wind_on_raw(truth, profile.loads_balance, noise_mv, effects, cycle)
            return tl.wind_on_timeline(
                profile.times_s,
                raw,
                profile.aero_tunnel,
                float(self._settings['temperature_c']),
                self._temperature_every(),
            )

        return build

    def _balance_effects(self, times_s, config) -> BalanceEffects:
        """The `effects` parameter's effects of the balance at the `temperature_c` parameter."""
        return BalanceEffects(
            parse_effects(self._settings['effects']),
            times_s,
            float(self._settings['temperature_c']),
            config.rated_output_mv,
        )

    def _wind_on_raw(self, truth, loads_balance, noise_mv, effects, cycle: int) -> np.ndarray:
        """Raw outputs (S, 6) mV of the cycle-th pass of a wind-on run, electrical zero in."""
        return wind_on_outputs(
            truth,
            loads_balance,
            electrical_zero_mv=float(self._settings['electrical_zero_mv']),
            noise_mv=noise_mv,
            seed=int(self._settings['seed']) + cycle,
            balance_effects=effects,
        )

    def _aero_run(self, config, truth, noise, installation, rate):
        model = load_model(self._settings['aero_model'])
        weight = float(self._settings['model_weight_n'])
        if weight > 0:
            cg = np.asarray(self._settings['model_cg_m'], dtype=float)
            if cg.shape != (3,):
                raise ValueError(
                    f'model_cg_m must be three numbers [x, y, z] in m, not {list(cg)}'
                )
        elif model.weight_declared:
            weight, cg = model.weight_n, model.centre_of_gravity_m
        else:
            raise ValueError(
                f'{model.path}: the model file says estimate; give the simulated model its true '
                f'weight and CG with model_weight_n and model_cg_m'
            )
        step = float(self._settings['alpha_step_deg'])
        alphas = np.arange(
            self._settings['alpha_start_deg'], self._settings['alpha_end_deg'] + step / 2, step
        )
        wind_off = [
            (r, a)
            for r in self._settings['wind_off_rolls_deg']
            for a in self._settings['wind_off_alphas_deg']
        ]
        run = TunnelRun(
            q_pa=float(self._settings['dynamic_pressure_pa']),
            rate_hz=rate,
            alphas_deg=alphas,
            hold_s=float(self._settings['hold_s']),
            wind_off_attitudes_deg=wind_off,
            wind_off_hold_s=float(self._settings['wind_off_hold_s']),
        )
        profile = aero_run_profile(model, installation, run, weight_n=weight, cg_m=cg)
        samples_per_hold = max(1, round(float(self._settings['hold_s']) * rate))
        noise_mv = noise_mv_for_load_sigma(
            truth.without_constant(), config.capacity, noise
        ) * np.sqrt(samples_per_hold)
        effects = self._balance_effects(profile.times_s, config)
        self._publisher(tl.TRUTH, WrenchStamped, '/balance/truth', STREAM_QOS)
        self._publisher(ATTITUDE, Vector3Stamped, '/model/attitude', STREAM_QOS)
        self._publisher(DYNAMIC_PRESSURE, FluidPressure, '/tunnel/dynamic_pressure', STREAM_QOS)
        self._publisher(AERO_TRUTH, WrenchStamped, '/aero/truth', STREAM_QOS)
        self._publisher(AERO_TRUTH_WIND, WrenchStamped, '/aero/truth_wind', STREAM_QOS)
        wind_on = profile.q_pa > 0

        def build(cycle):
            raw = self._wind_on_raw(truth, profile.loads_balance, noise_mv, effects, cycle)
            times = profile.times_s
            return tl.merge(
                tl.wind_on_timeline(
                    times,
                    raw,
                    profile.aero_tunnel,
                    float(self._settings['temperature_c']),
                    self._temperature_every(),
                ),
                tl.events(times, ATTITUDE, profile.support_attitude),
                tl.events(times, DYNAMIC_PRESSURE, profile.q_pa),
                tl.events(times[wind_on], AERO_TRUTH, profile.body_coefficients[wind_on]),
                tl.events(times[wind_on], AERO_TRUTH_WIND, profile.wind_coefficients[wind_on]),
            )

        return build

    def _replay(self):
        paths = [p.strip() for p in str(self._settings['bag']).split(',') if p.strip()]
        if not paths:
            raise ValueError(
                'parameter bag is empty: give the bag directory or .mcap file to replay'
            )
        recorded = read_recorded_messages(paths)
        for index, topic in enumerate(sorted(recorded.msgtypes)):
            package, _, name = recorded.msgtypes[topic].partition('/msg/')
            try:
                msg_type = getattr(importlib.import_module(f'{package}.msg'), name)
            except (ImportError, AttributeError):
                self.get_logger().warn(
                    f'replay: skipping {topic}: message type {recorded.msgtypes[topic]} '
                    f'is not available here'
                )
                continue
            self._outputs[topic] = self.create_publisher(msg_type, topic, STREAM_QOS)
        self._recorded = recorded
        replay_timeline = tl.Timeline(
            recorded.times_s, np.full(len(recorded), -1), np.zeros((len(recorded), 6))
        )
        return lambda cycle: replay_timeline

    def _thrust_stand(self):
        try:
            module = importlib.import_module('balance_calib.simulation.thrust_stand')
            simulator = module.ThrustStandSimulator(seed=int(self._settings['seed']))
        except (ImportError, AttributeError) as err:
            raise StartupError(
                f'thrust_stand mode is not available: balance_calib.simulation.thrust_stand.'
                f'ThrustStandSimulator cannot be loaded ({err})'
            ) from None
        self._frame_id = 'thrust_stand'
        self._publisher(tl.RAW, WrenchStamped, '/balance/raw', STREAM_QOS)
        self._publisher(
            tl.CHAMBER_PRESSURE, FluidPressure, '/thrust_stand/chamber_pressure', STREAM_QOS
        )
        self._publisher(
            tl.AMBIENT_PRESSURE, FluidPressure, '/thrust_stand/ambient_pressure', STREAM_QOS
        )
        self._publisher(tl.APPLIED_LOAD, WrenchStamped, '/calibration/applied_load')
        rate, duration = float(self._settings['rate_hz']), float(simulator.duration_s)
        times = (np.arange(int(duration * rate)) + 0.5) / rate
        applied = np.array(simulator.applied_load_events(), dtype=float).reshape(-1, 2)

        def build(cycle):
            sample = simulator.sample(times + cycle * duration)
            loads = np.zeros((len(applied), 6))
            loads[:, 0] = applied[:, 1]
            loads[np.isnan(applied[:, 1])] = np.nan
            return tl.merge(
                tl.thrust_stand_timeline(
                    times, sample.strain_mv, sample.chamber_gauge_pa, sample.ambient_pa
                ),
                tl.events(applied[:, 0], tl.APPLIED_LOAD, loads),
            )

        return build

    # --- playing ------------------------------------------------------------------------------
    def _on_tick(self):
        now = self.get_clock().now()
        if self._start is None:
            wanted = int(self._settings['wait_for_subscribers'])
            raw = self._outputs.get(tl.RAW) or self._outputs.get('/balance/raw')
            # the physical wind-on run's attitude and q∞ are as necessary as the raw samples
            gated = [raw] + [
                self._outputs[k] for k in (ATTITUDE, DYNAMIC_PRESSURE) if k in self._outputs
            ]
            # a campaign's gravity and applied-load events are published once each: a recorder
            # whose subscriptions to them match after /balance/raw's would lose the first
            # orientation
            events = [
                self._outputs[k]
                for k in (tl.GRAVITY, tl.APPLIED_LOAD)
                if k in self._outputs and self.mode == 'calibration'
            ]
            if (
                wanted > 0
                and raw is not None
                and (
                    min(p.get_subscription_count() for p in gated) < wanted
                    or any(p.get_subscription_count() < 1 for p in events)
                )
            ):
                what = f'{wanted} subscriber(s) on /balance/raw' + (
                    ' and the attitude and dynamic pressure' if len(gated) > 1 else ''
                )
                if self._waiting_since is None:
                    self.get_logger().info(f'waiting for {what}')
                    self._waiting_since = now
                self._give_up_if_waited_too_long(now, what, gated, events)
                return
            self._ready_at = self._ready_at or now
            if (now - self._ready_at).nanoseconds * 1e-9 < float(self._settings['start_delay_s']):
                return
            self._start = now
        sim_time_s = (now - self._start).nanoseconds * 1e-9 * float(self._settings['speed'])
        end = self._timeline.due(self._cursor, sim_time_s)
        for index in range(self._cursor, end):
            self._publish(index, now)
        self._cursor = end
        if self._cursor >= len(self._timeline):
            self._finish(now)

    def _give_up_if_waited_too_long(self, now: Time, what: str, gated, events) -> None:
        limit = float(self._settings['wait_for_subscribers_timeout_s'])
        waited = (now - self._waiting_since).nanoseconds * 1e-9
        if limit <= 0 or waited < limit:
            return
        seen = ', '.join(f'{p.topic_name} {p.get_subscription_count()}' for p in gated + events)
        self.failure = (
            f'gave up after {limit:g} s waiting for {what} '
            f'(subscribers seen: {seen}); start the subscribers first, or set '
            'wait_for_subscribers or wait_for_subscribers_timeout_s'
        )
        self._timer.cancel()
        if not self.done.done():
            self.done.set_result(False)

    def _stamp(self, time_s: float, now: Time):
        if time_s != self._last_time_s:  # a new sampling instant: a new, strictly later stamp
            self._stamp_ns = max(now.nanoseconds, self._stamp_ns + 1)
            self._last_time_s = time_s
        return Time(nanoseconds=self._stamp_ns).to_msg()

    def _publish(self, index: int, now: Time):
        kind = int(self._timeline.kinds[index])
        if self._recorded is not None:
            publisher = self._outputs.get(self._recorded.topics[index])
            if publisher is not None:
                publisher.publish(self._recorded.payloads[index])
            return
        values = self._timeline.values[index]
        stamp = self._stamp(float(self._timeline.times_s[index]), now)
        self._outputs[kind].publish(self._message(kind, values, stamp))

    def _message(self, kind: int, values, stamp):
        """The message of one timeline event (kind, its six values) with this header stamp."""
        if kind in (tl.RAW, tl.APPLIED_LOAD, tl.TRUTH, AERO_TRUTH, AERO_TRUTH_WIND):
            msg = WrenchStamped()
            msg.header.frame_id = {
                tl.RAW: self._frame_id,
                tl.APPLIED_LOAD: 'balance',
                AERO_TRUTH: 'body',
                AERO_TRUTH_WIND: 'wind',
            }.get(kind, 'tunnel')
            set_wrench(msg.wrench, values)
        elif kind in (tl.GRAVITY, ATTITUDE):
            msg = Vector3Stamped()
            msg.header.frame_id = 'balance' if kind == tl.GRAVITY else 'tunnel'
            msg.vector.x, msg.vector.y, msg.vector.z = (float(v) for v in values[:3])
        elif kind == tl.TEMPERATURE:
            msg = Temperature(temperature=float(values[0]), variance=0.0)
            msg.header.frame_id = self._frame_id
        else:
            msg = FluidPressure(fluid_pressure=float(values[0]), variance=0.0)
            msg.header.frame_id = self._frame_id
        msg.header.stamp = stamp
        return msg

    def _finish(self, now: Time):
        self.get_logger().info(
            f'campaign complete ({self.mode}, cycle {self._cycle + 1}): '
            f'{len(self._timeline)} events in {(now - self._start).nanoseconds * 1e-9:.1f} s'
        )
        if self._settings['loop']:
            self._cycle += 1
            self._timeline = self._build(self._cycle)
            self._cursor, self._start, self._last_time_s = 0, now, None
            return
        self._timer.cancel()
        if self._settings['exit_when_done']:
            # let reliable subscribers acknowledge the tail before the process goes away (acks come
            # with the writer's next heartbeat, so this can take a couple of seconds; a
            # subscriber that stalled needs its repairs first): what a writer takes with it is
            # lost to its late readers, so a tail left unacknowledged is said
            deadline = time.monotonic() + TAIL_ACK_TIMEOUT_S
            unacked = [
                publisher.topic_name
                for publisher in self._outputs.values()
                if publisher.get_subscription_count() > 0
                and not publisher.wait_for_all_acked(
                    Duration(seconds=max(deadline - time.monotonic(), 0.0))
                )
            ]
            if unacked:
                self.get_logger().warn(
                    f'leaving with samples not acknowledged after {TAIL_ACK_TIMEOUT_S:g} s on '
                    f'{", ".join(unacked)}: a subscriber that stalled may lack the end of the run'
                )
            self.done.set_result(True)


def main(args=None):
    from ._help import exit_if_help

    exit_if_help(__name__, args)  # --help: print the parameters and exit before rclpy starts
    return run_node(
        'bridge_publisher', BridgePublisher, refused=(StartupError,), args=args, until_done=True
    )


if __name__ == '__main__':
    sys.exit(main())
