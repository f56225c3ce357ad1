"""The QoS of the sample streams (/balance/raw, /balance/wrench, the wind-on run's topics).

Reliable, keep-last. The depth is how long a subscriber may stall before samples are lost for
good: a reliable writer repairs a sample its reader missed (a UDP datagram dropped while the
reader's process was off the CPU) only while the sample is still in the writer's history, and a
reader's queue holds what its callback has not yet taken. A recorder stalled 1.5 s behind a
1 kHz stream lost 1014 of 1700 /balance/wrench samples with a depth of 1000 (one second); ten
seconds cost about 3 MB per stream at most (measured with WrenchStamped).
"""

from rclpy.qos import QoSProfile, ReliabilityPolicy

STREAM_DEPTH = 10_000  # samples: ten seconds of a 1 kHz stream
STREAM_QOS = QoSProfile(depth=STREAM_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
