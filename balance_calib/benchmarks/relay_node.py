"""The baseline of the live benchmark: a bare rclpy relay (subscribe, copy, publish).

/balance/raw -> /balance/wrench with the same QoS as balance_calibrator (reliable, depth 1000),
no calibration: what rclpy and DDS alone cost.
"""

from geometry_msgs.msg import WrenchStamped
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy


class Relay(Node):
    def __init__(self):
        super().__init__('bare_relay')
        qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        self.publisher = self.create_publisher(WrenchStamped, '/balance/wrench', qos)
        self.create_subscription(WrenchStamped, '/balance/raw', self.relay, qos)

    def relay(self, raw: WrenchStamped) -> None:
        out = WrenchStamped()
        out.header.stamp = raw.header.stamp
        out.header.frame_id = 'tunnel'
        out.wrench.force.x, out.wrench.force.y, out.wrench.force.z = (
            raw.wrench.force.x,
            raw.wrench.force.y,
            raw.wrench.force.z,
        )
        out.wrench.torque.x, out.wrench.torque.y, out.wrench.torque.z = (
            raw.wrench.torque.x,
            raw.wrench.torque.y,
            raw.wrench.torque.z,
        )
        self.publisher.publish(out)


def main(args=None):
    rclpy.init(args=args)
    node = Relay()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
