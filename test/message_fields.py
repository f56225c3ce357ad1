"""Messages as nested plain values, so that what rosbags and mcap_ros2 decode can be compared
(test_bags_writer, test_bags_recorder).
"""

import dataclasses
import math


def fields_of(message):
    """A message as nested plain values, comparable across rosbags and mcap_ros2 objects."""
    if isinstance(message, (list, tuple)):
        return [fields_of(item) for item in message]
    if dataclasses.is_dataclass(message) or hasattr(message, '__slots__'):
        names = (
            [f.name for f in dataclasses.fields(message)]
            if dataclasses.is_dataclass(message)
            else message.__slots__
        )
        # ROS 2 field names are lower case; rosbags also lists the UPPER_CASE constants
        return {
            name: fields_of(getattr(message, name))
            for name in names
            if not name.startswith('_') and not name.isupper()
        }
    if isinstance(message, float) and math.isnan(message):
        return 'nan'
    return message
