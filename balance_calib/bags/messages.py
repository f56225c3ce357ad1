"""CDR bytes of the interface messages (interfaces.md topics), without ROS running.

One encoder per message type, shared by every writer of bags (simulated campaigns, wind-on
runs, the benchmarks), serialised with the rosbags type store.
"""

from __future__ import annotations

from rosbags.typesys import get_typestore, Stores

_STORE = None
# std_msgs/String in a simulated campaign's bag: its stamps are the simulator's clock, not a date
SIMULATION_TOPIC = '/simulation/campaign'
RELIABLE_QOS = [
    {'history': 'keep_last', 'depth': 1000, 'reliability': 'reliable', 'durability': 'volatile'}
]
LATCHED_QOS = [
    {
        'history': 'keep_last',
        'depth': 10,
        'reliability': 'reliable',
        'durability': 'transient_local',
    }
]


def typestore():
    """The rosbags type store of ROS 2 Jazzy (made once)."""
    global _STORE
    if _STORE is None:
        _STORE = get_typestore(Stores.ROS2_JAZZY)
    return _STORE


def header(ns: int, frame: str):
    store = typestore()
    Time = store.types['builtin_interfaces/msg/Time']
    Header = store.types['std_msgs/msg/Header']
    return Header(
        stamp=Time(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000)), frame_id=frame
    )


def wrench_cdr(ns: int, frame: str, values) -> bytes:
    store = typestore()
    Vector3 = store.types['geometry_msgs/msg/Vector3']
    Wrench = store.types['geometry_msgs/msg/Wrench']
    WrenchStamped = store.types['geometry_msgs/msg/WrenchStamped']
    v = [float(x) for x in values]
    msg = WrenchStamped(
        header=header(ns, frame),
        wrench=Wrench(
            force=Vector3(x=v[0], y=v[1], z=v[2]), torque=Vector3(x=v[3], y=v[4], z=v[5])
        ),
    )
    return store.serialize_cdr(msg, 'geometry_msgs/msg/WrenchStamped')


def vector_cdr(ns: int, frame: str, values) -> bytes:
    store = typestore()
    Vector3 = store.types['geometry_msgs/msg/Vector3']
    Vector3Stamped = store.types['geometry_msgs/msg/Vector3Stamped']
    msg = Vector3Stamped(
        header=header(ns, frame),
        vector=Vector3(x=float(values[0]), y=float(values[1]), z=float(values[2])),
    )
    return store.serialize_cdr(msg, 'geometry_msgs/msg/Vector3Stamped')


def temperature_cdr(ns: int, frame: str, value: float) -> bytes:
    store = typestore()
    Temperature = store.types['sensor_msgs/msg/Temperature']
    msg = Temperature(header=header(ns, frame), temperature=float(value), variance=0.0)
    return store.serialize_cdr(msg, 'sensor_msgs/msg/Temperature')
