"""launchless_scripts/windon: a wind-on run recorded over DDS into the bag `reduce` takes; a
publisher waiting for subscribers that never come gives up with one line; the recorder's defaults
cover every topic of the interface contract.
"""

import csv
import os
from pathlib import Path
import re
import subprocess
import time

import numpy as np
import pytest
from ros_harness import new_domain_id, NodeProcess

from balance_calib.aero.pipeline import reduce_bags
from balance_calib.bags.reader import read_bags
from balance_calib.nodes.balance_recorder import DEFAULT_TOPICS

ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = ROOT / 'launchless_scripts'
INTERFACES = ROOT.parent / 'shared' / 'docs' / 'interfaces.md'
COEFFICIENTS = ('CAF', 'CY', 'CN', 'Cl', 'Cm', 'Cn')
ALPHAS_DEG = (-2.0, 4.0, 10.0, 16.0, 22.0)


def interface_topics(text: str) -> set[str]:
    """Every topic named in the first column of a topics table, and the uncertainty topic."""
    rows = re.findall(r'^\| `(/[a-z_/]+)` \| `[a-z_]+/msg/', text, re.M)
    return set(rows) | set(re.findall(r'`(/balance/wrench_uncertainty)`', text))


def test_recorder_defaults_cover_every_topic_of_the_interface_contract():
    if not INTERFACES.exists():  # outside the project's checkout of ../shared
        pytest.skip(f'{INTERFACES} not found')
    topics = interface_topics(INTERFACES.read_text())
    assert len(topics) >= 12, topics
    assert topics <= set(DEFAULT_TOPICS), sorted(topics - set(DEFAULT_TOPICS))


@pytest.mark.ros
def test_windon_records_a_bag_that_reduce_turns_into_the_true_coefficients(tmp_path):
    bag = tmp_path / 'run'
    started = time.monotonic()
    done = subprocess.run(
        [
            str(SCRIPTS / 'windon'),
            str(bag),
            '--alpha-deg=-2,22,6',
            '--hold-s',
            '0.3',
            '--wind-off-hold-s',
            '0.1',
            '--noise-pct-fs',
            '0.005',
            '--seed',
            '4',
        ],
        capture_output=True,
        text=True,
        timeout=120,
        env=dict(os.environ, ROS_DOMAIN_ID=str(new_domain_id())),
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert time.monotonic() - started < 60
    assert 'Traceback' not in done.stderr and '[WARN]' not in done.stderr + done.stdout, (
        done.stderr
    )
    command = done.stdout.strip().splitlines()[-1].split('reduce it with: ')[1].split()
    assert command[:3] == ['balance-calib', 'reduce', str(bag)]
    assert (bag / 'metadata.yaml').exists()
    # 200 Hz: 12 wind-off attitudes of 0.1 s before and after 5 wind-on holds of 0.3 s
    data = read_bags(
        [bag], extra_topics=['/model/attitude', '/tunnel/dynamic_pressure', '/aero/truth']
    )
    assert len(data.raw) == 24 * 20 + 5 * 60
    assert (
        len(data.extra['/model/attitude'])
        == len(data.extra['/tunnel/dynamic_pressure'])
        == len(data.raw)
    )

    reduced = subprocess.run(command, capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert reduced.returncode == 0, reduced.stderr
    assert reduced.stderr == ''
    # the calibrator's ~/zero, taken before the run and stated in the bag's /diagnostics, is
    # subtracted in output space: no offset warning; the sweeps bracket the drift: none here
    assert 'warning' not in reduced.stdout, reduced.stdout
    zero_line = next(line for line in reduced.stdout.splitlines() if 'electrical zero' in line)
    zero = [float(v.split()[1]) for v in zero_line.split(': ', 1)[1].split(' mV')[0].split(', ')]
    # bridge_publisher's electrical_zero_mv (0.04 mV), to the noise of 100 samples
    assert np.allclose(zero, 0.04, atol=2e-3), zero_line
    assert "balance_calibrator's ~/zero" in zero_line
    assert 'zero drift (cubic): shift post − pre % FS' in reduced.stdout
    assert list(tmp_path.glob('*.tare.yaml')) == []  # the zero left nothing in the directory
    with open(
        Path(command[command.index('--out') + 1]) / 'coefficients.csv', newline=''
    ) as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == len(ALPHAS_DEG)
    # the deflection-corrected α: the support's α plus a few hundredths of a degree under load
    alpha = np.array([float(r['alpha_deg']) for r in rows])
    assert np.all(np.abs(alpha - ALPHAS_DEG) < 0.2), alpha
    reduced_body = np.array([[float(r[c]) for c in COEFFICIENTS] for r in rows])
    # the simulation's true coefficients, one value per hold (constant within it), in time order
    truth = np.array(
        [
            [
                m.wrench.force.x,
                m.wrench.force.y,
                m.wrench.force.z,
                m.wrench.torque.x,
                m.wrench.torque.y,
                m.wrench.torque.z,
            ]
            for m in data.extra['/aero/truth'].messages
        ]
    )
    holds = truth[np.r_[True, np.any(np.diff(truth, axis=0) != 0, axis=1)]]
    assert len(holds) == len(ALPHAS_DEG)
    u = np.array(
        [
            p.uncertainty_body
            for p in reduce_bags([bag], 'lmc6522', 'euler_replica_lmc6522').main.result.wind_on
        ]
    )
    ratio = np.abs(reduced_body - holds) / u
    assert np.max(ratio) < 4.5, ratio
    # and not trivially: C_N grows with α by more than 1 over the sweep
    assert reduced_body[-1, 2] - reduced_body[0, 2] > 1.0


@pytest.mark.ros
def test_publisher_waiting_for_subscribers_gives_up_with_one_line(tmp_path):
    publisher = NodeProcess(
        'bridge_publisher',
        new_domain_id(),
        tmp_path,
        {
            'mode': 'wind_on',
            'aero_model': 'euler_replica_lmc6522',
            'wait_for_subscribers': 1,
            'wait_for_subscribers_timeout_s': 1.5,
            'exit_when_done': True,
        },
    )
    started = time.monotonic()
    try:
        status = publisher.wait(30.0)
    finally:
        output = publisher.output()
        publisher.stop()
    waited = time.monotonic() - started
    assert status == 1, output
    assert 1.5 < waited < 20.0
    errors = [line for line in output.splitlines() if '[ERROR]' in line]
    assert (
        len(errors) == 1
        and 'gave up after 1.5 s waiting for 1 subscriber(s) on /balance/raw' in errors[0]
    ), output
    assert '/balance/raw 0' in errors[0] and 'Traceback' not in output
