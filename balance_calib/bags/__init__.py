"""Calibration bags: rosbag2 MCAP bags in (writer), numpy arrays per topic out (reader).

Pure: no rclpy here, so the refit reads bags in a notebook, the CLI and a node alike.
"""

from balance_calib.bags.errors import BagError
from balance_calib.bags.reader import BagData, GravitySeries, read_bags, StampedSeries, TopicNames
from balance_calib.bags.writer import BagWriter, qos_profiles_yaml

__all__ = [
    'BagData',
    'BagError',
    'BagWriter',
    'GravitySeries',
    'qos_profiles_yaml',
    'read_bags',
    'StampedSeries',
    'TopicNames',
]
