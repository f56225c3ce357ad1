"""balance_daq's device thread (daq/reader.py) against the fake devices of fake_devices.py, no
DDS: a pty, a TCP server that drops the node mid-line and takes it back, a refusing TCP port, an
ATI RDT sensor over UDP that is deaf at first, and a device sending UDP datagrams unasked.
"""

import threading
import time

from fake_devices import (
    free_udp_address,
    PtyDevice,
    rdt_record,
    RDT_START,
    RDT_STOP,
    RdtDevice,
    refused_tcp_address,
    TcpDevice,
    UdpSender,
)
import numpy as np
import pytest

from balance_calib.daq.parameters import daq_settings
from balance_calib.daq.reader import DeviceReader

BRIDGES = ['FXV', 'FYV', 'FZV', 'MXV', 'MYV', 'MZV']


def wait_for(predicate, timeout_s=10.0, what='a condition'):
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < deadline, f'timed out waiting for {what}'
        time.sleep(0.01)


class Run:
    """A DeviceReader collecting what it would publish and what it would log."""

    def __init__(self, **parameters):
        self.settings = daq_settings({'reconnect_period_s': 0.1, **parameters})
        self.batches = []
        self.logged = []
        self._lock = threading.Lock()
        self.reader = DeviceReader(
            self.settings,
            self._publish,
            lambda level, text: self.logged.append((level, text)),
            time.monotonic_ns,
        )
        self.reader.start()

    def _publish(self, samples):
        with self._lock:
            self.batches.append(samples)

    @property
    def bridges(self) -> np.ndarray:
        with self._lock:
            return np.vstack([b.bridges_mv for b in self.batches] or [np.zeros((0, 6))])

    def counts(self):
        return self.reader.snapshot()[0]

    def connected(self):
        return self.reader.snapshot()[1]

    def close(self):
        self.reader.close()


@pytest.fixture
def tcp():
    device = TcpDevice()
    yield device
    device.close()


def test_tcp_lines_a_device_closing_mid_line_and_coming_back(tcp):
    run = Run(transport='tcp', device=tcp.address, columns=['seq'] + BRIDGES)
    try:
        tcp.wait_client(1)
        tcp.send(b'1 1 2 3 4 5 6\n2 1 2 3 4 5 6\n3 9 9 9')  # the third line is cut
        wait_for(lambda: len(run.bridges) == 2, what='two samples')
        tcp.drop()
        tcp.wait_client(2)  # the reader came back
        tcp.send(b'400 7 7 7 7 7 7\n401 8 8 8 8 8 8\n')  # counting afresh after a reconnect
        wait_for(lambda: len(run.bridges) == 4, what='four samples')
        counts = run.counts()
        assert run.bridges[:, 0].tolist() == [1, 1, 7, 8]
        assert (counts.records_malformed, counts.reconnects, counts.samples_missing) == (1, 1, 0)
        assert run.connected()
        assert any('lost 127.0.0.1' in text for _, text in run.logged)
    finally:
        run.close()


def test_a_refusing_tcp_peer_is_tried_again_every_period_and_said_once_a_second():
    run = Run(transport='tcp', device=refused_tcp_address())
    try:
        wait_for(lambda: run.counts().reconnects >= 3, what='three attempts more')
        assert not run.connected() and len(run.bridges) == 0
        refusals = [text for _, text in run.logged if 'cannot reach' in text]
        assert 1 <= len(refusals) <= 2 and 'Connection refused' in refusals[0]
    finally:
        run.close()
    assert not run.reader._thread.is_alive()


def test_rdt_over_udp_a_deaf_device_is_asked_again_records_come_in_bursts():
    device = RdtDevice(deaf_requests=2)
    columns = ['seq', '_', 'status'] + BRIDGES
    run = Run(
        transport='udp',
        device=device.address,
        framing='binary',
        record_format='>3I6i',
        columns=columns,
        start_request='1234000200000000',
        stop_request='1234000000000000',
        units='counts',
        counts_to_mv=[0.5],
    )
    try:
        device.wait_streaming()
        assert device.requests[:3] == [(RDT_START, 0)] * 3  # asked three times
        assert run.counts().reconnects >= 2
        burst = b''.join(rdt_record(n, 100 + n, 0, [n, -n, 2, 4, 6, 8]) for n in (1, 2, 3))
        device.send(burst, rdt_record(4, 0, 0x8000_0000, [1] * 6), rdt_record(6, 0, 0, [1] * 6))
        device.send(rdt_record(6, 0, 0, [2] * 6), bytes(35))
        wait_for(lambda: run.counts().records_malformed == 1, what='the short datagram')
        assert run.bridges.tolist() == [
            [0.5, -0.5, 1, 2, 3, 4],
            [1, -1, 1, 2, 3, 4],
            [1.5, -1.5, 1, 2, 3, 4],
            [0.5] * 6,  # seq 6; seq 4 was flagged, seq 5 is missing
        ]
        counts = run.counts()
        assert (counts.samples_invalid, counts.samples_missing, counts.samples_duplicate) == (
            1,
            1,
            1,
        )
        run.close()  # stop_request before closing
        wait_for(lambda: device.requests[-1] == (RDT_STOP, 0), what='the stop request')
    finally:
        run.close()
        device.close()


def test_a_serial_devices_first_line_is_a_tail_then_prefixed_lines_with_temperature():
    pty = PtyDevice()
    pty.write(b'3.5,7\n')  # sent before the port opened: may be a tail
    run = Run(
        transport='serial',
        device=pty.path,
        columns=BRIDGES + ['temperature'],
        line_prefix='D',
        units='uV/V',
        excitation_v=10.0,
    )
    try:
        wait_for(run.connected, what='the port open')
        pty.write(b'HX711 ready\r\nD,100,200,300,400,500,600,21.5\r\n')
        pty.write(b'D;1;2;3;4;5;6;nan\r\nHX711 ready\r\nD 1 2 3 4 5 6 22\r\n')
        wait_for(lambda: len(run.bridges) == 2, what='two samples')
        expected = [[1, 2, 3, 4, 5, 6], [0.01, 0.02, 0.03, 0.04, 0.05, 0.06]]
        assert np.allclose(run.bridges, expected, rtol=1e-12, atol=0)
        assert [b.temperature_c.tolist() for b in run.batches] in ([[21.5], [22.0]], [[21.5, 22]])
        assert run.counts().records_malformed == 1  # the nan temperature
        skipped = [text for _, text in run.logged if 'not data' in text]
        assert skipped == ["skipped a line that is not data: 'HX711 ready'"]
    finally:
        run.close()
        pty.close()


def test_a_udp_device_sending_unasked_to_a_bound_port_one_line_a_datagram():
    address = free_udp_address()
    run = Run(transport='udp', device=address, units='V')
    sender = UdpSender(address)
    try:
        wait_for(run.connected, what='the port bound')
        sender.send(b'0.001 0.002 0.003 0.004 0.005 0.006', b'1,2,3\n', b'0 0 0 0 0 0.5\n')
        wait_for(lambda: len(run.bridges) == 2, what='two samples')
        assert run.bridges.tolist() == [[1, 2, 3, 4, 5, 6], [0, 0, 0, 0, 0, 500]]
        assert run.counts().records_malformed == 1 and run.counts().reconnects == 0
    finally:
        run.close()
        sender.close()


def test_a_serial_device_unplugged_is_said_and_tried_again_without_a_busy_loop():
    pty = PtyDevice()
    run = Run(transport='serial', device=pty.path, reconnect_period_s=0.05)
    try:
        wait_for(run.connected, what='the port open')
        pty.write(b'junk\n1 2 3 4 5 6\n')
        wait_for(lambda: len(run.bridges) == 1, what='a sample')
        pty.close()  # unplugged: the pty's path goes away
        wait_for(lambda: run.counts().reconnects >= 3, what='attempts to reopen it')
        assert not run.connected()
        assert any('lost' in text for _, text in run.logged)
        assert any('cannot reach' in text for _, text in run.logged)
    finally:
        run.close()
    assert not run.reader._thread.is_alive()
