"""Message fields filled from plain values, as more than one node fills them."""

from typing import Iterable

from geometry_msgs.msg import Wrench


def set_wrench(wrench: Wrench, values: Iterable[float]) -> None:
    """Set force x, y, z and torque x, y, z of `wrench` from six values (as floats); returns
    nothing.
    """
    (
        wrench.force.x,
        wrench.force.y,
        wrench.force.z,
        wrench.torque.x,
        wrench.torque.y,
        wrench.torque.z,
    ) = (float(v) for v in values)
