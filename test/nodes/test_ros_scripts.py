"""launchless_scripts/trigger and launchless_scripts/graph, run as a user runs them."""

import os
from pathlib import Path
import re
import signal
import subprocess
import threading

from geometry_msgs.msg import WrenchStamped
import pytest
from ros_harness import new_domain_id, NodeProcess, Probe, wait_for
import yaml

pytestmark = pytest.mark.ros
SCRIPTS = Path(__file__).resolve().parents[2] / 'launchless_scripts'


def run_trigger(domain, *args, timeout=60):
    return subprocess.run(
        [str(SCRIPTS / 'trigger'), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=dict(os.environ, ROS_DOMAIN_ID=str(domain)),
    )


def test_trigger_prints_the_reply_and_exits_by_success(tmp_path):
    domain = new_domain_id()
    calibrator = NodeProcess(
        'balance_calibrator', domain, tmp_path, {'tare_samples': 20, 'tare_timeout_s': 1.0}
    )
    try:
        # no samples: tare fails
        failed = run_trigger(domain, '/balance_calibrator/tare', '--timeout', '30')
        assert failed.returncode == 1, failed.stderr
        assert failed.stdout.startswith('success: false\nmessage: tare failed: only 0 of 20')
        probe = Probe(domain)
        wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
        # a long wind-off hold: ~/tare refuses a window taken while the α sweep moves the loads
        publisher = NodeProcess(
            'bridge_publisher',
            domain,
            tmp_path,
            {'mode': 'wind_on', 'loop': True, 'rate_hz': 100.0, 'wind_off_s': 60.0},
        )
        try:
            # the tare waits only tare_timeout_s = 1 s: let the publisher start streaming first
            wait_for(lambda: len(wrenches) > 0, 30.0, 'samples through the calibrator')
            done = run_trigger(domain, '/balance_calibrator/tare', '--timeout', '30')
        finally:
            publisher.stop()
            probe.close()
        assert done.returncode == 0, done.stdout + done.stderr
        assert done.stdout.startswith('success: true\nmessage: tare: averaged 20 samples')
    finally:
        calibrator.stop()
    missing = run_trigger(domain, '/no_such_node/refit', '--timeout', '1')
    assert (
        missing.returncode == 1
        and 'service /no_such_node/refit is not in the graph' in missing.stderr
        and len(missing.stderr.strip().splitlines()) == 1
    )


def graph_params(tmp_path, **calibrator):
    params = yaml.safe_load((SCRIPTS.parent / 'config' / 'graph_params.yaml').read_text())
    params['bridge_publisher']['ros__parameters'].update(
        mode='wind_on', rate_hz=100.0, wind_off_s=0.5, hold_s=0.2, alpha_step_deg=12.0
    )
    params['balance_calibrator']['ros__parameters'].update(calibrator)
    path = tmp_path / 'params.yaml'
    path.write_text(yaml.safe_dump(params))
    return path


def start_graph(tmp_path, params, *args):
    """The graph script; its output lines are collected in graph.lines as they come."""
    graph = subprocess.Popen(
        [str(SCRIPTS / 'graph'), str(params), '--bag', str(tmp_path / 'bag'), *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
        env=dict(os.environ, ROS_DOMAIN_ID=str(new_domain_id())),
    )
    graph.lines = []
    graph.reader = threading.Thread(target=lambda: graph.lines.extend(graph.stdout), daemon=True)
    graph.reader.start()
    return graph


def stop_graph(graph):
    if graph.poll() is None:
        os.killpg(graph.pid, signal.SIGKILL)
        graph.wait(30)
    graph.reader.join(30)
    return ''.join(graph.lines)


def test_graph_runs_the_nodes_and_ends_with_the_publisher_closing_the_bag(tmp_path):
    # By default the calibrator outlives the campaign; --stop-with-campaign ends them all
    graph = start_graph(tmp_path, graph_params(tmp_path), '--stop-with-campaign')
    try:
        assert graph.wait(90) == 0
    finally:
        output = stop_graph(graph)
    assert 'campaign complete' in output and 'bridge_publisher exited with status 0' in output, (
        output
    )
    assert f'bag {tmp_path / "bag"} closed (status 0)' in output, output
    metadata = yaml.safe_load((tmp_path / 'bag' / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information'
    ]
    counts = {
        t['topic_metadata']['name']: t['message_count']
        for t in metadata['topics_with_message_count']
    }
    assert counts['/balance/raw'] == 50 + 3 * 20 and counts['/balance/wrench'] > 0, counts


def test_graph_on_a_virtual_serial_device_records_the_campaign_through_balance_daq(tmp_path):
    """--daq serial_counts --virtual: the params file's campaign (ten points) played as a
    microcontroller printing counts on a pty, read by balance_daq; its end ends the graph.
    """
    params = yaml.safe_load((SCRIPTS.parent / 'config' / 'graph_params.yaml').read_text())
    params['bridge_publisher']['ros__parameters'].update(points='1-10')
    path = tmp_path / 'params.yaml'
    path.write_text(yaml.safe_dump(params))
    graph = start_graph(
        tmp_path, path, '--daq', 'serial_counts', '--virtual', '--stop-with-campaign'
    )
    try:
        assert graph.wait(90) == 0
    finally:
        output = stop_graph(graph)
    assert 'virtual-daq exited with status 0 (campaign done)' in output, output
    assert re.search(r'started balance_daq', output) and 'bridge_publisher' not in output
    metadata = yaml.safe_load((tmp_path / 'bag' / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information'
    ]
    counts = {
        t['topic_metadata']['name']: t['message_count']
        for t in metadata['topics_with_message_count']
    }
    # 200 Hz, 0.1 s a point + 0.03 s of weights changing: 26 samples a point, every one through
    # the pty; each point's applied load and the all-NaN one before it
    assert counts['/balance/raw'] == 10 * 26 and counts['/calibration/applied_load'] == 20, counts


def test_graph_forwards_sigterm_and_stops_every_node(tmp_path):
    params = graph_params(tmp_path)
    data = yaml.safe_load(params.read_text())
    data['bridge_publisher']['ros__parameters'].update(loop=True, exit_when_done=False)
    params.write_text(yaml.safe_dump(data))
    graph = start_graph(tmp_path, params)
    try:
        wait_for(
            lambda: any('campaign complete' in line for line in graph.lines), 30.0, 'a first cycle'
        )
        graph.send_signal(signal.SIGTERM)
        assert graph.wait(30) == 0
    finally:
        output = stop_graph(graph)
    pids = [int(p) for p in re.findall(r'started \w+ \(pid (\d+)\)', output)]
    assert len(pids) == 3, output
    for pid in pids:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)
    assert (tmp_path / 'bag' / 'metadata.yaml').exists()  # the recorder closed its bag


def test_graph_stops_everything_when_a_node_dies(tmp_path):
    broken = tmp_path / 'broken.yaml'
    broken.write_text('models: [\n')
    graph = start_graph(
        tmp_path, graph_params(tmp_path, calibration_file=str(broken)), '--no-recorder'
    )
    try:
        assert graph.wait(60) == 1
    finally:
        output = stop_graph(graph)
    assert 'balance_calibrator exited with status 1' in output and 'broken.yaml' in output, output


def run_ros(domain, *args, timeout=300):
    return subprocess.run(
        [str(SCRIPTS / 'ros'), *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=dict(os.environ, ROS_DOMAIN_ID=str(domain)),
    )


@pytest.mark.slow
def test_graph_as_its_help_says_the_calibrator_outlives_the_campaign_and_refits_its_bag(tmp_path):
    """The help's recipe: campaign through the graph, then param set calibration_bags to the
    recorded bag directory and trigger ~/refit, while the graph still runs.
    """
    params = yaml.safe_load((SCRIPTS.parent / 'config' / 'graph_params.yaml').read_text())
    params['bridge_publisher']['ros__parameters'].update(speed=4.0)  # the shipped campaign, 4x
    params['balance_calibrator']['ros__parameters'].update(report_dir=str(tmp_path / 'reports'))
    path = tmp_path / 'params.yaml'
    path.write_text(yaml.safe_dump(params))
    domain = new_domain_id()
    graph = subprocess.Popen(
        [str(SCRIPTS / 'graph'), str(path), '--bag', str(tmp_path / 'bag')],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
        env=dict(os.environ, ROS_DOMAIN_ID=str(domain)),
    )
    graph.lines = []
    graph.reader = threading.Thread(target=lambda: graph.lines.extend(graph.stdout), daemon=True)
    graph.reader.start()
    try:
        wait_for(
            lambda: (
                any('keeps running' in line for line in graph.lines) or graph.poll() is not None
            ),
            150.0,
            'the end of the campaign',
        )
        assert graph.poll() is None, ''.join(graph.lines)  # the calibrator still runs
        assert (tmp_path / 'bag' / 'metadata.yaml').exists()  # the recorder closed the bag
        done = run_ros(
            domain,
            'param',
            'set',
            '/balance_calibrator',
            'calibration_bags',
            f'[{tmp_path / "bag"}]',
            '--timeout',
            60,
        )
        assert done.returncode == 0, done.stderr
        refit = run_ros(domain, 'service', 'call', '/balance_calibrator/refit')
        assert refit.returncode == 0, refit.stdout + refit.stderr + ''.join(graph.lines)
        assert refit.stdout.startswith('success: true'), refit.stdout
        graph.send_signal(signal.SIGINT)
        assert graph.wait(30) == 0
    finally:
        output = stop_graph(graph)
    assert 'balance_calibrator keeps running' in output and 'Traceback' not in output, output
