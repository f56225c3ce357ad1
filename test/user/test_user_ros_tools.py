"""launchless_scripts/ros: the ros2 CLI habits (param, topic, service, bag info) over real DDS."""

import os
from pathlib import Path
import signal
import subprocess

from mcap.reader import make_reader
import numpy as np
import pytest
from ros_harness import new_domain_id, NodeProcess, ros, SCRIPTS
import yaml

from balance_calib.bags.reader import read_bags
from balance_calib.config import load_balance_config
from balance_calib.simulation.balance_sim import simulate_campaign, SimulationSettings
from balance_calib.simulation.campaign_bag import write_campaign_bag
from ros_cli.bag import format_bag_info


@pytest.mark.ros
def test_param_topic_and_service_verbs_on_a_running_calibrator(tmp_path):
    domain = new_domain_id()
    calibrator = NodeProcess(
        'balance_calibrator',
        domain,
        tmp_path,
        {'diagnostics_period_s': 0.2, 'tare_samples': 20, 'tare_timeout_s': 1.0},
    )
    try:
        # the new user's dead end of the issue: refit with calibration_bags empty -> set it, read
        # it back
        done = ros(
            domain,
            'param',
            'set',
            '/balance_calibrator',
            'calibration_bags',
            '[bags/a, bags/b]',
            '--timeout',
            60,
        )
        assert done.returncode == 0, done.stderr + calibrator.output()
        assert done.stdout.strip() == 'Set parameter successful'
        done = ros(
            domain, 'param', 'get', '/balance_calibrator', 'calibration_bags', '--timeout', 60
        )
        assert done.returncode == 0, done.stderr
        assert done.stdout.strip() == "String array value is: ['bags/a', 'bags/b']"
        # one path for a string-array parameter: a one-element list; a double stays a double
        assert (
            ros(
                domain, 'param', 'set', '/balance_calibrator', 'calibration_bags', 'bags/c'
            ).returncode
            == 0
        )
        assert (
            ros(domain, 'param', 'get', '/balance_calibrator', 'calibration_bags').stdout.strip()
            == "String array value is: ['bags/c']"
        )
        assert (
            ros(domain, 'param', 'set', '/balance_calibrator', 'envelope_margin', '2').returncode
            == 0
        )
        assert (
            ros(domain, 'param', 'get', '/balance_calibrator', 'envelope_margin').stdout.strip()
            == 'Double value is: 2.0'
        )
        wrong = ros(domain, 'param', 'set', '/balance_calibrator', 'envelope_margin', 'wide')
        assert wrong.returncode == 1 and 'is not a double' in wrong.stderr
        listed = ros(domain, 'param', 'list', '/balance_calibrator')
        assert {'calibration_bags', 'envelope_margin', 'model', 'installation'} <= set(
            listed.stdout.split()
        )

        echoed = ros(domain, 'topic', 'echo', '/diagnostics', '--count', '2', '--timeout', 60)
        assert echoed.returncode == 0, echoed.stderr
        documents = [d for d in yaml.safe_load_all(echoed.stdout) if d]
        assert len(documents) == 2
        assert any(
            status['name'].startswith('balance_calibrator') for status in documents[0]['status']
        )

        rate = ros(domain, 'topic', 'hz', '/diagnostics', '--duration', '3', '--timeout', 60)
        assert rate.returncode == 0, rate.stderr
        hz = float(rate.stdout.split('average rate:')[1].split()[0])
        assert 1.0 < hz < 25.0  # a 0.2 s period, within any scheduling a busy machine gives

        once = ros(domain, 'topic', 'echo', '--once', '/diagnostics', '--timeout', 60)
        assert once.returncode == 0 and once.stdout.count('---') == 1, once.stderr

        # ros2 topic info -v: each endpoint with its QoS
        info = ros(domain, 'topic', 'info', '/diagnostics', '-v', '--timeout', 60)
        assert info.returncode == 0, info.stderr
        assert 'Type: diagnostic_msgs/msg/DiagnosticArray' in info.stdout
        publisher = info.stdout.split('Node name: balance_calibrator', 1)[1]
        assert 'Endpoint type: PUBLISHER' in publisher
        assert 'Reliability: RELIABLE' in publisher.split('Node name:')[0]

        described = ros(domain, 'param', 'describe', '/balance_calibrator', 'tare_samples')
        assert described.returncode == 0, described.stderr
        lines = described.stdout.splitlines()
        assert lines[:2] == ['Parameter name: tare_samples', '  Type: integer']
        assert '    Min value: 10' in lines  # the table's range (live/parameters.py)

        dumped = ros(domain, 'param', 'dump', '/balance_calibrator')
        assert dumped.returncode == 0, dumped.stderr
        values = yaml.safe_load(dumped.stdout)['/balance_calibrator']['ros__parameters']
        assert values['tare_samples'] == 20 and values['envelope_margin'] == 2.0
        assert values['calibration_bags'] == ['bags/c']

        called = ros(domain, 'service', 'call', '/balance_calibrator/tare', '--timeout', 60)
        assert called.returncode == 1  # no samples flowing: the tare must refuse
        assert called.stdout.startswith('success: false\nmessage: ')
    finally:
        calibrator.stop()
    missing = ros(domain, 'param', 'get', '/no_such_node', 'x', '--timeout', 1)
    assert (
        missing.returncode == 1
        and 'service /no_such_node/get_parameters is not available' in missing.stderr
    )


def test_bag_info_counts_what_the_writer_wrote(tmp_path):
    config = load_balance_config('lmc6522')
    settings = SimulationSettings(samples_per_point=3, transition_samples=1, seed=5)
    campaign = simulate_campaign(config, settings=settings)
    bag = write_campaign_bag(campaign, tmp_path / 'campaign')
    # counted independently: every message of the bag's MCAP files, one by one
    counts, log_times = {}, []
    for file in sorted(Path(bag).glob('*.mcap')):
        with open(file, 'rb') as stream:
            for _, channel, message in make_reader(stream).iter_messages():
                counts[channel.topic] = counts.get(channel.topic, 0) + 1
                log_times.append(message.log_time)
    info = format_bag_info(Path(bag))
    assert f'Messages:          {sum(counts.values())}' in info
    for topic, count in counts.items():
        line = next(line for line in info.splitlines() if f'Topic: {topic} ' in line)
        assert f'| Count: {count} |' in line
    assert 'Chunk compression: zstd' in info
    # the raw samples: 3 per point plus the transition samples, per the simulation's own
    # bookkeeping
    points = len(campaign.point)
    assert counts['/balance/raw'] >= 3 * points
    assert f'Duration:          {(max(log_times) - min(log_times)) / 1e9:.3f}s' in info


def _wait_for_service(domain, name, kind='Trigger', timeout=60.0):
    """Until `name` answers (the node is up): the lists after it must not grow any more."""
    from rcl_interfaces.srv import ListParameters
    import rclpy
    from rclpy.context import Context
    from std_srvs.srv import Trigger

    context = Context()
    rclpy.init(context=context, domain_id=domain)
    try:
        node = rclpy.create_node('probe_wait', context=context)
        client = node.create_client(
            {'Trigger': Trigger, 'ListParameters': ListParameters}[kind], name
        )
        assert client.wait_for_service(timeout_sec=timeout), name
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


STANDARD_SERVICES = {  # every rclpy node of Jazzy: its parameters and its type descriptions
    'describe_parameters': 'rcl_interfaces/srv/DescribeParameters',
    'get_parameter_types': 'rcl_interfaces/srv/GetParameterTypes',
    'get_parameters': 'rcl_interfaces/srv/GetParameters',
    'list_parameters': 'rcl_interfaces/srv/ListParameters',
    'set_parameters': 'rcl_interfaces/srv/SetParameters',
    'set_parameters_atomically': 'rcl_interfaces/srv/SetParametersAtomically',
    'get_type_description': 'type_description_interfaces/srv/GetTypeDescription',
}


@pytest.mark.ros
def test_node_list_info_and_a_stable_service_list(tmp_path):
    domain = new_domain_id()
    calibrator = NodeProcess('balance_calibrator', domain, tmp_path, {})
    recorder = NodeProcess('balance_recorder', domain, tmp_path, {'output': str(tmp_path / 'bag')})
    try:
        # right after start: discovery of the two nodes' endpoints is under way
        listings = [ros(domain, 'service', 'list', '--timeout', 20)]
        _wait_for_service(domain, '/balance_calibrator/refit')  # both nodes are up
        _wait_for_service(domain, '/balance_recorder/list_parameters', 'ListParameters')
        listings += [ros(domain, 'service', 'list', '--timeout', 20) for _ in range(3)]
        nodes = ros(domain, 'node', 'list', '--timeout', 20)
        info = ros(domain, 'node', 'info', '/balance_calibrator', '--timeout', 20)
    finally:
        recorder.stop()
        calibrator.stop()
    expected = {
        f'/{node}/{name} [{kind}]'
        for node in ('balance_calibrator', 'balance_recorder')
        for name, kind in STANDARD_SERVICES.items()
    }
    expected |= {
        f'/balance_calibrator/{name} [std_srvs/srv/Trigger]'
        for name in ('tare', 'zero', 'clear_tare', 'refit')
    }
    assert listings[0].returncode == 0 and set(listings[0].stdout.splitlines()) <= expected
    for listing in listings[1:]:  # once the nodes are up: all of them, every time
        assert listing.returncode == 0, listing.stderr
        assert set(listing.stdout.splitlines()) == expected, sorted(
            set(listing.stdout.splitlines()) ^ expected
        )
    assert nodes.returncode == 0 and nodes.stdout.splitlines() == [
        '/balance_calibrator',
        '/balance_recorder',
    ]
    assert info.returncode == 0, info.stderr
    sections = {}
    for line in info.stdout.splitlines()[1:]:
        if line.startswith('  ') and not line.startswith('    '):
            current = sections.setdefault(line.strip().rstrip(':'), [])
        else:
            current.append(line.strip())
    assert info.stdout.splitlines()[0] == '/balance_calibrator'
    assert '/balance/raw: geometry_msgs/msg/WrenchStamped' in sections['Subscribers'], sections
    assert {
        '/balance/wrench: geometry_msgs/msg/WrenchStamped',
        '/balance/overload: std_msgs/msg/Bool',
        '/diagnostics: diagnostic_msgs/msg/DiagnosticArray',
    } <= set(sections['Publishers']), sections
    assert {
        line.replace(' [', ': ').rstrip(']')
        for line in expected
        if line.startswith('/balance_calibrator/')
    } == set(sections['Service Servers'])
    missing = ros(domain, 'node', 'info', '/no_such_node', '--timeout', 1)
    assert missing.returncode == 1 and 'node /no_such_node is not on the graph' in missing.stderr


@pytest.mark.ros
def test_topic_echo_into_a_pipe_closed_early_ends_without_a_traceback(tmp_path):
    domain = new_domain_id()
    publisher = NodeProcess(
        'bridge_publisher', domain, tmp_path, {'mode': 'wind_on', 'loop': True, 'rate_hz': 100.0}
    )
    try:
        echo = subprocess.Popen(
            [str(SCRIPTS / 'ros'), 'topic', 'echo', '/balance/raw', '--timeout', '60'],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=dict(os.environ, ROS_DOMAIN_ID=str(domain)),
        )
        head = [echo.stdout.readline() for _ in range(3)]  # what `| head -3` reads
        echo.stdout.close()
        status = echo.wait(60)
        errors = echo.stderr.read()
    finally:
        publisher.stop()
    assert head[0] == 'header:\n', head
    assert status == 0 and errors == '', errors


@pytest.mark.ros
def test_bag_play_into_bag_record_gives_back_the_campaign(tmp_path):
    config = load_balance_config('lmc6522')
    settings = SimulationSettings(
        samples_per_point=3,
        transition_samples=1,
        seed=7,
        point_duration_s=0.05,
        transition_s=0.02,
        sample_rate_hz=100.0,
    )
    original = write_campaign_bag(
        simulate_campaign(config, settings=settings), tmp_path / 'campaign', points=slice(0, 30)
    )
    domain = new_domain_id()
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    copy = tmp_path / 'copy'
    record = subprocess.Popen(
        [
            str(SCRIPTS / 'ros'),
            'bag',
            'record',
            str(copy),
            '/balance/raw',
            '/calibration/applied_load',
            '/calibration/gravity',
            '/balance/temperature',
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
    )
    try:
        played = ros(domain, 'bag', 'play', original, '--rate', '2', '--wait-for-subscribers', '1')
        assert played.returncode == 0, played.stdout + played.stderr
        assert 'campaign complete (replay' in played.stderr, played.stderr
    finally:
        record.send_signal(signal.SIGINT)
        recorded = record.communicate(timeout=60)[0]
    assert record.returncode == 0, recorded
    assert (copy / 'metadata.yaml').exists()
    before, after = read_bags([original]), read_bags([copy])
    for name in ('raw', 'applied_load', 'gravity', 'temperature'):
        a, b = getattr(before, name), getattr(after, name)
        assert len(a) == len(b) > 0, (name, len(a), len(b))
        np.testing.assert_array_equal(a.stamps_ns, b.stamps_ns)  # header stamps as recorded
        np.testing.assert_array_equal(a.values, b.values)  # NaN rows included
    bad = ros(domain, 'bag', 'play', tmp_path / 'nowhere')
    assert bad.returncode == 1 and 'nowhere: no such bag directory' in bad.stderr
