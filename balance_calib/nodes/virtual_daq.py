"""The ROS side of `balance-calib virtual-daq`: bridge_publisher's run, its raw samples sent
through a virtual device (simulation/virtual_device.py) instead of /balance/raw.

The node is a BridgePublisher named `virtual_daq`: the same parameters, timeline, truth, noise,
effects and pacing. Only two kinds of event leave it another way: a raw sample goes to the device
(balance_daq turns it back into /balance/raw), and a temperature goes into the device's
`temperature` column when its format has one (otherwise it stays on /balance/temperature, a
thermometer read apart). Everything else is published as bridge_publisher publishes it: in
calibration mode /calibration/applied_load and /calibration/gravity (the loading rig), in wind-on
mode /balance/truth and the physical run's topics. `wait_for_subscribers` counts the device's
clients (a TCP connection, a UDP peer that sent the start request; a pty always counts one).

One clock for the rig and the device. A campaign is cut into points by stamps: a point's samples
are the /balance/raw samples stamped from its applied_load on (interfaces.md). bridge_publisher
stamps both on its own clock; here balance_daq stamps the samples (on arrival, or device time
carried onto the host clock), a little later than this node sends them and by an amount this
node cannot know. So each rig message waits until the /balance/raw sample that came just before
it in the run has come back from balance_daq, and is stamped 1 ns after that sample: every
sample falls on the same side of every marker as in bridge_publisher's run, whatever the device's
latency or this node's timer jitter. The samples that come back are told apart by their values
(simulation/virtual_device.ReturnedSamples), so one lost on the way shifts nothing. A marker
still waiting after MARKER_WAIT_S (no balance_daq publishing) goes out stamped now, said once.
"""

from __future__ import annotations

from collections import deque

from geometry_msgs.msg import WrenchStamped
from rclpy.duration import Duration
from rclpy.time import Time

from balance_calib.simulation import timeline as tl
from balance_calib.simulation.virtual_device import ReturnedSamples, VirtualDevice

from ._qos import STREAM_QOS
from .bridge_publisher import BridgePublisher, EVENT_QOS, StartupError

MODES = ('calibration', 'wind_on')
MARKERS = (tl.GRAVITY, tl.APPLIED_LOAD)  # the loading rig's messages, cut against the samples
MARKER_WAIT_S = 5.0


class _DeviceOutput:
    """Stands where bridge_publisher keeps the /balance/raw publisher: the device's clients are
    its subscribers.
    """

    def __init__(self, device: VirtualDevice):
        self.device = device
        self.topic_name = f'the virtual device ({device.transport} {device.address})'
        self.returned = None  # calibration: the subscription the samples come back on

    def get_subscription_count(self) -> int:
        """The device's clients; in calibration mode none until this node hears /balance/raw
        (it stamps the rig's messages by the samples that come back).
        """
        if self.returned is not None and self.returned.get_publisher_count() < 1:
            return 0
        return self.device.clients()

    def wait_for_all_acked(self, timeout: Duration) -> bool:
        self.device.flush()
        return True


class VirtualDaq(BridgePublisher):
    def __init__(self, device: VirtualDevice, **kwargs):
        self._device = device
        self._device_output = _DeviceOutput(device)
        super().__init__('virtual_daq', **kwargs)
        if self.mode not in MODES:
            raise StartupError(f'mode {self.mode!r}: virtual-daq plays {" or ".join(MODES)}')
        self._speed = float(self._settings['speed'])
        self._start_temperature()
        self._written = 0  # raw samples handed to the device
        self._returned = ReturnedSamples(device.format)  # which came back, stamped how
        self._held: deque = deque()  # (samples before it, kind, values, held since ns)
        self._said_unmatched = False
        if self.mode == 'calibration':
            self._device_output.returned = self.create_subscription(
                WrenchStamped, '/balance/raw', self._on_raw, STREAM_QOS
            )

    def _in_device(self, kind: int) -> bool:
        return kind == tl.RAW or (kind == tl.TEMPERATURE and self._device.has_temperature)

    def _publisher(self, kind, msg_type, topic, qos=EVENT_QOS):
        if self._in_device(kind):
            self._outputs[kind] = self._device_output
        else:
            super()._publisher(kind, msg_type, topic, qos)

    def _start_temperature(self) -> None:
        """The device's temperature column before the first temperature event of a cycle."""
        first = self._timeline.kinds == tl.TEMPERATURE
        if first.any():
            self._device.temperature_c = float(self._timeline.values[first.argmax(), 0])

    def _publish(self, index: int, now: Time):
        kind = int(self._timeline.kinds[index])
        if kind == tl.RAW:
            time_s = float(self._timeline.times_s[index]) / self._speed  # device seconds
            self._device.add_sample(self._timeline.values[index], time_s)
            if self.mode == 'calibration':  # only the rig's markers need them back
                self._returned.written(self._timeline.values[index])
            self._written += 1
        elif kind == tl.TEMPERATURE and self._device.has_temperature:
            self._device.temperature_c = float(self._timeline.values[index, 0])
        elif kind in MARKERS and self.mode == 'calibration':
            values = self._timeline.values[index].copy()
            self._held.append((self._written, kind, values, now.nanoseconds))
            self._release(now)
        else:
            super()._publish(index, now)

    def _on_raw(self, msg: WrenchStamped) -> None:
        w = msg.wrench
        values = (w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z)
        self._returned.returned(values, Time.from_msg(msg.header.stamp).nanoseconds)
        self._release(self.get_clock().now())

    def _release(self, now: Time) -> None:
        """Publish the held markers whose preceding sample has come back (see the docstring)."""
        while self._held:
            before, kind, values, since_ns = self._held[0]
            matched = self._returned.marker_stamp(before) if before else None
            if before == 0:  # nothing before it: it goes first
                stamp_ns = now.nanoseconds
            elif matched is not None:
                stamp_ns = matched
            elif now.nanoseconds - since_ns > MARKER_WAIT_S * 1e9:
                stamp_ns = now.nanoseconds
                if not self._said_unmatched:
                    self._said_unmatched = True
                    self.get_logger().warn(
                        f'no /balance/raw sample came back from balance_daq within '
                        f"{MARKER_WAIT_S:g} s: the rig's messages are stamped on this "
                        "node's clock"
                    )
            else:
                return
            self._held.popleft()
            stamp = Time(nanoseconds=stamp_ns).to_msg()
            self._outputs[kind].publish(self._message(kind, values, stamp))

    def _on_tick(self):
        super()._on_tick()
        self._device.flush()  # the samples of one tick in one write (one datagram each)
        self._release(self.get_clock().now())

    def _finish(self, now: Time):
        if self._held:  # the rig's last messages first
            self._release(now)
            return
        super()._finish(now)


def run(device: VirtualDevice, parameters: dict, args=None) -> int:
    """Spin the node until the run is over (exit_when_done) or Ctrl-C; the exit status."""
    from rclpy.parameter import Parameter

    from ._run import run_node

    def make_node() -> VirtualDaq:
        overrides = [Parameter(name, value=value) for name, value in parameters.items()]
        return VirtualDaq(device, parameter_overrides=overrides)

    # not sys.argv: the command's own options (-p NAME:=VALUE) are not ROS arguments
    return run_node(
        'virtual_daq',
        make_node,
        refused=(StartupError, ValueError),
        args=['virtual_daq'] if args is None else args,
        until_done=True,
    )
