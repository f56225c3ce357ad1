"""Write a simulated campaign as a calibration bag (interfaces.md layout), without ROS running.

The messages are the ones `bridge_publisher` publishes in calibration mode: /calibration/gravity
on every orientation change, an all-NaN /calibration/applied_load while weights change, the load
when a point settles, /balance/raw samples in mV and /balance/temperature. Serialised with the
rosbags type store (CDR), written by bags.writer.BagWriter. One message on SIMULATION_TOPIC (this
simulation only, as /aero/truth is for wind-on runs) says that the stamps are the simulator's
clock, so that a report of the bag does not present them as the date of a campaign.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..bags.messages import (
    LATCHED_QOS,
    RELIABLE_QOS,
    SIMULATION_TOPIC,
    temperature_cdr,
    typestore,
    vector_cdr,
    wrench_cdr,
)
from ..bags.writer import BagWriter, qos_profiles_yaml
from .balance_sim import Campaign


def simulated_clock_note(start_ns: int) -> str:
    """The text of SIMULATION_TOPIC's message for a campaign whose clock starts at start_ns."""
    import datetime as _dt

    start = _dt.datetime.fromtimestamp(start_ns / 1e9, _dt.timezone.utc)
    return (
        f"simulated campaign (balance_calib): stamps are the simulation's clock, started at "
        f'{start.isoformat(timespec="seconds")}, not the date of a campaign'
    )


def _note(text: str) -> bytes:
    store = typestore()
    message = store.types['std_msgs/msg/String'](data=text)
    return store.serialize_cdr(message, 'std_msgs/msg/String')


def write_campaign_bag(
    campaign: Campaign,
    path: str | Path,
    *,
    start_ns: int = 1_700_000_000 * 10**9,
    temperature_every: int = 1,
    points: slice | None = None,
) -> Path:
    """Write the campaign (or a slice of its points) as a rosbag2 MCAP bag directory at path."""
    frame = campaign.balance
    selected = (
        np.arange(len(campaign.point))[points]
        if points is not None
        else np.arange(len(campaign.point))
    )
    chosen = np.zeros(len(campaign.point), bool)
    chosen[selected] = True
    writer = BagWriter(path)
    writer.open()
    try:
        writer.add_topic(
            '/balance/raw', 'geometry_msgs/msg/WrenchStamped', qos_profiles_yaml(RELIABLE_QOS)
        )
        writer.add_topic(
            '/balance/temperature', 'sensor_msgs/msg/Temperature', qos_profiles_yaml(RELIABLE_QOS)
        )
        writer.add_topic(
            '/calibration/applied_load',
            'geometry_msgs/msg/WrenchStamped',
            qos_profiles_yaml(RELIABLE_QOS),
        )
        writer.add_topic(
            '/calibration/gravity',
            'geometry_msgs/msg/Vector3Stamped',
            qos_profiles_yaml(LATCHED_QOS),
        )
        writer.add_topic(SIMULATION_TOPIC, 'std_msgs/msg/String', qos_profiles_yaml(LATCHED_QOS))
        # (time_ns, order, topic, bytes): the note first, markers before samples at equal times
        events = [(start_ns, -1, SIMULATION_TOPIC, _note(simulated_clock_note(start_ns)))]
        gap = campaign.start_s[1] - campaign.end_s[0] if len(campaign.start_s) > 1 else 1.0
        previous_orientation = None
        for p in selected:
            # weights start changing when the previous point's settled window ends
            previous_end = campaign.end_s[p - 1] if p > 0 else campaign.start_s[0] - gap
            transition_ns = start_ns + int(round(previous_end * 1e9)) + 1
            if campaign.orientation[p] != previous_orientation:
                events.append(
                    (
                        transition_ns,
                        0,
                        '/calibration/gravity',
                        vector_cdr(transition_ns, frame, campaign.gravity[p]),
                    )
                )
                previous_orientation = campaign.orientation[p]
            events.append(
                (
                    transition_ns,
                    1,
                    '/calibration/applied_load',
                    wrench_cdr(transition_ns, frame, [np.nan] * 6),
                )
            )
            settled_ns = start_ns + int(round(campaign.start_s[p] * 1e9))
            events.append(
                (
                    settled_ns,
                    1,
                    '/calibration/applied_load',
                    wrench_cdr(settled_ns, frame, campaign.applied_loads[p]),
                )
            )
        in_sample = (campaign.sample_point < 0) | chosen[np.maximum(campaign.sample_point, 0)]
        for i in np.flatnonzero(in_sample):
            ns = start_ns + int(round(campaign.times_s[i] * 1e9))
            events.append((ns, 2, '/balance/raw', wrench_cdr(ns, frame, campaign.raw_mv[i])))
            if temperature_every and i % temperature_every == 0:
                events.append(
                    (
                        ns,
                        3,
                        '/balance/temperature',
                        temperature_cdr(ns, frame, campaign.temperature_c[i]),
                    )
                )
        events.sort(key=lambda e: (e[0], e[1]))
        for ns, _, topic, data in events:
            writer.write(topic, ns, data)
    finally:
        writer.close()
    return Path(path)
