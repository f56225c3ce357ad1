"""thrust_analyzer: measured against theoretical thrust coefficient of the lab manual's thrust
stand.

Subscribes (best effort, so any publisher's QoS matches):
  /balance/wrench                 geometry_msgs/WrenchStamped   thrust F_t = wrench.force.x, N
  /thrust_stand/chamber_pressure  sensor_msgs/FluidPressure     chamber *gauge* pressure p_G, Pa
  /thrust_stand/ambient_pressure  sensor_msgs/FluidPressure     ambient pressure p_a, Pa
Each signal is averaged over the last `window_s` seconds (by arrival time on the node's clock);
a FluidPressure `variance` > 0 is taken as the sensor's own (non-averaging) uncertainty.

Publishes every `publish_period_s` on /diagnostics a DiagnosticArray with one DiagnosticStatus,
name "thrust_analyzer: thrust coefficient", hardware_id "thrust_stand". Level OK while firing
shock-free or idle, WARN when a normal shock stands in the nozzle (eq. (12) overestimates),
STALE while an input is missing or older than `stale_after_s`. Its key/values (numbers as text,
"nan" where undefined):
  cf_measured             C_F = F_t / (p_c A_t), p_c = p_G + p_a (manual §4.1)
  cf_measured_sigma       its standard uncertainty, root-sum-square eq. (20)
  cf_measured_worst_case  the absolute-sum bound, eq. (19)
  cf_dominant_input       the input with the largest contribution, eq. (21)
  cf_measured_formatted   "C_F = 0.97 ± 0.02" (§A1.3)
  cf_theory               ideal C_F at the measured p_c, p_a, eq. (12)
  cf_ratio                cf_measured / cf_theory
  thrust_measured_n, thrust_measured_sigma_n, thrust_theory_n   (eq. (5)), N
  chamber_pressure_pa     p_c (absolute), chamber_gauge_pressure_pa p_G, ambient_pressure_pa p_a
  pe_over_pc              exit to chamber pressure ratio, eq. (4) supersonic root
  exit_pressure_pa, area_ratio, expansion (optimum / over-expanded / under-expanded),
  flow_regime (shock-free / shock in nozzle / not choked), firing (true/false)
  samples_thrust, samples_chamber, samples_ambient, rejected_samples, window_s

The nozzle, the windows and the report (std_srvs/Trigger service ~/report, and on shutdown) are
set by the parameters of thrust_stand/analyzer_parameters.py's table.
"""

from __future__ import annotations

from collections import deque
import math
import sys

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
import numpy as np
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import FluidPressure
from std_srvs.srv import Trigger

from balance_calib.thrust_stand.analysis import compare_with_theory, ThrustComparison, window_mean
from balance_calib.thrust_stand.analyzer_parameters import PARAMETERS
from balance_calib.thrust_stand.nozzle import Nozzle
from balance_calib.thrust_stand.report import write_report

from ._parameters import declare_table
from ._run import run_node

STATUS_NAME = 'thrust_analyzer: thrust coefficient'
HARDWARE_ID = 'thrust_stand'
INPUT_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=200, reliability=ReliabilityPolicy.BEST_EFFORT
)
MAX_WINDOW_SAMPLES = 200_000  # bounds memory whatever the input rate


def _text(value) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, (float, np.floating)):
        return 'nan' if not math.isfinite(value) else f'{float(value):.9g}'
    return str(value)


class SignalWindow:
    """Samples of one signal (value, instrument variance) stamped with arrival time, ns."""

    def __init__(self):
        self._samples = deque(maxlen=MAX_WINDOW_SAMPLES)

    def add(self, time_ns: int, value: float, variance: float = 0.0) -> None:
        self._samples.append((time_ns, value, variance))

    def newest_ns(self) -> int | None:
        return self._samples[-1][0] if self._samples else None

    def window(self, since_ns: int) -> tuple[np.ndarray, np.ndarray]:
        while self._samples and self._samples[0][0] < since_ns:
            self._samples.popleft()
        if not self._samples:
            return np.zeros(0), np.zeros(0)
        data = np.array([(value, variance) for _, value, variance in self._samples])
        return data[:, 0], data[:, 1]


class ThrustAnalyzer(Node):
    def __init__(self):
        super().__init__('thrust_analyzer')
        p = declare_table(self, PARAMETERS)  # read once, here (read-only)
        self._nozzle = Nozzle(
            throat_diameter_m=p['throat_diameter_m'],
            exit_diameter_m=p['exit_diameter_m'],
            gamma=p['gamma'],
            gas_constant_j_kg_k=p['gas_constant'],
        )
        self._chamber_k = p['chamber_k']
        self._window_s = p['window_s']
        publish_period_s = p['publish_period_s']
        self._stale_after_s = p['stale_after_s']
        self._thrust_relative_sigma = p['thrust_relative_sigma']
        self._throat_sigma_m = p['throat_diameter_sigma_m']
        self._report_path = p['report_path']

        self._signals = {
            'thrust': SignalWindow(),
            'chamber': SignalWindow(),
            'ambient': SignalWindow(),
        }
        self._topics = {
            'thrust': '/balance/wrench',
            'chamber': '/thrust_stand/chamber_pressure',
            'ambient': '/thrust_stand/ambient_pressure',
        }
        self._rejected = 0
        self._latest: ThrustComparison | None = None
        self._last_firing: ThrustComparison | None = None
        self.create_subscription(WrenchStamped, self._topics['thrust'], self._on_wrench, INPUT_QOS)
        self.create_subscription(
            FluidPressure, self._topics['chamber'], self._pressure_callback('chamber'), INPUT_QOS
        )
        self.create_subscription(
            FluidPressure, self._topics['ambient'], self._pressure_callback('ambient'), INPUT_QOS
        )
        self._diagnostics = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_service(Trigger, '~/report', self._on_report)
        self.create_timer(publish_period_s, self._publish)

    # --- inputs ---------------------------------------------------------------------------------
    def _now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def _on_wrench(self, msg: WrenchStamped):
        self._add('thrust', msg.wrench.force.x, 0.0)

    def _pressure_callback(self, signal: str):
        def callback(msg: FluidPressure):
            self._add(signal, msg.fluid_pressure, msg.variance)

        return callback

    def _add(self, signal: str, value: float, variance: float):
        if not math.isfinite(value):
            self._rejected += 1
            return
        self._signals[signal].add(
            self._now_ns(), float(value), float(variance) if math.isfinite(variance) else 0.0
        )

    # --- analysis -------------------------------------------------------------------------------
    def _publish(self):
        now_ns = self._now_ns()
        status = DiagnosticStatus(name=STATUS_NAME, hardware_id=HARDWARE_ID)
        missing = [
            self._topics[name]
            for name, window in self._signals.items()
            if window.newest_ns() is None
            or now_ns - window.newest_ns() > self._stale_after_s * 1e9
        ]
        if missing:
            status.level = DiagnosticStatus.STALE
            status.message = f'no recent data on {", ".join(missing)}'
            status.values = [KeyValue(key='rejected_samples', value=str(self._rejected))]
        else:
            since_ns = now_ns - int(self._window_s * 1e9)
            thrust, _ = self._signals['thrust'].window(since_ns)
            chamber, chamber_var = self._signals['chamber'].window(since_ns)
            ambient, ambient_var = self._signals['ambient'].window(since_ns)
            try:
                comparison = compare_with_theory(
                    window_mean(thrust),
                    window_mean(chamber, chamber_var),
                    window_mean(ambient, ambient_var),
                    self._nozzle,
                    thrust_relative_sigma=self._thrust_relative_sigma,
                    throat_diameter_sigma_m=self._throat_sigma_m,
                    chamber_k=self._chamber_k,
                )
            except ValueError as error:
                status.level = DiagnosticStatus.ERROR
                status.message = f'cannot analyse the window: {error}'
            else:
                self._latest = comparison
                if comparison.firing:
                    self._last_firing = comparison
                self._fill_status(status, comparison)
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._diagnostics.publish(array)

    def _fill_status(self, status: DiagnosticStatus, c: ThrustComparison):
        theory = c.theory
        nan = float('nan')
        values = {
            'cf_measured': c.cf_measured.value,
            'cf_measured_sigma': c.cf_measured.sigma,
            'cf_measured_worst_case': c.cf_measured.worst_case,
            'cf_dominant_input': c.cf_measured.dominant_input,
            'cf_measured_formatted': c.cf_formatted,
            'cf_theory': theory.cf if theory else nan,
            'cf_ratio': c.cf_ratio,
            'thrust_measured_n': c.thrust_n.mean,
            'thrust_measured_sigma_n': c.thrust_n.sigma,
            'thrust_theory_n': theory.thrust_n if theory else nan,
            'chamber_pressure_pa': c.chamber_pa,
            'chamber_gauge_pressure_pa': c.chamber_gauge_pa.mean,
            'ambient_pressure_pa': c.ambient_pa.mean,
            'pe_over_pc': theory.pe_over_pc if theory else nan,
            'exit_pressure_pa': theory.exit_pa if theory else nan,
            'area_ratio': self._nozzle.area_ratio,
            'expansion': theory.expansion if theory else 'no flow',
            'flow_regime': theory.flow_regime if theory else 'no flow',
            'firing': c.firing,
            'samples_thrust': c.thrust_n.samples,
            'samples_chamber': c.chamber_gauge_pa.samples,
            'samples_ambient': c.ambient_pa.samples,
            'rejected_samples': self._rejected,
            'window_s': self._window_s,
        }
        status.values = [KeyValue(key=key, value=_text(value)) for key, value in values.items()]
        if not c.firing:
            status.level = DiagnosticStatus.OK
            status.message = (
                f'not firing (p_G = {c.chamber_gauge_pa.mean:.4g} Pa, throat not choked)'
            )
        elif theory.flow_regime == 'shock in nozzle':
            status.level = DiagnosticStatus.WARN
            status.message = (
                f'{c.cf_formatted}; normal shock inside the nozzle at p_a/p_c = '
                f'{c.ambient_pa.mean / c.chamber_pa:.3f}: the ideal C_F {theory.cf:.4f} does '
                'not apply'
            )
        else:
            status.level = DiagnosticStatus.OK
            status.message = (
                f'{c.cf_formatted} measured, {theory.cf:.4f} ideal (ratio {c.cf_ratio:.3f})'
            )

    # --- report ---------------------------------------------------------------------------------
    def write_report(self) -> str:
        """Write the report; returns what was done (raises ValueError if nothing can be
        written).
        """
        if not self._report_path:
            raise ValueError('parameter report_path is empty: no report requested')
        comparison = self._last_firing or self._latest
        if comparison is None:
            raise ValueError('no complete window of thrust, chamber and ambient pressure yet')
        json_path, markdown_path = write_report(
            self._report_path,
            comparison,
            {'window_s': self._window_s, 'rejected_samples': self._rejected},
        )
        return f'wrote {json_path} and {markdown_path}'

    def _on_report(self, request, response):
        try:
            response.message = self.write_report()
            response.success = True
        except (ValueError, OSError) as error:
            response.success, response.message = False, str(error)
        return response

    def destroy_node(self):
        outcome = None
        if self._report_path:
            try:
                outcome = (True, self.write_report())
            except (ValueError, OSError) as error:
                outcome = (False, f'no report written: {error}')
        logger = self.get_logger()
        super().destroy_node()
        # logged once the node is gone: after a signal the context can no longer reach /rosout
        if outcome:
            (logger.info if outcome[0] else logger.warn)(outcome[1])


def main(args=None):
    from ._help import exit_if_help

    exit_if_help(__name__, args)  # --help: print the parameters and exit before rclpy starts
    # SIGINT and SIGTERM both shut the context down; the report is written in destroy_node().
    # A ValueError at start-up is a bad parameter.
    return run_node(
        'thrust_analyzer',
        ThrustAnalyzer,
        refused=(ValueError,),
        args=args,
        signals=SignalHandlerOptions.ALL,
    )


if __name__ == '__main__':
    sys.exit(main())
