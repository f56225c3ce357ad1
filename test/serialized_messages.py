"""Live messages as rclpy serializes them, and the live path's one call fed one message at a time:
what the C kernel's tests (test_sample_kernel, test_live_partial_calibration) compare with the pure
core.
"""

from geometry_msgs.msg import WrenchStamped
import numpy as np
from rclpy.serialization import deserialize_message, serialize_message
from ros_harness import six as wrench_six

from balance_calib.live.raw_codec import decode_wrenches
from balance_calib.nodes._messages import set_wrench


def serialized(values, stamps_ns, frame='LMC6522'):
    messages = []
    for row, stamp in zip(values, stamps_ns):
        msg = WrenchStamped()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp), 10**9)
        msg.header.frame_id = frame
        set_wrench(msg.wrench, row)
        messages.append(serialize_message(msg))
    return messages


def six(data: bytes) -> np.ndarray:
    return np.array(wrench_six(deserialize_message(data, WrenchStamped)))


def through_kernel(live, data, now_s, encoder, scale=1.0):
    """One message through LiveCalibrator.process_messages (the live path's one call) ->
    (wrench bytes, uncertainty bytes or None) when the C kernel took it, else None (the pure
    core took it in the same call).
    """
    out = live.process_messages(
        [data],
        now_s=now_s,
        decode=decode_wrenches,
        input_scale=scale,
        encoder=encoder,
        uncertainty_wanted=True,
    )
    if not out.accelerated:
        return None
    uncertainty = out.uncertainty()
    return out.wrench[0], uncertainty[0] if uncertainty else None


def single_through_kernel(live, messages, scale, encoder):
    """Each message alone through process_messages, 0.1 s apart; wrench/uncertainty per message
    (None: not published), and which ones the kernel took.
    """
    wrench, uncertainty, by_kernel = [], [], []
    for k, data in enumerate(messages):
        out = live.process_messages(
            [data],
            now_s=0.1 * k,
            decode=decode_wrenches,
            input_scale=scale,
            encoder=encoder,
            uncertainty_wanted=True,
        )
        by_kernel.append(out.accelerated == 1)
        values = out.uncertainty()
        wrench.append(six(out.wrench[0]) if out.wrench else None)
        uncertainty.append(six(values[0]) if values else None)
        if out.wrench:
            assert deserialize_message(out.wrench[0], WrenchStamped).header.frame_id == 'tunnel'
    return wrench, uncertainty, by_kernel
