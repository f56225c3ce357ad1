"""balance_daq fed by a device on loopback, beside the raw relay, measured the same way.

    python -m balance_calib.benchmarks.daq_throughput [--udp-rates 1000,2000,4000,7000,...]
        [--tcp-rates 1000,2000,4000] [--seconds 3] [--trials 1]

The harness is live_throughput's: the same sink process (bytes in, the stamp read, counted) on
/balance/raw, the same pacing loop, zero-loss and CPU bookkeeping (/proc/PID/stat of the node
over the samples of a step). What differs is the source: instead of publishing on DDS it is a
device in this process (simulation/virtual_device.py, the one `balance-calib virtual-daq` uses)
in the format of a shipped preset -- ATI RDT records over UDP (config/daq/netft_rdt.yaml: one
36-byte record a datagram, streamed to the peer that sent the start request) and text lines over
TCP (config/daq/tcp_mvv.yaml: device time and six mV/V values a line) -- and balance_daq between
device and sink. Printed first, the harness's own ceilings: the DDS source straight to the sink
(no node between, as live_throughput prints it) and the device source alone (records a second
this process sends when nothing is paced). Then the raw relay (live_throughput's: bytes in, bytes
out, the calibrator's reader; DDS in, DDS out), the reference of the CPU target: balance_daq's
CPU per sample at 1 kHz <= 1.5 x the raw relay's. Targets: zero loss at 7 kHz of RDT
records, at 2 kHz of lines.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import socket
import sys
import threading
import time

import numpy as np

from .dds_harness import Harness, machine_line, start_process, stop_process
from .loss_summary import first_loss_rate, medians_at_1k, zero_loss_rate

PRESETS = Path(__file__).resolve().parents[2] / 'config' / 'daq'
UDP_RDT, TCP_LINES = 'balance_daq, udp RDT', 'balance_daq, tcp lines'
SOURCES = {UDP_RDT: ('udp', 'netft_rdt.yaml'), TCP_LINES: ('tcp', 'tcp_mvv.yaml')}
SAMPLE_MV = np.array([0.10, -0.05, 0.20, 0.01, -0.02, 0.03])  # inside any preset's range


def _preset(name: str) -> Path:
    from ..config import resolve_config_path

    local = PRESETS / name
    return local if local.exists() else resolve_config_path(f'daq/{name}')


class DeviceHarness(Harness):
    """The live harness with a device for a source: each send() is one record (one datagram, or
    one line written) of the preset's format, stamped by the device's clock (time.monotonic).
    """

    def __init__(self, node, transport: str, preset: Path):
        from ..simulation.virtual_device import read_format, VirtualDevice

        super().__init__(node, '/balance/raw', uncertainty=False, dds_source=False)
        self.device = VirtualDevice(transport, '127.0.0.1:0', read_format(preset), str(preset))
        self.address = self.device.address

    def source_connected(self) -> bool:
        return self.device.clients() > 0

    def send(self) -> None:
        self.device.add_sample(SAMPLE_MV, time.monotonic())
        self.device.flush()

    def close(self):
        super().close()
        self.device.close()


def decode_cost_us(preset: Path, records: int = 20_000) -> float:
    """balance_daq's own work on one record as the device thread meets it, in this process:
    µs per record of framing, parsing and SampleStream.take, one record a read (a datagram, or
    one line written), records encoded by the virtual device's Encoder. No DDS: what the CPU
    figures at 1 kHz spend in the node's Python besides rclpy's publish.
    """
    from ..daq.framing import LineFramer, LineParser, RecordParser
    from ..daq.samples import SampleStream
    from ..simulation.virtual_device import Encoder, read_format

    settings = read_format(preset)
    encoder = Encoder(settings)
    chunks = [encoder.encode(SAMPLE_MV, 1e-3 * i) for i in range(records)]
    stream = SampleStream(settings)
    if settings.framing == 'binary':
        parser = RecordParser(settings.record_format, settings.columns)
        begin = time.perf_counter()
        for i, datagram in enumerate(chunks):
            parsed = parser.parse([datagram])
            stream.take(parsed.fields, i * 1_000_000, parsed.malformed)
    else:
        framer, line_parser = LineFramer(), LineParser(settings.columns, settings.line_prefix)
        framer.restart(False)
        begin = time.perf_counter()
        for i, line in enumerate(chunks):
            lines, overlong = framer.feed(line)
            parsed = line_parser.parse(lines)
            stream.take(parsed.fields, i * 1_000_000, parsed.malformed + overlong)
    elapsed = time.perf_counter() - begin
    if stream.counts.samples_published != records:
        raise RuntimeError(
            f'{preset.name}: {stream.counts.samples_published} of {records} decoded'
        )
    return elapsed / records * 1e6


def source_ceiling(transport: str, preset: Path, seconds: float = 1.0) -> float:
    """Records a second the device source sends, unpaced, to a reader that drains them."""
    from ..simulation.virtual_device import read_format, VirtualDevice

    device = VirtualDevice(transport, '127.0.0.1:0', read_format(preset), str(preset))
    host, port = device.address.split(':')
    if transport == 'tcp':
        reader = socket.create_connection((host, int(port)))
    else:
        reader = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        reader.sendto(bytes.fromhex('1234000200000000'), (host, int(port)))
    reader.settimeout(0.2)
    running = True

    def drain():
        while running:
            try:
                reader.recv(65536)
            except OSError:
                continue

    thread = threading.Thread(target=drain, daemon=True)
    thread.start()
    deadline = time.monotonic() + 5.0
    while device.clients() == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    sent, start = 0, time.monotonic()
    while time.monotonic() - start < seconds:
        device.add_sample(SAMPLE_MV, time.monotonic())
        device.flush()
        sent += 1
    rate = sent / (time.monotonic() - start)
    running = False
    thread.join(timeout=1.0)
    reader.close()
    device.close()
    return rate


def _step_line(rate: float, trial: int, result: dict) -> str:
    step = f'{rate:6.0f} Hz' if trial == 0 else f'{"":>6s} #{trial + 1}'
    return (
        f'  {step} (sent at {result["achieved"]:6.0f}): {result["received"]}/{result["sent"]} '
        f'back, p50 {result["p50_ms"]:.3f} ms, p99 {result["p99_ms"]:.3f} ms, CPU '
        f'{result["cpu_us_per_sample"]:.1f} µs/sample (source '
        f'{result["source_us_per_sample"]:.0f}, sink {result["sink_us_per_sample"]:.0f})'
    )


def _measure(label, harness, process, rates, seconds, trials, summary) -> None:
    harness.wait_connected()
    summary[label] = []
    for rate in rates:
        for trial in range(trials):
            result = harness.run(rate, seconds, None if process is None else process.pid)
            summary[label].append(result)
            print(_step_line(rate, trial, result), flush=True)
            if rate == 1000.0 and result['threads']:
                print(
                    '         by thread (CPU µs, wake-ups per sample): '
                    + ', '.join(
                        f'{group} {cpu:.0f} µs {wakes:.1f}'
                        for group, (cpu, wakes) in result['threads'].items()
                    ),
                    flush=True,
                )
        if any(r['received'] < 0.5 * r['sent'] for r in summary[label] if r['rate'] == rate):
            break  # far beyond this node's rate


def throughput(udp_rates, tcp_rates, seconds: float, trials: int) -> dict:
    import rclpy

    env = dict(os.environ)
    summary: dict = {}
    ceilings = {
        label: source_ceiling(transport, _preset(name))
        for label, (transport, name) in SOURCES.items()
    }
    relay_rates = sorted(set(udp_rates) | set(tcp_rates))
    rclpy.init()
    try:
        rows = [('harness ceiling', None), ('raw relay', None), (UDP_RDT, None), (TCP_LINES, None)]
        for label, _ in rows:
            print(f'{label}:', flush=True)
            if label in SOURCES:
                transport, name = SOURCES[label]
                preset = _preset(name)
                harness = DeviceHarness(
                    rclpy.create_node('benchmark_' + transport), transport, preset
                )
                command = [
                    'balance_daq',
                    '--ros-args',
                    '--params-file',
                    str(preset),
                    '-p',
                    f'device:={harness.address}',
                    '-p',
                    'expected_rate_hz:=1000.0',
                ]
                rates = udp_rates if transport == 'udp' else tcp_rates
            else:
                relay = label == 'raw relay'
                harness = Harness(
                    rclpy.create_node('benchmark_' + label.replace(' ', '_')),
                    '/balance/wrench' if relay else '/balance/raw',
                    uncertainty=False,
                )
                command = (
                    [sys.executable, '-m', 'balance_calib.benchmarks.live_throughput']
                    + ['--node', 'raw-relay']
                    if relay
                    else None
                )
                rates = relay_rates
            process = None if command is None else start_process(command, env)
            try:
                _measure(label, harness, process, rates, seconds, trials, summary)
            finally:
                harness.close()
                if process is not None:
                    stop_process(process)
    finally:
        rclpy.try_shutdown()
    report(summary, ceilings, seconds, trials)
    return summary


def report(summary: dict, ceilings: dict, seconds: float, trials: int) -> None:
    print('\n' + machine_line())
    print(
        f'{trials} trial(s) of {seconds:g} s per rate; device source alone, unpaced: '
        + ', '.join(
            f'{label.split(", ")[1]} {rate:.0f} records/s' for label, rate in ceilings.items()
        )
    )
    print(
        f'{"":24s} {"zero-loss Hz":>12s} {"first loss Hz":>13s} {"CPU µs/sample @1k":>18s} '
        f'{"p50 ms @1k":>11s} {"p99 ms @1k":>11s}'
    )
    for label, results in summary.items():
        one = medians_at_1k(results) or {}
        lost = first_loss_rate(results)
        print(
            f'{label:24s} {zero_loss_rate(results):12.0f} '
            f'{"none" if lost != lost else f"{lost:.0f}":>13s} '
            f'{one.get("cpu_us_per_sample", float("nan")):18.1f} '
            f'{one.get("p50_ms", float("nan")):11.3f} {one.get("p99_ms", float("nan")):11.3f}'
        )
    print(
        'decode in this process (framing, parsing, take; one record a read): '
        + ', '.join(
            f'{label.split(", ")[1]} {decode_cost_us(_preset(name)):.1f} µs/record'
            for label, (_, name) in SOURCES.items()
        )
    )
    relay = medians_at_1k(summary.get('raw relay', [])) if summary.get('raw relay') else None
    for label, target in ((UDP_RDT, 7000.0), (TCP_LINES, 2000.0)):
        results = summary.get(label)
        if not results:
            continue
        best = zero_loss_rate(results)
        line = f'{label}: zero loss up to {best:.0f} Hz (target {target:.0f}: '
        line += 'met)' if best >= target else 'missed)'
        one = medians_at_1k(results)
        if one and relay:
            ratio = one['cpu_us_per_sample'] / relay['cpu_us_per_sample']
            line += f'; CPU per sample at 1 kHz {ratio:.2f} x the raw relay (target <= 1.5)'
        print(line)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--udp-rates', default='1000,2000,4000,7000,10000,14000')
    parser.add_argument('--tcp-rates', default='1000,2000,4000,7000')
    parser.add_argument('--seconds', type=float, default=3.0)
    parser.add_argument('--trials', type=int, default=1, help='runs of each rate (1-20)')
    parser.add_argument('--domain', type=int, default=int(os.environ.get('ROS_DOMAIN_ID', '77')))
    args = parser.parse_args(argv)
    if not 1 <= args.trials <= 20:
        parser.error(f'--trials {args.trials}: must be 1 to 20')
    os.environ.update(ROS_DOMAIN_ID=str(args.domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    throughput(
        [float(r) for r in args.udp_rates.split(',')],
        [float(r) for r in args.tcp_rates.split(',')],
        args.seconds,
        args.trials,
    )


if __name__ == '__main__':
    main()
