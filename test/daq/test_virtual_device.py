"""The virtual device of `balance-calib virtual-daq` sends what interfaces.md's "Acquisition"
says a device sends: decoded here from the contract (not from balance_daq's code), its records
give back the bridge outputs it was handed, over a pty, TCP and UDP (the ATI RDT request).
"""

from __future__ import annotations

import os
from pathlib import Path
import re
import select
import socket
import struct
import time

import numpy as np
import pytest

from balance_calib.simulation.virtual_device import (
    device_format,
    DeviceError,
    Encoder,
    read_format,
    ReturnedSamples,
    VirtualDevice,
)

RAW_MV = np.array([0.8123456, -1.25, 2.0e-3, 3.5, -0.000731, 1.9999])
CONFIG_DAQ = Path(__file__).resolve().parents[2] / 'config' / 'daq'


def fields_of_line(line: bytes) -> list[str]:
    """The contract's separators: a comma, a semicolon, or a run of spaces or tabs."""
    return re.split(r'[,;]|[ \t]+', line.decode('ascii').rstrip('\r\n'))


def to_mv(value: float, units: str, excitation_v: float = 5.0, mv_per_count: float = 1.0):
    """The contract's unit conversions, bridge field -> mV."""
    return {
        'mV': value,
        'V': value * 1000.0,
        'mV/V': value * excitation_v,
        'uV/V': value * excitation_v / 1000.0,
        'counts': value * mv_per_count,
    }[units]


@pytest.mark.parametrize('units', ['mV', 'V', 'mV/V', 'uV/V'])
def test_a_line_gives_back_the_bridge_outputs_in_every_unit(units):
    device = device_format(
        {
            'columns': ['seq', 'MZV', 'FXV', 'FYV', 'FZV', 'MXV', 'MYV', 'temperature', '_'],
            'units': units,
            'excitation_v': 10.0,
        }
    )
    encoder = Encoder(device)
    lines = [encoder.encode(RAW_MV * k, 0.0, 21.5) for k in (1.0, -2.0)]
    for k, line in zip((1.0, -2.0), lines):
        fields = fields_of_line(line)
        assert len(fields) == 9 and line.endswith(b'\n')
        mv = [to_mv(float(f), units, 10.0) for f in fields[1:7]]
        expected = RAW_MV * k
        # written order MZV, FXV ... MYV
        assert np.allclose(mv, np.r_[expected[5], expected[:5]], rtol=1e-8, atol=1e-12)
        assert float(fields[7]) == 21.5 and fields[8] == '0'
    assert [int(fields_of_line(line)[0]) for line in lines] == [0, 1]  # seq steps by one


def test_counts_are_whole_and_within_half_a_count_and_a_prefix_leads_the_line():
    device = device_format(
        {
            'columns': ['FXV', 'FYV', 'FZV', 'MXV', 'MYV', 'MZV', 'status'],
            'units': 'counts',
            'counts_to_mv': [1e-4, 2e-4, 1e-4, 1e-4, 1e-4, 5e-5],
            'line_prefix': 'D',
        }
    )
    fields = fields_of_line(Encoder(device, '\r\n').encode(RAW_MV))
    assert fields[0] == 'D' and fields[-1] == '0'
    counts = [int(f) for f in fields[1:7]]  # integers, as an A/D converter sends
    steps = np.array([1e-4, 2e-4, 1e-4, 1e-4, 1e-4, 5e-5])
    assert np.all(np.abs(np.array(counts) * steps - RAW_MV) <= steps / 2 + 1e-15)


def test_an_rdt_record_is_36_big_endian_bytes_and_clips_like_an_adc():
    device = device_format(
        {
            'transport': 'udp',
            'device': '127.0.0.1:49152',
            'framing': 'binary',
            'record_format': '>3I6i',
            'columns': ['seq', '_', 'status', 'FXV', 'FYV', 'FZV', 'MXV', 'MYV', 'MZV'],
            'units': 'counts',
            'counts_to_mv': [1e-6],
        }
    )
    encoder = Encoder(device)
    record = encoder.encode(RAW_MV)
    assert len(record) == 36
    seq, _, status, *counts = struct.unpack('>3I6i', record)
    assert (seq, status) == (0, 0)
    assert counts == [round(v / 1e-6) for v in RAW_MV]
    big = encoder.encode(RAW_MV * 1e4)  # 8123 mV / 1 nV a count: beyond int32
    counts = struct.unpack('>3I6i', big)[3:]
    assert (
        counts[0] == 2**31 - 1 and counts[1] == -(2**31) and struct.unpack('>I', big[:4]) == (1,)
    )


@pytest.mark.parametrize(
    ('parameters', 'says'),
    [
        ({'columns': ['FXV', 'FYV', 'FZV', 'MXV', 'MYV']}, 'exactly once'),
        ({'columns': ['FXV', 'FXV', 'FYV', 'FZV', 'MXV', 'MYV', 'MZV']}, 'exactly once'),
        ({'units': 'mV/A'}, 'units'),
        (
            {'transport': 'udp', 'device': 'h:1', 'framing': 'binary', 'record_format': '>6q9'},
            'record_format',
        ),
        (
            {'transport': 'udp', 'device': 'h:1', 'framing': 'binary', 'record_format': '>5i'},
            'holds 5 fields',
        ),
        ({'framing': 'binary', 'record_format': '>6i'}, 'udp'),
        ({'start_request': '12zz'}, 'hex'),
        ({'units': 'counts', 'counts_to_mv': [0.0]}, 'counts_to_mv'),
    ],
)
def test_a_format_the_device_cannot_send_is_refused_naming_the_parameter(parameters, says):
    with pytest.raises(DeviceError, match=says):
        device_format(parameters, 'preset.yaml')


def test_binary_records_only_over_udp(tmp_path):
    device = device_format(
        {'transport': 'udp', 'device': 'h:1', 'framing': 'binary', 'record_format': '>6i'}
    )
    with pytest.raises(DeviceError, match='udp only'):
        VirtualDevice('tcp', '127.0.0.1:0', device)


def test_the_format_is_read_from_a_presets_balance_daq_section(tmp_path):
    preset = tmp_path / 'p.yaml'
    preset.write_text(
        'balance_daq:\n  ros__parameters:\n    transport: udp\n    device: 192.0.2.1:49152\n'
        '    units: uV/V\n'
        '    excitation_v: 2.5\n    start_request: "1234000200000000"\n'
    )
    device = read_format(preset)
    assert device.units == 'uV/V' and device.excitation_v == 2.5
    assert device.start_request == bytes.fromhex('1234000200000000')
    (tmp_path / 'bad.yaml').write_text('other:\n  ros__parameters: {}\nmore:\n  x: 1\n')
    assert read_format(tmp_path / 'bad.yaml').units == 'mV'  # the only section: defaults
    (tmp_path / 'two.yaml').write_text('a:\n  ros__parameters: {}\nb:\n  ros__parameters: {}\n')
    with pytest.raises(DeviceError, match='no balance_daq'):
        read_format(tmp_path / 'two.yaml')


def test_every_shipped_preset_is_a_format_the_device_plays():
    presets = sorted(CONFIG_DAQ.glob('*.yaml'))
    assert len(presets) >= 3, f'{CONFIG_DAQ}: the three presets are missing'
    for preset in presets:
        device = read_format(preset)
        encoder = Encoder(device)
        assert encoder.encode(RAW_MV)


def _read_until(fd_or_sock, want: int, timeout_s: float = 5.0) -> bytes:
    data = b''
    deadline = time.monotonic() + timeout_s
    while len(data) < want and time.monotonic() < deadline:
        if select.select([fd_or_sock], [], [], 0.1)[0]:
            chunk = (
                os.read(fd_or_sock, 4096) if isinstance(fd_or_sock, int) else fd_or_sock.recv(4096)
            )
            if not chunk:
                break
            data += chunk
    return data


def test_a_pty_carries_crlf_lines_and_a_link_names_it(tmp_path):
    device = VirtualDevice('serial', str(tmp_path / 'ttyBALANCE'), device_format({}))
    try:
        assert os.path.realpath(tmp_path / 'ttyBALANCE') == device.link.path
        reader = os.open(tmp_path / 'ttyBALANCE', os.O_RDONLY | os.O_NOCTTY)
        try:
            device.add_sample(RAW_MV, 0.0)
            device.add_sample(-RAW_MV, 0.01)
            device.flush()
            data = b''
            deadline = time.monotonic() + 5.0
            while data.count(b'\r\n') < 2 and time.monotonic() < deadline:
                data += _read_until(reader, 1, 0.5)
            while data.count(b'\r\n') < 3 and time.monotonic() < deadline:
                data += _read_until(reader, 1, 0.5)
            lines = data.split(b'\r\n')
            # the empty line the node drops as a possible tail, then the samples
            assert len(lines) == 4 and lines[0] == lines[3] == b'', data
            assert np.allclose([float(f) for f in fields_of_line(lines[2])], -RAW_MV)
        finally:
            os.close(reader)
    finally:
        device.close()
    assert not (tmp_path / 'ttyBALANCE').exists()


def test_tcp_serves_whole_lines_to_each_client_from_the_next_record():
    device = VirtualDevice(
        'tcp',
        '127.0.0.1:0',
        device_format({'columns': ['seq', *'FXV FYV FZV MXV MYV MZV'.split()]}),
    )
    try:
        device.add_sample(RAW_MV, 0.0)
        device.flush()  # nobody connected: gone
        client = socket.create_connection(('127.0.0.1', device.link.port), timeout=5)
        with client:
            assert device.clients() == 1
            device.add_sample(RAW_MV, 0.01)
            device.flush()
            data = _read_until(client, 1)
            assert data.endswith(b'\n') and int(fields_of_line(data)[0]) == 1
    finally:
        device.close()


def test_udp_answers_the_rdt_request_with_count_records_and_stops_on_command_zero():
    device = VirtualDevice(
        'udp',
        '127.0.0.1:0',
        device_format(
            {
                'transport': 'udp',
                'device': '127.0.0.1:49152',
                'framing': 'binary',
                'record_format': '>3I6i',
                'columns': ['seq', '_', 'status', 'FXV', 'FYV', 'FZV', 'MXV', 'MYV', 'MZV'],
                'units': 'counts',
                'counts_to_mv': [1e-5],
                'start_request': '1234000200000000',
                'stop_request': '1234000000000000',
            }
        ),
    )
    peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    peer.settimeout(5.0)
    try:
        address = ('127.0.0.1', device.link.port)
        assert device.clients() == 0
        peer.sendto(struct.pack('>HHI', 0x1234, 2, 3), address)  # 3 records, as ATI documents
        wait = time.monotonic() + 5
        while device.clients() == 0 and time.monotonic() < wait:
            time.sleep(0.01)
        for k in range(5):
            device.add_sample(RAW_MV * (k + 1), k * 0.001)
        device.flush()
        records = [peer.recv(100) for _ in range(3)]
        assert [len(r) for r in records] == [36, 36, 36]
        assert [struct.unpack('>3I6i', r)[0] for r in records] == [0, 1, 2]
        assert device.clients() == 0  # the count is served
        peer.sendto(bytes.fromhex('1234000200000000'), address)  # for ever
        wait = time.monotonic() + 5
        while device.clients() == 0 and time.monotonic() < wait:
            time.sleep(0.01)
        peer.sendto(struct.pack('>HHI', 0x1234, 0, 0), address)
        wait = time.monotonic() + 5
        while device.clients() == 1 and time.monotonic() < wait:
            time.sleep(0.01)
        assert device.clients() == 0
    finally:
        peer.close()
        device.close()


@pytest.mark.parametrize(
    ('args', 'says'),
    [
        (['--transport', 'tcp', '--device', '127.0.0.1:0', '--format', 'nosuch'], 'nosuch'),
        (['--transport', 'tcp', '--device', 'nonsense'], 'host:port'),
        (['--transport', 'tcp', '--device', '127.0.0.1:0', '--format', 'netft_rdt'], 'udp only'),
        (['--transport', 'udp', '--device', '127.0.0.1:0', '-p', 'mode:=replay'], 'replay'),
        (['--transport', 'udp', '--device', '127.0.0.1:0', '-p', 'rate_hz'], 'NAME:=VALUE'),
    ],
)
def test_virtual_daq_refuses_bad_options_in_one_line_before_ros_starts(args, says, capsys):
    from balance_calib.cli import main

    assert main(['virtual-daq', *args]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and says in err and err.startswith('balance-calib virtual-daq:')


def test_returned_samples_are_told_apart_by_value_so_a_lost_one_shifts_no_marker():
    rng = np.random.default_rng(3)
    written = rng.normal(0.0, 1e-3, (8, 6)) + 1.0  # noise of a µV between samples
    device = device_format({'units': 'counts', 'counts_to_mv': [1e-6]})
    returned = ReturnedSamples(device)
    for values in written:
        returned.written(values)
    quantised = np.rint(written / 1e-6) * 1e-6  # what balance_daq publishes from counts
    assert returned.marker_stamp(0) is None and returned.marker_stamp(1) is None
    assert returned.returned(quantised[0], 100)
    assert returned.marker_stamp(1) == 101  # 1 ns after sample 0
    assert returned.marker_stamp(2) is None  # sample 1 not resolved yet
    assert returned.returned(quantised[3], 400)  # 1 and 2 lost on the way
    assert returned.lost == 2
    assert returned.marker_stamp(2) == 101 and returned.marker_stamp(3) == 101
    assert returned.marker_stamp(4) == 401
    assert not returned.returned(quantised[3] + 1e-4, 500)  # matches nothing written
    first_lost = ReturnedSamples(device)
    for values in written[:3]:
        first_lost.written(values)
    first_lost.returned(quantised[1], 200)  # the very first one lost (a port's first line)
    assert first_lost.marker_stamp(1) == 199  # before the next that came back
