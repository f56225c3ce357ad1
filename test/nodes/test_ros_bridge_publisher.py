"""bridge_publisher over real DDS: a calibration campaign as interfaces.md has it, replay,
thrust stand, errors.
"""

import sys

from geometry_msgs.msg import Vector3Stamped, WrenchStamped
import numpy as np
import pytest
import rclpy
from rclpy.context import Context
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message
from ros_harness import new_domain_id, NodeProcess, Probe, six, wait_for
from sensor_msgs.msg import FluidPressure, Temperature

from balance_calib.bags.writer import BagWriter
from balance_calib.config import load_balance_config
from balance_calib.nodes.bridge_publisher import BridgePublisher, StartupError
from balance_calib.simulation.balance_sim import (
    simulate_campaign,
    SimulationSettings,
    table17_noise,
)
from balance_calib.simulation.timeline import select_points

pytestmark = pytest.mark.ros
CONFIG = load_balance_config('lmc6522')


def stamp_ns(msg):
    return msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec


@pytest.fixture
def probe():
    probe = Probe(new_domain_id())
    yield probe
    probe.close()


def test_calibration_mode_plays_the_schedule_as_interfaces_md_describes(probe, tmp_path):
    raw = probe.subscribe(WrenchStamped, '/balance/raw')
    applied = probe.subscribe(WrenchStamped, '/calibration/applied_load')
    gravity = probe.subscribe(Vector3Stamped, '/calibration/gravity')
    temperature = probe.subscribe(Temperature, '/balance/temperature')
    node = NodeProcess(
        'bridge_publisher',
        probe.domain_id,
        tmp_path,
        {
            'mode': 'calibration',
            'points': '1-16',
            'rate_hz': 200.0,
            'point_duration_s': 0.1,
            'transition_s': 0.03,
            'seed': 7,
            'exit_when_done': True,
            'wait_for_subscribers': 1,
        },
    )
    try:
        assert node.wait(60.0) == 0, node.output()
    finally:
        node.stop()
    assert 'campaign complete' in node.output()
    wait_for(lambda: len(raw) == 16 * 26, 5.0, f'all 416 raw samples (have {len(raw)})')

    # exactly the simulated campaign, sample for sample (same settings and seed)
    settings = SimulationSettings(
        samples_per_point=20,
        sample_rate_hz=200.0,
        point_duration_s=0.1,
        transition_s=0.03,
        transition_samples=6,
        noise_sigma_pct_fs=table17_noise(CONFIG),
        seed=7,
        # physical_seconds_per_point 90 (default)
        time_scale=90.0 / 0.13,
    )
    campaign = simulate_campaign(
        CONFIG,
        CONFIG.matrices['cubic'],
        schedule=select_points(CONFIG.schedule, '1-16'),
        settings=settings,
    )
    np.testing.assert_array_equal([six(m) for m in raw], campaign.raw_mv)
    assert {m.header.frame_id for m in raw} == {'LMC6522'}
    raw_stamps = np.array([stamp_ns(m) for m in raw], dtype=np.int64)
    assert np.all(np.diff(raw_stamps) > 0)
    assert 0.8 * 2.08 < (raw_stamps[-1] - raw_stamps[0]) * 1e-9 < 1.5 * 2.08  # played in real time

    # applied_load: NaN while weights change, then the schedule's load once settled
    values = np.array([six(m) for m in applied])
    assert (
        len(values) == 32 and np.all(np.isnan(values[0::2])) and not np.isnan(values[1::2]).any()
    )
    np.testing.assert_allclose(values[1::2], campaign.applied_loads)
    # a point's samples are the raw messages stamped from its applied_load to the next applied_load
    applied_stamps = np.append(
        np.array([stamp_ns(m) for m in applied], dtype=np.int64), np.iinfo(np.int64).max
    )
    owner = np.searchsorted(applied_stamps, raw_stamps, side='right') - 1
    expected = np.where(owner % 2 == 1, owner // 2, -1)
    np.testing.assert_array_equal(expected, campaign.sample_point)
    # gravity: before the first point of each orientation (I_g 2, then 4 from point 15)
    assert [[m.vector.x, m.vector.y, m.vector.z] for m in gravity] == [
        CONFIG.gravity(i).tolist() for i in (2, 4)
    ]
    first_points = [0, 14]
    for message, point in zip(gravity, first_points):
        assert stamp_ns(message) <= stamp_ns(applied[2 * point + 1])
        assert (
            point == 0 or stamp_ns(message) > raw_stamps[campaign.sample_point == point - 1].max()
        )
    assert 16 <= len(temperature) <= 26 and all(15 < m.temperature < 25 for m in temperature)


def test_replay_republishes_a_bag_with_its_stamps(probe, tmp_path):
    bag = tmp_path / 'recorded'
    messages = []
    with BagWriter(bag) as writer:
        writer.add_topic('/balance/raw', 'geometry_msgs/msg/WrenchStamped')
        writer.add_topic('/calibration/gravity', 'geometry_msgs/msg/Vector3Stamped')
        g = Vector3Stamped()
        g.header.stamp.sec, g.vector.z = 500, 1.0
        writer.write('/calibration/gravity', 1_000_000_000, serialize_message(g))
        for k in range(40):
            msg = WrenchStamped()
            msg.header.stamp.sec, msg.header.stamp.nanosec = 500, k * 10_000_000
            msg.header.frame_id = 'LMC6522'
            msg.wrench.force.x, msg.wrench.torque.z = 0.01 * k, -0.02 * k
            messages.append(msg)
            writer.write(
                '/balance/raw', 1_000_000_000 + (k + 1) * 10_000_000, serialize_message(msg)
            )
    raw = probe.subscribe(WrenchStamped, '/balance/raw')
    gravity = probe.subscribe(Vector3Stamped, '/calibration/gravity')
    node = NodeProcess(
        'bridge_publisher',
        probe.domain_id,
        tmp_path,
        {
            'mode': 'replay',
            'bag': str(bag),
            'speed': 2.0,
            'exit_when_done': True,
            'wait_for_subscribers': 1,
        },
    )
    try:
        assert node.wait(30.0) == 0, node.output()
    finally:
        node.stop()
    wait_for(lambda: len(raw) == 40 and len(gravity) == 1, 5.0, 'the replayed messages')
    assert [(m.header.stamp.sec, m.header.stamp.nanosec, six(m)) for m in raw] == [
        (m.header.stamp.sec, m.header.stamp.nanosec, six(m)) for m in messages
    ]
    assert gravity[0].vector.z == 1.0 and gravity[0].header.stamp.sec == 500


def test_thrust_stand_mode_publishes_strain_and_pressures(probe, tmp_path):
    raw = probe.subscribe(WrenchStamped, '/balance/raw')
    chamber = probe.subscribe(FluidPressure, '/thrust_stand/chamber_pressure')
    ambient = probe.subscribe(FluidPressure, '/thrust_stand/ambient_pressure')
    node = NodeProcess(
        'bridge_publisher',
        probe.domain_id,
        tmp_path,
        {'mode': 'thrust_stand', 'rate_hz': 100.0, 'wait_for_subscribers': 1},
    )
    try:
        wait_for(
            lambda: len(raw) >= 50 and len(chamber) >= 50 and len(ambient) >= 50,
            20.0,
            'thrust stand signals',
        )
        assert node.stop() == 0  # SIGINT: a clean exit
    finally:
        node.stop()
    assert {m.header.frame_id for m in raw} == {'thrust_stand'}
    assert all(six(m)[1:] == [0.0] * 5 for m in raw)  # one strain channel, on force.x
    assert 9e4 < np.mean([m.fluid_pressure for m in ambient]) < 1.1e5


def test_unknown_mode_exits_with_a_message(tmp_path):
    node = NodeProcess('bridge_publisher', new_domain_id(), tmp_path, {'mode': 'tunnel'})
    try:
        assert node.wait(30.0) == 1
    finally:
        node.stop()
    assert (
        "mode = 'tunnel'" in node.output()
        and 'calibration, wind_on, replay, thrust_stand' in node.output()
    )


def test_thrust_stand_mode_without_its_simulator_fails_clearly(monkeypatch):
    monkeypatch.setitem(sys.modules, 'balance_calib.simulation.thrust_stand', None)  # import fails
    context = Context()
    rclpy.init(context=context, domain_id=new_domain_id())
    try:
        with pytest.raises(
            StartupError, match='thrust_stand mode is not available.*ThrustStandSimulator'
        ):
            BridgePublisher(
                context=context, parameter_overrides=[Parameter('mode', value='thrust_stand')]
            )
    finally:
        rclpy.try_shutdown(context=context)


def test_calibration_mode_plays_the_schedule_of_schedule_file(probe, tmp_path):
    """A designed schedule (balance-calib design) played with parameter schedule_file: the points
    of the file, not the config's, on /calibration/applied_load.
    """
    from balance_calib.config import LoadSchedule
    from balance_calib.schedule_file import read_schedule_csv, schedule_csv_text

    extra = LoadSchedule(
        np.array([400, 401, 402]),
        np.array([3, 3, 3]),
        np.array([[0.0] * 6, [-200.0, -1500.0, 3000.0, -40.0, 150.0, -180.0], [0.0] * 6]),
        ('', '', ''),
    )
    path = tmp_path / 'schedule.csv'
    path.write_text(schedule_csv_text(extra))
    raw = probe.subscribe(WrenchStamped, '/balance/raw')  # the node waits for a raw reader
    applied = probe.subscribe(WrenchStamped, '/calibration/applied_load')
    gravity = probe.subscribe(Vector3Stamped, '/calibration/gravity')
    node = NodeProcess(
        'bridge_publisher',
        probe.domain_id,
        tmp_path,
        {
            'mode': 'calibration',
            'schedule_file': str(path),
            'rate_hz': 200.0,
            'point_duration_s': 0.1,
            'transition_s': 0.03,
            'exit_when_done': True,
            'wait_for_subscribers': 1,
        },
    )
    try:
        assert node.wait(60.0) == 0, node.output()
    finally:
        node.stop()
    wait_for(
        lambda: len(applied) == 6, 5.0, f'the 3 points of the file (have {len(applied)} messages)'
    )
    values = np.array([six(m) for m in applied])
    np.testing.assert_allclose(values[1::2], read_schedule_csv(path).loads, rtol=1e-9, atol=1e-9)
    assert [[m.vector.x, m.vector.y, m.vector.z] for m in gravity] == [CONFIG.gravity(3).tolist()]
    wait_for(lambda: len(raw) == 3 * 26, 5.0, f'the raw samples of 3 points (have {len(raw)})')


def test_a_schedule_file_that_is_not_a_schedule_stops_the_node_with_its_name(tmp_path):
    path = tmp_path / 'schedule.csv'
    path.write_text('point,Ig,FX\n1,2,0\n')
    node = NodeProcess(
        'bridge_publisher',
        new_domain_id(),
        tmp_path,
        {'mode': 'calibration', 'schedule_file': str(path)},
    )
    try:
        assert node.wait(30.0) == 1
    finally:
        node.stop()
    assert f'{path}: not a load schedule: missing column(s) FX_kgf, FY_kgf' in node.output()
