"""balance_daq over real DDS against fake devices (fake_devices.py): every kind of bad input in
one scripted run per transport, each said by its counter in /diagnostics, none published as a
wrong number, none stopping the node; and bad parameters refused at start-up in one line.

Runs are grouped to keep DDS time small: a TCP line device and a refusing TCP peer share a
domain; an ATI RDT sensor over UDP and a serial pty (each with its shipped preset) share another.
"""

from __future__ import annotations

import os
from pathlib import Path
import subprocess
import time

from diagnostic_msgs.msg import DiagnosticArray
from fake_devices import (
    PtyDevice,
    rdt_record,
    RDT_START,
    RDT_STOP,
    RdtDevice,
    refused_tcp_address,
    TcpDevice,
)
from geometry_msgs.msg import WrenchStamped
import pytest
from ros_harness import new_domain_id, NodeProcess, Probe, six, wait_for
from sensor_msgs.msg import Temperature
import yaml

pytestmark = pytest.mark.ros

ROOT = Path(__file__).resolve().parents[2]
BRIDGES = ['FXV', 'FYV', 'FZV', 'MXV', 'MYV', 'MZV']
ERROR = b'\x02'


def statuses(diagnostics: list, name: str) -> list:
    """(level, message, values) of every status named `name`, oldest first."""
    return [
        (status.level, status.message, {kv.key: kv.value for kv in status.values})
        for array in list(diagnostics)
        for status in array.status
        if status.name == name
    ]


def latest(diagnostics: list, name: str) -> dict:
    found = statuses(diagnostics, name)
    return found[-1][2] if found else {}


def stamp_ns(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def warm_up(send, received: list, timeout_s: float = 20.0) -> tuple[int, int]:
    """Send good samples (send(n), n = 1, 2, ...: FXV = n) until the probe receives one, so the
    node's writer has matched the probe's reader; then wait for the last one sent (a reliable
    writer delivers everything after the first sample received).

    -> (samples sent, samples received): those before the match may be lost to the probe.
    """
    sent = 0
    for _ in range(int(timeout_s / 0.25)):
        sent += 1
        send(sent)
        try:
            wait_for(lambda: received, 0.25, 'a warm-up sample')
            break
        except AssertionError:
            continue
    wait_for(
        lambda: received and abs(six(received[-1])[0] - sent) < 1e-3, 10.0, 'the last warm-up'
    )
    return sent, len(received)


# --- a text-line device over TCP, and a peer that refuses --------------------------------------
def line(seq: int, time_s: float, status: int = 0, fx: str | None = None) -> bytes:
    """seq, FXV ... MZV (mV), status, temperature, time: FXV = seq unless given."""
    bridges = [fx if fx is not None else str(seq), str(-seq / 2), '0.25', '1e-3', '-7.5', '42']
    return (
        ','.join([str(seq)] + bridges + [str(status), f'{20 + seq / 100:g}', f'{time_s:.6f}'])
        + '\n'
    ).encode()


# device time: a microsecond a sample, slower than any delivery here, so that the stamps it carries
# stay behind the host's clock (a device faster than the host would be held to strictly
# increasing stamps instead)
US = 1e-6


def expected(seq: int) -> list[float]:
    return [float(seq), -seq / 2, 0.25, 1e-3, -7.5, 42.0]


def test_a_tcp_line_device_survives_every_bad_input_and_a_refusing_peer_is_retried(tmp_path):
    domain = new_domain_id()
    device = TcpDevice()
    refused = refused_tcp_address()
    probe = Probe(domain)
    nodes = []
    try:
        raw = probe.subscribe(WrenchStamped, '/balance/raw')
        temperature = probe.subscribe(Temperature, '/balance/temperature')
        diagnostics = probe.subscribe(DiagnosticArray, '/diagnostics')
        columns = ['seq'] + BRIDGES + ['status', 'temperature', 'time']
        nodes.append(
            NodeProcess(
                'balance_daq',
                domain,
                tmp_path,
                {
                    'transport': 'tcp',
                    'device': device.address,
                    'columns': columns,
                    'saturation': '[1000.0]',
                    'reconnect_period_s': 0.3,
                    'expected_rate_hz': 10.0,
                },
            )
        )
        nodes.append(
            NodeProcess(
                'balance_daq',
                domain,
                tmp_path,
                {'transport': 'tcp', 'device': refused, 'reconnect_period_s': 0.2},
                ['-r', '__node:=balance_daq_refused', '-r', '/balance/raw:=/refused/raw'],
            )
        )
        device.wait_client(1)
        warm, seen = warm_up(lambda seq: device.send(line(seq, seq * US)), raw)
        s = warm  # seq of the last sample sent; the device's time is seq microseconds
        script = [
            line(s + 1, (s + 1) * US),  # published
            b'\x00\x17garbage\xff\xfe,,\n',  # random bytes: malformed
            b'\xff\xfe\xfd 1 2 3 4 5 6 7 8 9 10\n',  # not UTF-8: malformed
            f'{s + 2},1,2\n'.encode(),  # short: malformed
            b','.join([b'1'] * 12) + b'\n',  # long: malformed
            b'9' * 5000 + b'\n',  # longer than any line may be: malformed
            line(s + 2, (s + 2) * US, fx='nan'),  # malformed
            line(s + 2, (s + 2) * US, fx='-inf'),  # malformed
            line(s + 2, (s + 2) * US, status=3),  # invalid (status flag)
            line(s + 3, (s + 3) * US, fx='1500'),  # saturated (|FXV| reaches 1000)
            line(s + 4, (s + 4) * US),  # published
            line(s + 7, (s + 7) * US),  # published; s + 5 and s + 6 missing
            line(s + 7, (s + 7) * US),  # duplicate
            line(s + 6, (s + 6) * US),  # late: duplicate
            line(s + 8, (s + 8) * US + 5.0),  # published; device time jumps 5 s: re-fixed
            line(s + 9, (s + 9) * US + 5.0),  # published, 1 us after
            line(s + 10, 0.0)[:9],  # cut by the device closing: malformed
        ]
        sent_ns = time.time_ns()  # ROS time is the system clock here
        device.send(b''.join(script))
        wait_for(lambda: len(raw) == seen + 5, 10.0, 'the five good samples of the script')
        received_ns = time.time_ns()
        device.drop()
        device.wait_client(2)
        device.send(line(900, 20.0) + line(901, 20.01))  # after a reconnect: counts afresh
        wait_for(lambda: len(raw) == seen + 7, 10.0, 'the samples after the reconnect')
        sent = list(range(warm - seen + 1, warm + 1)) + [
            s + 1,
            s + 4,
            s + 7,
            s + 8,
            s + 9,
            900,
            901,
        ]
        assert [six(m) for m in raw] == [expected(seq) for seq in sent]
        assert {m.header.frame_id for m in raw} == {'balance'}
        stamps = [stamp_ns(m) for m in raw]
        assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
        # the device's spacing kept (1 us, 3 us over the gap), re-fixed after the jump
        at = dict(zip(sent, stamps))
        assert at[s + 4] - at[s + 1] == 3_000 and at[s + 9] - at[s + 8] == 1_000
        # the jump re-fixed the offset: s + 8 is stamped with its arrival, not 5 s after s + 7
        assert sent_ns <= at[s + 8] <= received_ns and at[s + 8] - at[s + 7] != 5_000_001_000
        # one temperature per published sample, with its header (the script's seven)
        wait_for(
            lambda: temperature and stamp_ns(temperature[-1]) == stamps[-1], 10.0, 'temperatures'
        )
        assert [stamp_ns(m) for m in temperature[-8:]] == stamps[-8:]
        assert [m.temperature for m in temperature[-8:]] == pytest.approx(
            [20 + q / 100 for q in sent[-8:]]
        )
        name = f'balance_daq: {device.address}'
        want = {
            'samples_published': str(warm + 7),
            'records_malformed': '8',
            'samples_invalid': '1',
            'samples_saturated': '1',
            'samples_missing': '2',
            'samples_duplicate': '2',
            'reconnects': '1',
            'connected': 'true',
        }
        wait_for(
            lambda: all(latest(diagnostics, name).get(k) == v for k, v in want.items()),
            10.0,
            f'the counters {want} (last: {latest(diagnostics, name)})',
        )
        said = statuses(diagnostics, name)
        assert any(level == ERROR and 'saturated' in message for level, message, _ in said)
        assert any('dropped' in message for _, message, _ in said)
        assert any('device time jumped 1 time(s)' in message for _, message, _ in said)
        # the refusing peer: retried every period, never connected, never exited
        other = f'balance_daq: {refused}'
        wait_for(
            lambda: int(latest(diagnostics, other).get('reconnects', 0)) >= 3,
            10.0,
            'the refused node to retry',
        )
        level, message, values = statuses(diagnostics, other)[-1]
        assert level == ERROR and values['connected'] == 'false' and 'disconnected' in message
        assert all(node.process.poll() is None for node in nodes)
    finally:
        for node in nodes:
            node.stop()
        probe.close()
        device.close()
    # said at most once a second, although tried every 0.2 s
    said_at = [
        float(text.split('] [', 2)[1])
        for text in nodes[1].output().splitlines()
        if 'cannot reach' in text
    ]
    assert said_at and all(b - a >= 0.99 for a, b in zip(said_at, said_at[1:])), said_at


# --- ATI RDT over UDP and a serial port, with the shipped presets -------------------------------
def in_namespace(preset: Path, directory: Path) -> Path:
    """The preset's parameters for /serial/balance_daq (a params file names the node)."""
    values = yaml.safe_load(preset.read_text())['balance_daq']
    path = directory / f'serial_{preset.name}'
    path.write_text(yaml.safe_dump({'/serial/balance_daq': values}))
    return path


def test_rdt_and_serial_presets_a_deaf_sensor_is_asked_again_bursts_and_flags(tmp_path):
    domain = new_domain_id()
    sensor = RdtDevice(deaf_requests=2)
    pty = PtyDevice()
    pty.write(b'7,-8\n')  # before the port opens: a tail, dropped uncounted
    probe = Probe(domain)
    nodes = []
    try:
        rdt_raw = probe.subscribe(WrenchStamped, '/balance/raw')
        serial_raw = probe.subscribe(WrenchStamped, '/serial/raw')
        diagnostics = probe.subscribe(DiagnosticArray, '/diagnostics')
        nodes.append(
            NodeProcess(
                'balance_daq',
                domain,
                tmp_path,
                {},
                [
                    '--params-file',
                    str(ROOT / 'config' / 'daq' / 'netft_rdt.yaml'),
                    '-p',
                    f'device:={sensor.address}',
                    '-p',
                    'reconnect_period_s:=0.3',
                ],
            )
        )
        nodes.append(
            NodeProcess(
                'balance_daq',
                domain,
                tmp_path,
                {},
                [
                    '--params-file',
                    str(in_namespace(ROOT / 'config' / 'daq' / 'serial_counts.yaml', tmp_path)),
                    '-p',
                    f'device:={pty.path}',
                    '-r',
                    '__ns:=/serial',
                    '-r',
                    '/balance/raw:=/serial/raw',
                ],
            )
        )
        sensor.wait_streaming()
        assert sensor.requests[:3] == [(RDT_START, 0)] * 3  # the first two went unanswered
        rdt = f'balance_daq: {sensor.address}'
        wait_for(
            lambda: int(latest(diagnostics, rdt).get('reconnects', 0)) >= 2,
            10.0,
            'the resent requests counted',
        )
        warm, seen = warm_up(lambda n: sensor.send(rdt_record(n, n, 0, [n * 10**6] * 6)), rdt_raw)
        s = warm
        burst = b''.join(
            rdt_record(s + k, 7, 0, [1_000_000 * k, -k, 0, 0, 0, 2**31 - 1]) for k in (1, 2, 3)
        )
        sensor.send(
            burst,  # three records in one datagram
            rdt_record(s + 4, 7, 0x0002_0000, [5] * 6),  # status flag: invalid
            rdt_record(s + 6, 7, 0, [6] * 6),  # s + 5 missing
            rdt_record(s + 6, 7, 0, [6] * 6),  # duplicate
            bytes(35),  # not a whole record: malformed
        )
        wait_for(lambda: len(rdt_raw) == seen + 4, 10.0, 'the RDT samples')
        got = [six(m) for m in rdt_raw[seen:]]
        scale = 1e-6  # the preset's placeholder counts_to_mv
        assert got == [
            [1_000_000 * k * scale, -k * scale, 0.0, 0.0, 0.0, (2**31 - 1) * scale]
            for k in (1, 2, 3)
        ] + [[6 * scale] * 6]
        want = {
            'samples_published': str(warm + 4),
            'records_malformed': '1',
            'samples_invalid': '1',
            'samples_missing': '1',
            'samples_duplicate': '1',
            'connected': 'true',
        }
        wait_for(
            lambda: all(latest(diagnostics, rdt).get(k) == v for k, v in want.items()),
            10.0,
            f'the RDT counters {want} (last: {latest(diagnostics, rdt)})',
        )
        # the serial device: counts of a 24-bit converter, one saturated
        serial = f'balance_daq: {pty.path}'
        mv = 2.3283064365386963e-06  # the preset's mV per count
        wait_for(lambda: latest(diagnostics, serial).get('connected') == 'true', 10.0, 'serial')
        _, seen = warm_up(lambda n: pty.write(b'%d 0 0 0 0 0\r\n' % round(n / mv)), serial_raw)
        pty.write(b'HX711 ready\r\n1000000,-2000000,3,4,5,6\r\n8388607,0,0,0,0,0\r\n')
        wait_for(lambda: len(serial_raw) == seen + 1, 10.0, 'the serial sample')
        assert six(serial_raw[-1]) == [1e6 * mv, -2e6 * mv, 3 * mv, 4 * mv, 5 * mv, 6 * mv]
        wait_for(
            lambda: (
                latest(diagnostics, serial).get('samples_saturated') == '1'
                and latest(diagnostics, serial).get('records_malformed') == '1'
            ),  # the banner
            10.0,
            f'the serial counters (last: {latest(diagnostics, serial)})',
        )
    finally:
        for node in nodes:
            node.stop()
        probe.close()
        pty.close()
    wait_for(lambda: sensor.requests[-1] == (RDT_STOP, 0), 10.0, 'the stop request')
    sensor.close()


# --- bad parameters ------------------------------------------------------------------------------
BAD = [
    (['-p', 'transport:=can'], 'parameter transport'),
    (['-p', "columns:=['FXV','FYV','FZV','MXV','MYV']"], 'parameter columns'),
    (['-p', "columns:=['FXV','FXV','FYV','FZV','MXV','MYV','MZV']"], 'parameter columns'),
    (['-p', 'units:=mv'], 'parameter units'),
    (
        ['-p', 'transport:=udp', '-p', 'device:=127.0.0.1:9', '-p', 'framing:=binary']
        + ['-p', "record_format:='>3Q6z'"],
        'parameter record_format',
    ),
    (['-p', 'framing:=binary', '-p', "record_format:='>6i'"], 'parameter framing'),
]


def test_bad_parameters_are_refused_at_start_up_in_one_line():
    env = dict(os.environ, ROS_DOMAIN_ID=str(new_domain_id()))
    runs = [
        subprocess.Popen(
            ['balance_daq', '--ros-args', *args],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for args, _ in BAD
    ]
    for run, (args, named) in zip(runs, BAD):
        out, err = run.communicate(timeout=60)
        assert run.returncode != 0, (args, out, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith('[ERROR]'), (args, err)
        assert f'[balance_daq]: {named}' in lines[0], (args, err)
        assert '[INFO]' not in out + err  # refused before anything came up
