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
"""

from __future__ import annotations

from rclpy.duration import Duration
from rclpy.time import Time

from balance_calib.simulation import timeline as tl
from balance_calib.simulation.virtual_device import VirtualDevice

from .bridge_publisher import BridgePublisher, EVENT_QOS, StartupError

MODES = ('calibration', 'wind_on')


class _DeviceOutput:
    """Stands where bridge_publisher keeps the /balance/raw publisher: the device's clients are
    its subscribers.
    """

    def __init__(self, device: VirtualDevice):
        self.device = device
        self.topic_name = f'the virtual device ({device.transport} {device.address})'

    def get_subscription_count(self) -> int:
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
        elif kind == tl.TEMPERATURE and self._device.has_temperature:
            self._device.temperature_c = float(self._timeline.values[index, 0])
        else:
            super()._publish(index, now)

    def _on_tick(self):
        super()._on_tick()
        self._device.flush()  # the samples of one tick in one write (one datagram each)


def run(device: VirtualDevice, parameters: dict, args=None) -> int:
    """Spin the node until the run is over (exit_when_done) or Ctrl-C; the exit status."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.parameter import Parameter

    rclpy.init(args=args)
    node = None
    status = 0
    logger = rclpy.logging.get_logger('virtual_daq')
    try:
        overrides = [Parameter(name, value=value) for name, value in parameters.items()]
        node = VirtualDaq(device, parameter_overrides=overrides)
        rclpy.spin_until_future_complete(node, node.done)
        if node.failure:
            logger.error(node.failure)
            status = 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (StartupError, ValueError) as err:
        logger.error(str(err))
        status = 1
    except RuntimeError:
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return status
