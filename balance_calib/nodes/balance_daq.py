"""balance_daq: a data acquisition device (serial port, TCP or UDP) on /balance/raw.

Reads what a balance's data acquisition sends (text lines or binary records; mV, V, mV/V, uV/V
or counts) and publishes each whole, finite, unflagged, unsaturated sample on /balance/raw
(geometry_msgs/WrenchStamped, mV: force = F_XV F_YV F_ZV, torque = M_XV M_YV M_ZV), its
temperature on /balance/temperature when the device sends one, and at 1 Hz one /diagnostics
status named "balance_daq: " + device (rate_hz, samples_published, records_malformed,
samples_invalid, samples_saturated, samples_missing, samples_duplicate, reconnects,
last_sample_age_s, connected). It never exits because of the device: it reconnects every
reconnect_period_s. Contract: docs/interfaces.md, "Acquisition"; presets: config/daq/*.yaml
(--ros-args --params-file config/daq/netft_rdt.yaml); guide: docs/guide/acquisition.md.

The device is read on a thread of its own (daq/reader.py), which publishes the samples it decodes
as they come, serialized once by the package's WrenchStamped encoder (live/raw_codec.py).
"""

from __future__ import annotations

import sys
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from rclpy.time import Time
from sensor_msgs.msg import Temperature

from balance_calib.daq.health import Health
from balance_calib.daq.parameters import daq_settings, PARAMETERS
from balance_calib.daq.reader import DeviceReader
from balance_calib.daq.samples import Samples
from balance_calib.live.raw_codec import WrenchEncoder
from balance_calib.parameter_table import ParameterError

from ._messages import diagnostic_array
from ._parameters import declare_table
from ._qos import STREAM_QOS
from ._run import run_node

DIAGNOSTICS_PERIOD_S = 1.0


class BalanceDaq(Node):
    def __init__(self, **kwargs):
        super().__init__('balance_daq', **kwargs)
        self.settings = daq_settings(declare_table(self, PARAMETERS))  # ParameterError: refused
        self._encoder = WrenchEncoder(self.settings.frame_id)
        self._raw = self.create_publisher(WrenchStamped, '/balance/raw', STREAM_QOS)
        self._temperature = self.create_publisher(Temperature, '/balance/temperature', STREAM_QOS)
        self._diagnostics = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._health = Health(
            self.settings.device,
            self.settings.expected_rate_hz,
            self.settings.stale_after_s,
            time.monotonic(),
        )
        self._reader = DeviceReader(
            self.settings, self._publish, self._log, lambda: self.get_clock().now().nanoseconds
        )
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._on_diagnostics)
        self._reader.start()

    def _log(self, level: str, line: str) -> None:
        logger = self.get_logger()  # rclpy wants one severity per call site
        if level == 'info':
            logger.info(line)
        elif level == 'warning':
            logger.warning(line)
        else:
            logger.error(line)

    def _publish(self, samples: Samples) -> None:
        """In the device's thread: the samples of one chunk."""
        if not self.context.ok():  # Ctrl-C: rclpy shut down before destroy_node stops the thread
            return
        publish = self._raw.publish
        for data in self._encoder.encode(samples.stamps_ns, samples.bridges_mv):
            publish(data)
        if samples.temperature_c is not None:
            for stamp_ns, celsius in zip(
                samples.stamps_ns.tolist(), samples.temperature_c.tolist()
            ):
                msg = Temperature(temperature=celsius, variance=0.0)
                msg.header.stamp = Time(nanoseconds=stamp_ns).to_msg()
                msg.header.frame_id = self.settings.frame_id
                self._temperature.publish(msg)

    def _on_diagnostics(self) -> None:
        counts, connected, last_sample_s = self._reader.snapshot()
        status = self._health.status(counts, connected, time.monotonic(), last_sample_s)
        self._diagnostics.publish(diagnostic_array(self.get_clock().now().to_msg(), [status]))

    def destroy_node(self):
        self._reader.close()  # stop_request sent, link closed (the thread ends before the node)
        return super().destroy_node()


def main(args=None):
    from ._help import exit_if_help

    exit_if_help(__name__, args)  # --help: print the parameters and exit before rclpy starts
    # a ParameterError is one line naming the parameter, as every node says it
    return run_node('balance_daq', BalanceDaq, refused=(ParameterError,), args=args)


if __name__ == '__main__':
    sys.exit(main())
