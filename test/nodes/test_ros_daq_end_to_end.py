"""The graph on an instrument: `balance-calib virtual-daq` -> balance_daq -> the rest, over DDS.

(a) A calibration campaign played through a TCP line device, recorded by balance_recorder and
    refitted by `balance-calib refit`, gives the calibration the same campaign (same seed, the
    same simulation bridge_publisher plays) gives from its bag, within the refit's own standard
    errors.
(b) A wind-on sweep played through the ATI RDT device over UDP reads, through balance_calibrator,
    the true loads within what the noise allows.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
import signal
import subprocess

from geometry_msgs.msg import WrenchStamped
import numpy as np
import pytest
from ros_harness import new_domain_id, NodeProcess, Probe, six, wait_for
from std_srvs.srv import Trigger

from balance_calib.bags.reader import read_bags
from balance_calib.calibration_file import load_calibration
from balance_calib.config import load_balance_config
from balance_calib.model.active_calibration import six_axis_loads
from balance_calib.model.inverse import linear_part
from balance_calib.simulation.balance_sim import (
    paced_settings,
    simulate_campaign,
    table17_noise,
)
from balance_calib.simulation.campaign_bag import write_campaign_bag
from balance_calib.simulation.virtual_device import bridge_fields, read_format

pytestmark = [pytest.mark.ros, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[2]
PRESETS = ROOT / 'config' / 'daq'
COMPONENTS = ('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ')


class VirtualDaqProcess:
    """`balance-calib virtual-daq ...` on a ROS domain, its output in log files."""

    def __init__(self, domain_id: int, log_dir: Path, args: list[str]):
        log_dir.mkdir(parents=True, exist_ok=True)
        self.log = log_dir / 'virtual_daq.log'
        self._out = open(self.log, 'w')
        self.process = subprocess.Popen(
            ['balance-calib', 'virtual-daq', *args],
            env=dict(os.environ, ROS_DOMAIN_ID=str(domain_id), PYTHONUNBUFFERED='1'),
            stdout=self._out,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )

    def output(self) -> str:
        self._out.flush()
        return self.log.read_text()

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=10)
        self._out.close()


def free_port(kind=None) -> int:
    import socket

    with socket.socket(socket.AF_INET, kind or socket.SOCK_STREAM) as probe:
        probe.bind(('127.0.0.1', 0))
        return probe.getsockname()[1]


def daq_args(preset: Path, device: str, rate_hz: float) -> list[str]:
    """balance_daq's arguments: the preset, then (later wins) this device and its rate."""
    return [
        '--params-file',
        str(preset),
        '-p',
        f'device:={device}',
        '-p',
        f'expected_rate_hz:={rate_hz}',
    ]


def refit(bag: Path, out: Path) -> dict:
    done = subprocess.run(
        ['balance-calib', 'refit', str(bag), '--balance', 'lmc6522', '--out', str(out)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    return json.loads((out / 'report.json').read_text())


def test_a_campaign_through_a_tcp_device_refits_to_the_simulators_calibration(tmp_path):
    preset = PRESETS / 'tcp_mvv.yaml'
    rate_hz, point_s, transition_s, seed, speed = 200.0, 0.06, 0.03, 5, 4.0
    config = load_balance_config('lmc6522')
    # the campaign bridge_publisher plays with these parameters (its calibration mode)
    campaign = simulate_campaign(
        config,
        config.matrices['cubic'],
        schedule=config.schedule,
        settings=paced_settings(rate_hz, point_s, transition_s, table17_noise(config), seed, 90.0),
    )
    reference = refit(write_campaign_bag(campaign, tmp_path / 'reference_bag'), tmp_path / 'ref')

    domain = new_domain_id()
    port = free_port()
    device = f'127.0.0.1:{port}'
    logs = tmp_path / 'logs'
    bag = tmp_path / 'daq_bag'
    probe = Probe(domain)
    raw = probe.subscribe(WrenchStamped, '/balance/raw')
    processes: list = []
    virtual = None
    try:
        processes.append(
            NodeProcess(
                'balance_daq',
                domain,
                logs,
                {},  # the preset first, then what this device needs
                daq_args(preset, device, rate_hz * speed),
            )
        )
        recorder = NodeProcess('balance_recorder', domain, logs, {'output': str(bag)})
        processes.append(recorder)
        # the device starts once balance_daq connects; by then the probe hears balance_daq
        wait_for(lambda: probe.node.count_publishers('/balance/raw') > 0, 30, 'balance_daq')
        virtual = VirtualDaqProcess(
            domain,
            logs,
            [
                '--transport',
                'tcp',
                '--device',
                device,
                '--format',
                str(preset),
                '--mode',
                'calibration',
                *('-p', f'rate_hz:={rate_hz}', '-p', f'point_duration_s:={point_s}'),
                *('-p', f'transition_s:={transition_s}', '-p', f'seed:={seed}'),
                *('-p', f'speed:={speed}', '-p', 'exit_when_done:=true'),
                *('-p', 'wait_for_subscribers:=1', '-p', 'start_delay_s:=1.0'),
            ],
        )
        assert virtual.process.wait(timeout=120) == 0, virtual.output()
        # every sample the device sent reached /balance/raw (TCP loses none)
        wait_for(lambda: len(raw) >= len(campaign.times_s), 20, 'the last samples')
        assert recorder.stop() == 0, recorder.output()
    finally:
        for process in reversed(processes):
            process.stop()
        if virtual is not None:
            virtual.stop()
        probe.close()

    # the simulator's own samples, through the device's unit (mV/V, nine digits) and back
    values = np.array([six(m) for m in raw])
    assert values.shape == campaign.raw_mv.shape
    assert np.allclose(values, campaign.raw_mv, rtol=1e-8, atol=1e-12)
    assert len(read_bags([bag]).raw) >= len(campaign.times_s) - 5  # the recorder kept them

    result = refit(bag, tmp_path / 'daq')
    assert result['points'] == reference['points'] == len(campaign.point)
    # Both calibrations read the campaign's own point means. Fitted on the same noisy samples
    # (the device path may lose a sample at a point's edge), they differ by far less than two
    # fits on independent noise would: those differ by sqrt(2)·σ·sqrt(p/n) RMS over the points
    # (σ the refit's eq. 44-49 σ, p/n the mean leverage of a least-squares fit of p terms to n
    # points). The bound: that RMS standard error σ·sqrt(p/n), and σ at any single point.
    means, _, _ = campaign.point_means()
    daq = load_calibration(tmp_path / 'daq' / 'calibration.yaml')
    ref = load_calibration(tmp_path / 'ref' / 'calibration.yaml')
    model = reference['base_model']
    difference = (
        (six_axis_loads(daq.model(model), means) - six_axis_loads(ref.model(model), means))
        / config.capacity
        * 100.0
    )
    terms = len(ref.model(model).terms)
    sigma = np.array([reference['sigma_pct_fs']['before'][c] for c in COMPONENTS])
    rms = np.sqrt(np.mean(difference**2, axis=0))
    assert np.all(rms <= sigma * np.sqrt(terms / len(means))), (rms, sigma)
    assert np.all(np.max(np.abs(difference), axis=0) <= sigma), difference
    assert result['effects'] == reference['effects'] == []


def held_means(truths, wrenches, edge_s: float):
    """Per held condition (truth constant and non-zero): the true load and the mean wrench over
    the samples stamped inside the hold, `edge_s` trimmed at both ends (the device path stamps
    on arrival, a few ms after the simulator's own stamp).
    """
    t_stamp = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in truths])
    t_value = np.array([six(m) for m in truths])
    w_stamp = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in wrenches])
    w_value = np.array([six(m) for m in wrenches])
    change = np.r_[True, np.any(np.diff(t_value, axis=0) != 0, axis=1)]
    starts = np.flatnonzero(change)
    ends = np.r_[starts[1:], len(t_value)] - 1
    rows = []
    for start, end in zip(starts, ends):
        if not np.any(t_value[start] != 0):
            continue  # wind off
        inside = (w_stamp > t_stamp[start] + edge_s) & (w_stamp < t_stamp[end] - edge_s)
        rows.append((t_value[start], w_value[inside].mean(axis=0), int(inside.sum())))
    return rows


def test_a_wind_on_sweep_through_the_rdt_device_reads_the_truth_within_the_noise(tmp_path):
    preset = PRESETS / 'netft_rdt.yaml'
    rate_hz, hold_s, wind_off_s, noise_pct_fs, tare_samples = 200.0, 0.5, 2.0, 0.005, 100
    config = load_balance_config('lmc6522')
    domain = new_domain_id()
    device = f'127.0.0.1:{free_port(__import__("socket").SOCK_DGRAM)}'
    logs = tmp_path / 'logs'
    probe = Probe(domain)
    truths = probe.subscribe(WrenchStamped, '/balance/truth')
    wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
    processes: list = []
    virtual = None
    try:
        processes.append(
            NodeProcess(
                'balance_calibrator',
                domain,
                logs,
                {'balance': 'lmc6522', 'tare_samples': tare_samples, 'publish_uncertainty': False},
            )
        )
        processes.append(
            NodeProcess('balance_daq', domain, logs, {}, daq_args(preset, device, rate_hz))
        )
        # the next 100 samples, wind off (the calibrator's and the probe's subscriptions may
        # match a little after the device starts streaming: the wind-off part gives them 2 s)
        zero = probe.call_async(Trigger, '/balance_calibrator/zero')
        virtual = VirtualDaqProcess(
            domain,
            logs,
            [
                '--transport',
                'udp',
                '--device',
                device,
                '--format',
                str(preset),
                '--mode',
                'wind_on',
                *('-p', f'rate_hz:={rate_hz}', '-p', f'hold_s:={hold_s}'),
                *('-p', f'wind_off_s:={wind_off_s}', '-p', 'alpha_step_deg:=4.0'),
                *('-p', f'noise_sigma_pct_fs:={noise_pct_fs}', '-p', 'exit_when_done:=true'),
                *('-p', 'wait_for_subscribers:=1', '-p', 'seed:=6'),
            ],
        )
        assert virtual.process.wait(timeout=120) == 0, virtual.output()
        wait_for(zero.done, 10, 'the ~/zero reply')
        assert zero.result().success, zero.result().message
        holds = 7 * round(hold_s * rate_hz)  # α = -2, 2, ..., 22°
        wait_for(lambda: min(len(truths), len(wrenches)) >= holds, 10, 'the held samples')
    finally:
        for process in reversed(processes):
            process.stop()
        if virtual is not None:
            virtual.stop()
        probe.close()

    rows = held_means(truths, wrenches, edge_s=0.02)
    assert len(rows) == 7  # α = -2, 2, ..., 22°
    truth = np.array([r[0] for r in rows])
    measured = np.array([r[1] for r in rows])
    samples = np.array([r[2] for r in rows])
    samples_per_hold = round(hold_s * rate_hz)
    assert np.all(samples >= 0.8 * samples_per_hold), samples  # 20 ms trimmed at each end
    # the noise bridge_publisher's wind-on mode gives: σ of a hold's mean = noise_pct_fs, i.e.
    # per sample noise_pct_fs·sqrt(samples_per_hold); the mean of n samples, the ~/zero's mean
    # of tare_samples, and the device's counts (a count/sqrt(12) per sample, through the
    # linear part of the calibration) add in quadrature
    per_sample = noise_pct_fs * np.sqrt(samples_per_hold)
    rdt = read_format(preset)
    count_mv = np.abs(np.asarray(rdt.counts_to_mv)) * np.ones(6)
    assert np.allclose(bridge_fields(count_mv, rdt), 1.0)  # one count
    truth_model = config.matrices['cubic'].without_constant()
    linear = linear_part(truth_model)  # N (N·m) per mV, the first-order terms
    quantisation_pct = np.sqrt((linear**2) @ (count_mv**2 / 12.0)) / config.capacity * 100.0
    sigma = np.sqrt(
        (per_sample**2 + quantisation_pct**2) / samples[:, None]
        + (per_sample**2 + quantisation_pct**2) / tare_samples
    )
    error = (measured - truth) / config.capacity * 100.0
    assert np.all(np.abs(error) <= 4.0 * sigma), np.round(error / sigma, 2)
    # not trivially: the sweep loads the balance by more than 10 % FS on some component
    assert np.max(np.abs(truth) / config.capacity) > 0.1
