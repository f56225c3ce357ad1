"""launchless_scripts/ros: the ros2 CLI habits (param, topic, service, bag info) over real DDS."""
import os
import subprocess
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader

from balance_calib.config import load_balance_config
from balance_calib.launchless.ros_tools import format_bag_info
from balance_calib.simulation.balance_sim import SimulationSettings, simulate_campaign
from balance_calib.simulation.campaign_bag import write_campaign_bag
from ros_harness import NodeProcess, new_domain_id

SCRIPTS = Path(__file__).resolve().parent.parent / 'launchless_scripts'


def ros(domain, *args, timeout=120):
    return subprocess.run([str(SCRIPTS / 'ros'), *map(str, args)], capture_output=True, text=True, timeout=timeout,
                          env=dict(os.environ, ROS_DOMAIN_ID=str(domain)))


@pytest.mark.ros
def test_param_topic_and_service_verbs_on_a_running_calibrator(tmp_path):
    domain = new_domain_id()
    calibrator = NodeProcess('balance_calibrator', domain, tmp_path,
                             {'diagnostics_period_s': 0.2, 'tare_samples': 20, 'tare_timeout_s': 1.0})
    try:
        # the new user's dead end of the issue: refit with calibration_bags empty -> set it, read it back
        done = ros(domain, 'param', 'set', '/balance_calibrator', 'calibration_bags', '[bags/a, bags/b]',
                   '--timeout', 60)
        assert done.returncode == 0, done.stderr + calibrator.output()
        assert done.stdout.strip() == 'Set parameter successful'
        done = ros(domain, 'param', 'get', '/balance_calibrator', 'calibration_bags', '--timeout', 60)
        assert done.returncode == 0, done.stderr
        assert done.stdout.strip() == "String array value is: ['bags/a', 'bags/b']"
        # one path for a string-array parameter: a one-element list; a double stays a double
        assert ros(domain, 'param', 'set', '/balance_calibrator', 'calibration_bags', 'bags/c').returncode == 0
        assert ros(domain, 'param', 'get', '/balance_calibrator', 'calibration_bags').stdout.strip() == \
            "String array value is: ['bags/c']"
        assert ros(domain, 'param', 'set', '/balance_calibrator', 'envelope_margin', '2').returncode == 0
        assert ros(domain, 'param', 'get', '/balance_calibrator', 'envelope_margin').stdout.strip() == \
            'Double value is: 2.0'
        wrong = ros(domain, 'param', 'set', '/balance_calibrator', 'envelope_margin', 'wide')
        assert wrong.returncode == 1 and 'is not a double' in wrong.stderr
        listed = ros(domain, 'param', 'list', '/balance_calibrator')
        assert {'calibration_bags', 'envelope_margin', 'model', 'installation'} <= set(listed.stdout.split())

        echoed = ros(domain, 'topic', 'echo', '/diagnostics', '--count', '2', '--timeout', 60)
        assert echoed.returncode == 0, echoed.stderr
        documents = [d for d in yaml.safe_load_all(echoed.stdout) if d]
        assert len(documents) == 2
        assert any(status['name'].startswith('balance_calibrator') for status in documents[0]['status'])

        rate = ros(domain, 'topic', 'hz', '/diagnostics', '--duration', '3', '--timeout', 60)
        assert rate.returncode == 0, rate.stderr
        hz = float(rate.stdout.split('average rate:')[1].split()[0])
        assert 1.0 < hz < 25.0         # a 0.2 s period, within any scheduling a busy machine gives

        called = ros(domain, 'service', 'call', '/balance_calibrator/tare', '--timeout', 60)
        assert called.returncode == 1          # no samples flowing: the tare must refuse
        assert called.stdout.startswith('success: false\nmessage: ')
    finally:
        calibrator.stop()
    missing = ros(domain, 'param', 'get', '/no_such_node', 'x', '--timeout', 1)
    assert missing.returncode == 1 and 'service /no_such_node/get_parameters is not available' in missing.stderr


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
    # the raw samples: 3 per point plus the transition samples, per the simulation's own bookkeeping
    points = len(campaign.point)
    assert counts['/balance/raw'] >= 3 * points
    assert f'Duration:          {(max(log_times) - min(log_times)) / 1e9:.3f}s' in info
