"""Wind-on runs in bags: the samples the reduction needs, matched by header stamp.

A run bag holds /balance/raw (mV), /model/attitude (Vector3Stamped: x roll φ, y α, z β, rad) and
/tunnel/dynamic_pressure (FluidPressure, Pa) (interfaces.md; topics remappable). Each raw sample
takes the latest attitude and q∞ stamped at or before its own stamp; a sample whose latest attitude
or q∞ is older than `max_input_age_s` (or that has none) is stale and left out, and counted, the
same rule the live node applies.

`write_run_bag` writes such a bag without ROS running (tests, demo), plus the simulation's truth
topics when given.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from ..bags.errors import BagError
from ..bags.reader import read_bags, TopicNames
from ..bags.writer import BagWriter, qos_profiles_yaml
from ..units import BRIDGE_OUTPUTS

RAW_TOPIC = '/balance/raw'
ATTITUDE_TOPIC = '/model/attitude'
DYNAMIC_PRESSURE_TOPIC = '/tunnel/dynamic_pressure'
TRUTH_TOPIC = '/aero/truth'  # simulation only: true body coefficients
TRUTH_WIND_TOPIC = '/aero/truth_wind'  # simulation only: true wind-axis coefficients
DIAGNOSTICS_TOPIC = '/diagnostics'  # a live balance_calibrator's, stating its ~/zero
DEFAULT_MAX_INPUT_AGE_S = 0.5


@dataclass(frozen=True)
class RunSamples:
    """Raw samples of a run with their matched attitude and q∞, in stamp order (stale ones
    removed).
    """

    stamps_ns: np.ndarray  # (S,)
    raw_mv: np.ndarray  # (S, 6)
    support_attitude: np.ndarray  # (S, 3) rad
    q_pa: np.ndarray  # (S,)
    stale: int  # raw samples left out: attitude or q∞ missing or too old
    sources: tuple[Path, ...]
    frame_id: str
    truth_body: np.ndarray | None = None  # (S, 6) if the bag has /aero/truth at the same stamps
    truth_wind: np.ndarray | None = None
    # the electrical zeros a live balance_calibrator stated in the bag's /diagnostics (key
    # zero_mv of its calibration status), in time order: (node, balance, zero (6,) mV)
    stated_zeros: tuple[tuple[str, str, np.ndarray], ...] = ()


def parse_zero_mv(text: str) -> np.ndarray | None:
    """balance_calibrator's /diagnostics `zero_mv` ('FXV=+0.04000, FYV=…', diagnostics_status)
    -> (6,) mV, bridges it does not name 0; None for 'none' or what does not parse.
    """
    zero = np.zeros(6)
    try:
        for item in text.split(','):
            name, _, value = item.strip().partition('=')
            zero[BRIDGE_OUTPUTS.index(name)] = float(value)
    except ValueError:  # 'none', an unknown bridge name, not a number
        return None
    return zero if np.all(np.isfinite(zero)) else None


def stated_zeros(messages) -> tuple[tuple[str, str, np.ndarray], ...]:
    """(node, balance, zero) of every calibration status of DiagnosticArray messages that states
    an electrical zero.
    """
    found = []
    for array in messages:
        for status in array.status:
            node, _, part = status.name.rpartition(': ')
            if part != 'calibration':
                continue
            values = {kv.key: kv.value for kv in status.values}
            zero = parse_zero_mv(values.get('zero_mv', 'none'))
            if zero is not None:
                found.append((node, status.hardware_id, zero))
    return tuple(found)


def match_latest(stamps_ns, input_stamps_ns, input_values, max_age_s: float):
    """For each stamp, the latest input value stamped at or before it: (values, ok mask).

    input_* need not be sorted; ok is False where there is none or it is older than max_age_s.
    """
    stamps = np.asarray(stamps_ns, np.int64)
    order = np.argsort(np.asarray(input_stamps_ns, np.int64), kind='stable')
    inputs = np.asarray(input_stamps_ns, np.int64)[order]
    values = np.asarray(input_values, float)[order]
    index = np.searchsorted(inputs, stamps, side='right') - 1
    ok = index >= 0
    safe = np.maximum(index, 0)
    if len(inputs) == 0:
        return np.full((len(stamps),) + values.shape[1:], np.nan), np.zeros(len(stamps), bool)
    ok &= (stamps - inputs[safe]) <= int(round(max_age_s * 1e9))
    matched = values[safe].copy()
    matched[~ok] = np.nan
    return matched, ok


def _scalar_series(messages, field: str, topic: str, sources) -> tuple[np.ndarray, np.ndarray]:
    stamps = np.array(
        [m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in messages.messages],
        dtype=np.int64,
    )
    try:
        values = np.array([float(getattr(m, field)) for m in messages.messages], dtype=float)
    except AttributeError:
        raise BagError(
            f'{", ".join(map(str, sources))}: topic {topic} has type {messages.msgtype}, '
            f'expected sensor_msgs/msg/FluidPressure'
        ) from None
    return stamps, values


def _wrench_series(messages) -> tuple[np.ndarray, np.ndarray]:
    stamps = np.array(
        [m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in messages.messages],
        dtype=np.int64,
    )
    values = np.array(
        [
            [
                m.wrench.force.x,
                m.wrench.force.y,
                m.wrench.force.z,
                m.wrench.torque.x,
                m.wrench.torque.y,
                m.wrench.torque.z,
            ]
            for m in messages.messages
        ],
        dtype=float,
    )
    return stamps, values.reshape(-1, 6)


def read_run(
    paths: Sequence[str | Path],
    *,
    raw_topic: str = RAW_TOPIC,
    attitude_topic: str = ATTITUDE_TOPIC,
    dynamic_pressure_topic: str = DYNAMIC_PRESSURE_TOPIC,
    max_input_age_s: float = DEFAULT_MAX_INPUT_AGE_S,
    truth: bool = True,
) -> RunSamples:
    """Read a wind-on run from bags. BagError names the file and topic when something is
    missing.
    """
    paths = [Path(p) for p in paths]
    # /model/attitude has the calibration gravity's message type: read it through that array path
    extra = [dynamic_pressure_topic, DIAGNOSTICS_TOPIC] + (
        [TRUTH_TOPIC, TRUTH_WIND_TOPIC] if truth else []
    )
    data = read_bags(
        paths,
        topics=TopicNames(
            raw=raw_topic,
            gravity=attitude_topic,
            applied_load='/aero/unused',
            temperature='/aero/unused_temperature',
        ),
        required=('raw', 'gravity'),
        extra_topics=extra,
    )
    q_messages = data.extra.get(dynamic_pressure_topic)
    if q_messages is None or len(q_messages) == 0:
        raise BagError(
            f'{", ".join(map(str, paths))}: no messages on {dynamic_pressure_topic}, which is '
            'required (the free-stream dynamic pressure)'
        )
    q_stamps, q_values = _scalar_series(
        q_messages, 'fluid_pressure', dynamic_pressure_topic, paths
    )
    raw = data.raw
    order = np.argsort(raw.stamps_ns, kind='stable')
    stamps = raw.stamps_ns[order]
    attitude, ok_attitude = match_latest(
        stamps, data.gravity.stamps_ns, data.gravity.values, max_input_age_s
    )
    q, ok_q = match_latest(stamps, q_stamps, q_values, max_input_age_s)
    ok = (
        ok_attitude
        & ok_q
        & np.all(np.isfinite(raw.values[order]), axis=1)
        & np.all(np.isfinite(attitude), axis=1)
        & np.isfinite(q)
    )
    truth_body = truth_wind = None
    for topic, name in ((TRUTH_TOPIC, 'body'), (TRUTH_WIND_TOPIC, 'wind')):
        messages = data.extra.get(topic)
        if messages is not None and len(messages):
            t_stamps, t_values = _wrench_series(messages)
            matched, t_ok = match_latest(stamps[ok], t_stamps, t_values, 0.0)  # same stamp only
            if name == 'body':
                truth_body = matched
            else:
                truth_wind = matched
    frame = str(raw.frame_ids[order][0]) if len(raw) else ''
    diagnostics = data.extra.get(DIAGNOSTICS_TOPIC)
    zeros = stated_zeros(diagnostics.messages) if diagnostics is not None else ()
    return RunSamples(
        stamps[ok],
        raw.values[order][ok],
        attitude[ok],
        q[ok],
        int(np.count_nonzero(~ok)),
        tuple(paths),
        frame,
        truth_body,
        truth_wind,
        zeros,
    )


# --- writing (without ROS)
# ------------------------------------------------------------------------
def write_run_bag(
    path: str | Path,
    stamps_ns,
    raw_mv,
    support_attitude,
    q_pa,
    *,
    frame_id: str = 'balance',
    truth_body=None,
    truth_wind=None,
) -> Path:
    """A run bag as bridge_publisher's wind_on mode publishes it, one attitude and q∞ per raw
    sample.
    """
    from ..bags.messages import RELIABLE_QOS, typestore, vector_cdr, wrench_cdr

    store = typestore()

    def fluid_pressure(ns, value):
        header = store.types['std_msgs/msg/Header'](
            stamp=store.types['builtin_interfaces/msg/Time'](
                sec=int(ns // 10**9), nanosec=int(ns % 10**9)
            ),
            frame_id='tunnel',
        )
        message = store.types['sensor_msgs/msg/FluidPressure'](
            header=header, fluid_pressure=float(value), variance=0.0
        )
        return store.serialize_cdr(message, 'sensor_msgs/msg/FluidPressure')

    qos = qos_profiles_yaml(RELIABLE_QOS)
    with BagWriter(path) as writer:
        writer.add_topic(ATTITUDE_TOPIC, 'geometry_msgs/msg/Vector3Stamped', qos)
        writer.add_topic(DYNAMIC_PRESSURE_TOPIC, 'sensor_msgs/msg/FluidPressure', qos)
        writer.add_topic(RAW_TOPIC, 'geometry_msgs/msg/WrenchStamped', qos)
        if truth_body is not None:
            writer.add_topic(TRUTH_TOPIC, 'geometry_msgs/msg/WrenchStamped', qos)
        if truth_wind is not None:
            writer.add_topic(TRUTH_WIND_TOPIC, 'geometry_msgs/msg/WrenchStamped', qos)
        for i, ns in enumerate(np.asarray(stamps_ns, np.int64)):
            ns = int(ns)
            writer.write(ATTITUDE_TOPIC, ns, vector_cdr(ns, 'tunnel', support_attitude[i]))
            writer.write(DYNAMIC_PRESSURE_TOPIC, ns, fluid_pressure(ns, q_pa[i]))
            writer.write(RAW_TOPIC, ns, wrench_cdr(ns, frame_id, raw_mv[i]))
            if truth_body is not None and np.all(np.isfinite(truth_body[i])):
                writer.write(TRUTH_TOPIC, ns, wrench_cdr(ns, 'body', truth_body[i]))
            if truth_wind is not None and np.all(np.isfinite(truth_wind[i])):
                writer.write(TRUTH_WIND_TOPIC, ns, wrench_cdr(ns, 'wind', truth_wind[i]))
    return Path(path)
