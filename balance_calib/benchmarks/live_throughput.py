"""The live calibrator beside rclpy relays, measured the same way in the same run.

    python -m balance_calib.benchmarks.live_throughput [--rates 1000,2000,4000,...] [--seconds 2]
    python -m balance_calib.benchmarks.live_throughput --refit BAG [--seconds 5]

The harness measures the node, not itself: the source publishes pre-serialized samples (a byte
template with the stamp patched in) and the sink -- its own process, the calibrator's reader --
takes bytes and reads only the stamp, so the harness's own ceiling -- source straight to sink, no
node between -- is printed first. Then,
each as a subprocess between the same source and sink (reliable, depth 1000 both ways):

- bare relay: Python messages, the default executor, what users write (relay_node.py);
- raw relay: bytes in, bytes out, the calibrator's reader (nodes/_raw_input.py: a thread waiting on
  the subscription alone, batches of what is waiting; `--node raw-relay` of this module): rclpy's
  own ceiling for a node;
- raw relay, 2 topics: the same, each sample published on balance/wrench and on
  balance/wrench_uncertainty: the floor of any rclpy node with the calibrator's topics, before it
  decodes, computes or encodes anything;
- calibrator, pure core: the calibrator with its lone-sample C kernel switched off
  (BALANCE_CALIB_LONE_KERNEL=0, live/lone_sample.py): the kernel's baseline, same run;
- calibrator, wrench only: the same with publish_uncertainty:=false, one topic out as the relays:
  the calibrator's own rate without the second topic's cost (last, so as not to disturb the rest);
- balance_calibrator: the memo's cubic matrix with a coefficient covariance, diagnostics at 1 Hz;
the
  sink subscribes to balance/wrench_uncertainty too (the calibrator computes and publishes it only
  for subscribers), so one more message per sample is computed, published and counted, and a step
  is zero-loss only if both topics came back whole.

Per rate: messages back / sent and latency p50/p99 (receive time minus the sample's stamp). Per
node: the highest rate with zero loss, and at 1 kHz the process CPU time per sample (/proc/PID/stat
utime + stime over the samples of that step), split by thread (rclpy's executor, the node's own
Python threads, Fast DDS's event and transport threads) with their wake-ups per sample, and p50/p99
latency.

`--refit BAG` measures what issue 12 asks of ~/refit: the calibrator's latency at 1 kHz while quiet
and while ~/refit fits BAG (in its own process), p50/p99/max, and that no sample is lost.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import subprocess
import sys
import threading
import time

import numpy as np

QOS_DEPTH = 1000
UNCERTAINTY_TOPIC = '/balance/wrench_uncertainty'
BOTH_TOPICS = 'raw relay, 2 topics'
PURE_CORE = 'calibrator, pure core'
WRENCH_ONLY = 'calibrator, wrench only'
CDR_LE = b'\x00\x01\x00\x00'


def raw_template(frame_id: str = 'LMC6522') -> bytearray:
    from balance_calib.live.raw_codec import WrenchEncoder

    encoder = WrenchEncoder(frame_id)
    values = np.zeros((1, 6))
    values[0, :3] = 0.1, 0.0, 0.2  # inside the calibrated envelope
    return bytearray(encoder.encode(np.zeros(1, np.int64), values)[0])


def stamped(template: bytearray, stamp_ns: int) -> bytes:
    """A copy of a serialized WrenchStamped (little-endian CDR) with header.stamp set to
    stamp_ns.
    """
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    template[4:8] = sec.to_bytes(4, 'little', signed=True)
    template[8:12] = nanosec.to_bytes(4, 'little')
    return bytes(template)


def _clock_ticks() -> float:
    return float(os.sysconf('SC_CLK_TCK'))


def _cpu_seconds(pid: int) -> float:
    """Utime + stime of a process, s (Linux /proc)."""
    with open(f'/proc/{pid}/stat') as handle:
        fields = handle.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / _clock_ticks()


def _thread_cpu(pid: int) -> dict:
    """Per thread of a process: (group, utime + stime in ticks, voluntary context switches).

    Groups: 'main' (the thread whose id is the pid: rclpy's executor), 'dds.<kind>' for Fast DDS's
    threads (event, shm, udp, ...), 'other' for the rest (the node's own Python threads).
    """
    import glob

    threads = {}
    for task in glob.glob(f'/proc/{pid}/task/*'):
        tid = int(task.rsplit('/', 1)[1])
        try:
            with open(f'{task}/stat') as handle:
                fields = handle.read().rsplit(')', 1)[1].split()
            with open(f'{task}/comm') as handle:
                name = handle.read().strip()
            with open(f'{task}/status') as handle:
                switches = int(handle.read().split('voluntary_ctxt_switches:')[1].split()[0])
        except (OSError, IndexError, ValueError):  # the thread ended meanwhile
            continue
        group = (
            'main'
            if tid == pid
            else 'dds.' + name.split('.')[1]
            if name.startswith('dds.')
            else 'other'
        )
        threads[tid] = (group, int(fields[11]) + int(fields[12]), switches)
    return threads


def _thread_breakdown(before: dict, after: dict, samples: int) -> dict:
    """CPU µs and wake-ups per sample by thread group, between two _thread_cpu snapshots."""
    tick_us = 1e6 / _clock_ticks()
    groups: dict = {}
    for tid, (group, ticks, switches) in after.items():
        old = before.get(tid, (group, 0, 0))
        cpu, wakes = groups.get(group, (0.0, 0.0))
        groups[group] = (
            cpu + (ticks - old[1]) * tick_us / samples,
            wakes + (switches - old[2]) / samples,
        )
    return dict(sorted(groups.items(), key=lambda item: -item[1][0]))


class Harness:
    """Source (pre-serialized, this process) and sink (bytes, stamp only, its own process).

    The sink is `--node sink` of this module: a RawInput thread (the calibrator's reader) that
    takes what is waiting as bytes and notes receive time minus stamp; it answers `reset`, `count
    [K]`, `stats` (JSON), `publishers [K]` and `dump FILE` on stdin/stdout. In its own process it
    neither competes with the source for the GIL nor is counted in the node's CPU. With a node
    between, the same thread also counts balance/wrench_uncertainty (the calibrator computes it
    only for subscribers): one reader thread, so no GIL is shared between readers, and one process,
    so that the second topic costs the harness as little as it can on two cores (a second sink
    process competed with the node for them).
    """

    def __init__(self, node, sink_topic: str, uncertainty: bool = True, dds_source: bool = True):
        from geometry_msgs.msg import WrenchStamped
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        qos = QoSProfile(depth=QOS_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
        self.node = node
        # without: a subclass feeds the node another way (benchmarks/daq_throughput.py: a device)
        self.publisher = (
            node.create_publisher(WrenchStamped, '/balance/raw', qos) if dds_source else None
        )
        topics = [sink_topic] + (
            [UNCERTAINTY_TOPIC] if sink_topic != '/balance/raw' and uncertainty else []
        )
        self.topics = len(topics)
        self.sink = subprocess.Popen(
            [sys.executable, '-m', 'balance_calib.benchmarks.live_throughput', '--node', 'sink']
            + [a for topic in topics for a in ('--topic', topic)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            bufsize=1,
        )
        self.template = raw_template()

    def ask(self, command: str) -> str:
        self.sink.stdin.write(command + '\n')
        self.sink.stdin.flush()
        line = self.sink.stdout.readline()
        if not line:
            raise RuntimeError(f'the benchmark sink exited (code {self.sink.poll()})')
        return line.strip()

    def wait_uncertainty_connected(self, timeout_s: float = 10.0) -> None:
        """For a node that publishes balance/wrench_uncertainty: until the sink's second
        subscription is matched.
        """
        deadline = time.monotonic() + timeout_s
        while (
            self.topics > 1 and int(self.ask('publishers 1')) == 0 and time.monotonic() < deadline
        ):
            time.sleep(0.05)

    def source_connected(self) -> bool:
        return self.publisher.get_subscription_count() > 0

    def wait_connected(self, timeout_s: float = 30.0) -> None:
        deadline = time.monotonic() + timeout_s
        while (
            not self.source_connected() or int(self.ask('publishers')) == 0
        ) and time.monotonic() < deadline:
            time.sleep(0.05)
        # warm-up: discovery on the writer side and first allocations, not measured
        for _ in range(100):
            self.send()
            time.sleep(0.005)
        time.sleep(0.5)

    def send(self) -> None:
        self.publisher.publish(stamped(self.template, time.time_ns()))

    def run(self, rate: float, seconds: float, pid: int | None) -> dict:
        self.ask('reset')
        total = int(rate * seconds)
        cpu_before = _cpu_seconds(pid) if pid else 0.0
        threads_before = _thread_cpu(pid) if pid else {}
        source_before, sink_before = time.process_time(), _cpu_seconds(self.sink.pid)
        start = time.monotonic()
        for i in range(total):
            delay = start + i / rate - time.monotonic()
            if delay > 0.0005:
                time.sleep(delay)
            self.send()
        achieved = total / (time.monotonic() - start)
        settle = time.monotonic() + 3.0
        while time.monotonic() < settle and int(self.ask('count')) < total:
            time.sleep(0.02)
        if self.topics > 1:
            while time.monotonic() < settle and int(self.ask('count 1')) < total:
                time.sleep(0.02)
        cpu = (_cpu_seconds(pid) - cpu_before) if pid else float('nan')
        threads = _thread_breakdown(threads_before, _thread_cpu(pid), total) if pid else {}
        source, sink = (
            time.process_time() - source_before,
            _cpu_seconds(self.sink.pid) - sink_before,
        )
        stats = json.loads(self.ask('stats'))
        if self.topics > 1:
            stats['uncertainty_received'] = int(self.ask('count 1'))
        return {
            'rate': rate,
            'achieved': achieved,
            'sent': total,
            **stats,
            'cpu_us_per_sample': cpu / total * 1e6,
            'threads': threads,
            'source_us_per_sample': source / total * 1e6,
            'sink_us_per_sample': sink / total * 1e6,
        }

    def close(self):
        try:
            self.sink.stdin.close()
            self.sink.wait(timeout=10)
        except (OSError, subprocess.TimeoutExpired):
            self.sink.kill()
        self.node.destroy_node()


def sink_main(topics: list) -> None:
    """The harness's sink: bytes in, stamp read, latency noted for the first topic, the others
    counted; all read by one RawInput thread; commands on stdin (see Harness).
    """
    from geometry_msgs.msg import WrenchStamped
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from balance_calib.nodes._raw_input import RawInput

    latencies_ns: list[int] = []
    counts = [0] * len(topics)
    lock = threading.Lock()

    def on_batch(batch):
        now = time.time_ns()
        stamps = [
            int.from_bytes(d[4:8], 'little', signed=True) * 1_000_000_000
            + int.from_bytes(d[8:12], 'little')
            for d in batch
        ]
        with lock:
            latencies_ns.extend(now - s for s in stamps)

    def counter(k):
        def on_batch(batch):
            with lock:
                counts[k] += len(batch)

        return on_batch

    rclpy.init()
    node = rclpy.create_node('benchmark_sink')
    qos = QoSProfile(depth=QOS_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
    reader = RawInput(node, WrenchStamped, topics[0], qos, on_batch)
    subscriptions = [reader.subscription] + [
        reader.also_read(topic, counter(k), qos) for k, topic in enumerate(topics) if k > 0
    ]
    reader.start()
    try:
        for line in sys.stdin:
            command, _, argument = line.strip().partition(' ')
            if command == 'reset':
                with lock:
                    latencies_ns.clear()
                    counts[:] = [0] * len(topics)
                answer = 'ok'
            elif command == 'count':  # cheap: polled while the last samples arrive
                k = int(argument or 0)
                with lock:
                    answer = str(counts[k] if k else len(latencies_ns))
            elif command == 'publishers':
                answer = str(subscriptions[int(argument or 0)].get_publisher_count())
            elif command == 'stats':
                with lock:
                    latencies = np.array(latencies_ns, dtype=float) / 1e6
                answer = json.dumps(
                    {
                        'received': len(latencies),
                        'uncertainty_received': 0,
                        'p50_ms': float(np.percentile(latencies, 50))
                        if len(latencies)
                        else float('nan'),
                        'p99_ms': float(np.percentile(latencies, 99))
                        if len(latencies)
                        else float('nan'),
                        'max_ms': float(latencies.max()) if len(latencies) else float('nan'),
                    }
                )
            elif command == 'dump':  # latencies in arrival order, ms, one per line
                with lock:
                    latencies = np.array(latencies_ns, dtype=float) / 1e6
                np.savetxt(argument, latencies, fmt='%.4f')
                answer = 'ok'
            else:
                answer = f'unknown command {command!r}'
            print(answer, flush=True)
    finally:
        reader.close()
        node.destroy_node()
        rclpy.try_shutdown()


def calibration_with_covariance(directory: str) -> str:
    """The memo's LMC6522 cubic matrix with a coefficient covariance and residual σ (from 300
    synthetic points), so that the calibrator publishes balance/wrench_uncertainty as a refit's
    calibration makes it.
    """
    from dataclasses import replace

    from balance_calib.calibration_file import load_calibration, save_calibration
    from balance_calib.fit.fitted_covariance import with_fitted_covariance

    memo = load_calibration('lmc6522')
    rng = np.random.default_rng(11)
    outputs = rng.uniform(-1.0, 1.0, (300, 6)) * memo.rated_output_mv
    residuals = rng.normal(0.0, 1e-4, (300, 6)) * memo.capacity
    cubic = with_fitted_covariance(memo.model('cubic'), outputs, residuals)
    path = os.path.join(directory, 'calibration.yaml')
    save_calibration(path, replace(memo, models={**memo.models, 'cubic': cubic}))
    return path


def _node_commands(calibration_file: str):
    relay = [sys.executable, '-m', 'balance_calib.benchmarks.relay_node']
    raw_relay = [
        sys.executable,
        '-m',
        'balance_calib.benchmarks.live_throughput',
        '--node',
        'raw-relay',
    ]
    both_topics = raw_relay[:-1] + ['raw-relay-both']
    calibrator = [
        'balance_calibrator',
        '--ros-args',
        '-p',
        f'calibration_file:={calibration_file}',
        '-p',
        'diagnostics_period_s:=1.0',
        '-p',
        f'input_depth:={QOS_DEPTH}',
    ]
    return [
        ('harness ceiling', None),
        ('bare relay', relay),
        ('raw relay', raw_relay),
        (BOTH_TOPICS, both_topics),
        (PURE_CORE, calibrator),
        ('balance_calibrator', calibrator),
        (WRENCH_ONLY, calibrator + ['-p', 'publish_uncertainty:=false']),
    ]


def raw_relay_main(both_topics: bool = False) -> None:
    """Bytes in, bytes out, the calibrator's reader (nodes/_raw_input.py: own thread, batches):
    rclpy's ceiling for a node that does nothing. both_topics: each sample also goes out on the
    uncertainty topic, as the calibrator's do: the floor of any rclpy node with the calibrator's
    topics, before it decodes, computes or encodes anything.
    """
    from geometry_msgs.msg import WrenchStamped
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from balance_calib.nodes._raw_input import RawInput

    rclpy.init()
    node = rclpy.create_node('raw_relay')
    qos = QoSProfile(depth=QOS_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
    publisher = node.create_publisher(WrenchStamped, '/balance/wrench', qos)
    second = node.create_publisher(WrenchStamped, UNCERTAINTY_TOPIC, qos) if both_topics else None

    def relay(batch):
        publish = publisher.publish
        for data in batch:
            publish(data)
        if second is not None:
            publish = second.publish
            for data in batch:
                publish(data)

    reader = RawInput(node, WrenchStamped, '/balance/raw', qos, relay)
    reader.start()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        reader.close()
        node.destroy_node()
        rclpy.try_shutdown()


def _start(command, env):
    return subprocess.Popen(
        command,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )


def _stop(process):
    os.killpg(process.pid, signal.SIGINT)
    try:
        process.wait(timeout=10)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)


def _machine_line() -> str:
    load = os.getloadavg()
    return (
        f'machine: {platform.machine()}, {os.cpu_count()} cores, Python '
        f'{platform.python_version()}, '
        f'{os.environ.get("RMW_IMPLEMENTATION", "default rmw")}; load average {load[0]:.1f} '
        'over the last '
        f"minute (the benchmark's own processes included)"
    )


def _whole(results: list, r: dict) -> bool:
    """Every sample back on every topic (the second topic checked for a row that published on it at
    all: see --calibrator-parameter), sent at >= 95 % of the rate aimed at.
    """
    two_topics = any(other['uncertainty_received'] for other in results)
    return (
        r['received'] == r['sent']
        and r['achieved'] >= 0.95 * r['rate']
        and (not two_topics or r['uncertainty_received'] == r['sent'])
    )


def _whole_rates(results: list) -> set:
    """The rates at which every trial came back whole."""
    return {
        rate
        for rate in {r['rate'] for r in results}
        if all(_whole(results, r) for r in results if r['rate'] == rate)
    }


def zero_loss_rate(results: list) -> float:
    """The highest rate at which every trial came back whole (0 if none did). A lower rate may have
    lost samples in one of its trials (first_loss_rate says which): losses come from scheduling
    stalls on two cores, not from a sharp ceiling.
    """
    lossless = _whole_rates(results)
    return max(lossless) if lossless else 0.0


def first_loss_rate(results: list) -> float:
    """The lowest rate at which some trial lost a sample (NaN if none did)."""
    lost = [r['rate'] for r in results if not _whole(results, r)]
    return min(lost) if lost else float('nan')


def medians_at_1k(results: list) -> dict | None:
    """At 1 kHz: the median over the trials of CPU per sample, p50 and p99 (None if 1 kHz was
    not run).
    """
    ones = [r for r in results if r['rate'] == 1000.0]
    if not ones:
        return None
    return {
        key: float(np.median([r[key] for r in ones]))
        for key in ('cpu_us_per_sample', 'p50_ms', 'p99_ms')
    }


def cpu_budget(summary: dict, labels: tuple) -> tuple[float, dict] | None:
    """The two cores' budget per sample: at the highest rate at which every trial of every row in
    `labels` came back whole, the median over its trials of node, source and sink CPU per sample
    (µs) and their total, per row. Were the two cores what runs out, a row's zero-loss rate would
    go as 1 / total; at 10-12 kHz they are 1.0-1.5 cores busy and the losses come from stalls
    (README), so the ratio of totals is evidence of where the CPU goes, not a prediction of the
    rate. None if some row is missing or no rate is whole in all of them.
    """
    rows = [summary.get(label) for label in labels]
    if any(not row for row in rows):
        return None
    common = set.intersection(*(_whole_rates(row) for row in rows))
    if not common:
        return None
    rate = max(common)
    budget = {}
    for label, row in zip(labels, rows):
        at = [r for r in row if r['rate'] == rate]
        node, source, sink = (
            float(np.median([r[key] for r in at]))
            for key in ('cpu_us_per_sample', 'source_us_per_sample', 'sink_us_per_sample')
        )
        budget[label] = {
            'node': node,
            'source': source,
            'sink': sink,
            'total': node + source + sink,
        }
    return rate, budget


def throughput(rates, seconds, only=None, calibrator_args=(), trials: int = 1) -> None:
    import tempfile

    import rclpy

    env = dict(os.environ)
    summary = {}
    calibration_file = calibration_with_covariance(tempfile.mkdtemp(prefix='live_throughput_'))
    rclpy.init()
    try:
        for label, command in _node_commands(calibration_file):
            if only and label not in only:
                continue
            if command and command[0] == 'balance_calibrator':
                command = command + [a for item in calibrator_args for a in ('-p', item)]
            print(f'{label}:', flush=True)
            process = (
                None
                if command is None
                else _start(
                    command,
                    {**env, 'BALANCE_CALIB_LONE_KERNEL': '0'} if label == PURE_CORE else env,
                )
            )
            harness = Harness(
                rclpy.create_node(
                    'benchmark_' + ''.join(c if c.isalnum() else '_' for c in label)
                ),
                '/balance/raw' if command is None else '/balance/wrench',
                label != WRENCH_ONLY,
            )
            try:
                harness.wait_connected()
                if label in (BOTH_TOPICS, PURE_CORE, 'balance_calibrator'):
                    harness.wait_uncertainty_connected()
                summary[label] = []
                for rate in rates:
                    for trial in range(trials):
                        result = harness.run(
                            rate, seconds, None if process is None else process.pid
                        )
                        summary[label].append(result)
                        also = (
                            f' (+{result["uncertainty_received"]} uncertainty)'
                            if result['uncertainty_received']
                            else ''
                        )
                        step = f'{rate:6.0f} Hz' if trial == 0 else f'{"":>6s} #{trial + 1}'
                        print(
                            f'  {step} (sent at {result["achieved"]:6.0f}): '
                            f'{result["received"]}/{result["sent"]} back{also}, p50 '
                            f'{result["p50_ms"]:.3f} ms, p99 {result["p99_ms"]:.3f} ms, CPU '
                            f'{result["cpu_us_per_sample"]:.1f} µs/sample (source '
                            f'{result["source_us_per_sample"]:.0f}, sink '
                            f'{result["sink_us_per_sample"]:.0f})',
                            flush=True,
                        )
                        if rate == 1000.0 and result['threads']:
                            print(
                                '         by thread (CPU µs, wake-ups per sample): '
                                + ', '.join(
                                    f'{group} {cpu:.0f} µs {wakes:.1f}'
                                    for group, (cpu, wakes) in result['threads'].items()
                                ),
                                flush=True,
                            )
                    if any(
                        r['received'] < 0.5 * r['sent']
                        for r in summary[label]
                        if r['rate'] == rate
                    ):
                        break  # far beyond this node's rate: the next steps say nothing new
            finally:
                harness.close()
                if process is not None:
                    _stop(process)
    finally:
        rclpy.try_shutdown()

    best, first_loss, at_1k = zero_loss_rate, first_loss_rate, medians_at_1k
    print('\n' + _machine_line())
    if trials > 1:
        print(
            f'{trials} trials of {seconds:g} s per rate: zero-loss = every trial whole; at 1 '
            'kHz the medians'
        )
    print(
        f'{"":24s} {"zero-loss Hz":>12s} {"first loss Hz":>13s} {"CPU µs/sample @1k":>18s} '
        f'{"p50 ms @1k":>11s} {"p99 ms @1k":>11s}'
    )
    for label, results in summary.items():
        one = at_1k(results) or {}
        lost = first_loss(results)
        print(
            f'{label:24s} {best(results):12.0f} {"none" if lost != lost else f"{lost:.0f}":>13s} '
            f'{one.get("cpu_us_per_sample", float("nan")):18.1f} '
            f'{one.get("p50_ms", float("nan")):11.3f} {one.get("p99_ms", float("nan")):11.3f}'
        )
    bare, raw, cal, floor = (
        summary.get(k) for k in ('bare relay', 'raw relay', 'balance_calibrator', BOTH_TOPICS)
    )
    if bare and raw and cal:
        ceiling = best(summary['harness ceiling'])
        print(
            f'harness ceiling / bare relay rate: {ceiling / max(best(bare), 1):.1f} (should be '
            '>= 3)'
        )
        print(
            f'calibrator zero-loss rate: {best(cal) / max(best(bare), 1):.2f} x bare relay '
            f'(target >= 2.0), {best(cal) / max(best(raw), 1):.2f} x raw relay (target >= 0.8)'
        )
        if at_1k(cal) and at_1k(bare) and at_1k(raw):
            print(
                'calibrator CPU per sample: '
                f'{at_1k(cal)["cpu_us_per_sample"] / at_1k(bare)["cpu_us_per_sample"]:.2f} x '
                'bare relay (target <= 0.5); added p99 over the raw relay: '
                f'{at_1k(cal)["p99_ms"] - at_1k(raw)["p99_ms"]:+.3f} ms (target <= 0.2)'
            )
        only_wrench = summary.get(WRENCH_ONLY)
        if only_wrench:
            print(
                'calibrator with balance/wrench only (publish_uncertainty:=false, one topic as '
                f'the raw relay): {best(only_wrench) / max(best(raw), 1):.2f} x raw relay'
            )
        if floor:
            print(
                'floor (raw relay, 2 topics) zero-loss rate: '
                f'{best(floor) / max(best(raw), 1):.2f} x raw relay; calibrator '
                f'{best(cal) / max(best(floor), 1):.2f} x floor'
            )
        pure = summary.get(PURE_CORE)
        if pure and at_1k(pure) and at_1k(cal):
            print(
                'lone-sample C kernel: CPU per sample at 1 kHz '
                f'{at_1k(cal)["cpu_us_per_sample"]:.0f} µs against '
                f'{at_1k(pure)["cpu_us_per_sample"]:.0f} µs with the pure core '
                f'({at_1k(cal)["cpu_us_per_sample"] / at_1k(pure)["cpu_us_per_sample"]:.2f} x)'
            )
        budget = cpu_budget(summary, ('raw relay', BOTH_TOPICS, 'balance_calibrator'))
        if budget:
            rate, rows = budget
            print(
                f'CPU per sample at {rate:.0f} Hz, the highest rate all three came back whole '
                '(node + source + sink = total, µs): '
                + '; '.join(
                    f'{label} {b["node"]:.0f} + {b["source"]:.0f} + {b["sink"]:.0f} = '
                    f'{b["total"]:.0f}'
                    for label, b in rows.items()
                )
            )
            raw_total = rows['raw relay']['total']
            print(
                'rate the two cores would allow were they what runs out (raw relay total / row '
                f'total): floor {raw_total / rows[BOTH_TOPICS]["total"]:.2f}, calibrator '
                f'{raw_total / rows["balance_calibrator"]["total"]:.2f} x raw relay; the '
                "calibrator's node "
                f'{rows["balance_calibrator"]["node"] - rows[BOTH_TOPICS]["node"]:+.0f} '
                "µs/sample over the floor's"
            )
        if floor and at_1k(floor) and at_1k(bare) and at_1k(cal):
            bare_us, floor_us = at_1k(bare)['cpu_us_per_sample'], at_1k(floor)['cpu_us_per_sample']
            print(
                f"floor (raw relay publishing both of the calibrator's topics, no arithmetic): "
                f"{floor_us / bare_us:.2f} x bare relay; the calibrator's own work (decode, "
                "calibrate, "
                'uncertainty, encode, bookkeeping): '
                f'{at_1k(cal)["cpu_us_per_sample"] - floor_us:.0f} µs/sample, '
                f'against {0.5 * bare_us - floor_us:.0f} µs left by the CPU target'
            )


def refit_latency(bag: str, seconds: float) -> None:
    """Latency of the calibrator at 1 kHz, quiet and during ~/refit of `bag`."""
    import tempfile

    import rclpy
    from std_srvs.srv import Trigger

    rclpy.init()
    workdir = tempfile.mkdtemp(prefix='refit_latency_')
    from balance_calib.calibration_file import load_calibration, save_calibration

    calibration_file = os.path.join(workdir, 'calibration.yaml')
    save_calibration(calibration_file, load_calibration('lmc6522'))
    command = [
        'balance_calibrator',
        '--ros-args',
        '-p',
        f'calibration_file:={calibration_file}',
        '-p',
        f"calibration_bags:=['{bag}']",
        '-p',
        f'report_dir:={workdir}/reports',
    ]
    process = _start(command, dict(os.environ))
    harness = Harness(rclpy.create_node('benchmark_refit'), '/balance/wrench')
    client = harness.node.create_client(Trigger, '/balance_calibrator/refit')
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor()  # only the service client: the sink is its own process
    executor.add_node(harness.node)
    spinning = threading.Thread(target=executor.spin, daemon=True)
    spinning.start()
    try:
        harness.wait_connected()
        quiet = harness.run(1000.0, seconds, process.pid)
        harness.ask('reset')
        future = client.call_async(Trigger.Request())
        sent, start = 0, time.monotonic()
        while not future.done() or sent < 1000:
            delay = start + sent / 1000.0 - time.monotonic()
            if delay > 0.0005:
                time.sleep(delay)
            harness.send()
            sent += 1
        refit_s = time.monotonic() - start
        settle = time.monotonic() + 3.0
        while time.monotonic() < settle and int(harness.ask('count')) < sent:
            time.sleep(0.02)
        during = json.loads(harness.ask('stats'))
        if os.environ.get('LIVE_THROUGHPUT_DUMP'):
            harness.ask(f'dump {os.environ["LIVE_THROUGHPUT_DUMP"]}')
    finally:
        executor.shutdown(timeout_sec=1.0)
        harness.close()
        _stop(process)
        rclpy.try_shutdown()
    print(_machine_line())
    print(
        f'quiet, 1 kHz {seconds:g} s: {quiet["received"]}/{quiet["sent"]} back, p50 '
        f'{quiet["p50_ms"]:.3f} ms, p99 {quiet["p99_ms"]:.3f} ms'
    )
    print(
        f'during ~/refit ({refit_s:.1f} s, reply: {future.result().message[:100]}...): '
        f'{during["received"]}/{sent} back, p50 {during["p50_ms"]:.3f} ms, p99 '
        f'{during["p99_ms"]:.3f} ms, max {during["max_ms"]:.1f} ms'
    )
    print(f'p99 during / quiet: {during["p99_ms"] / quiet["p99_ms"]:.2f} (target <= 2)')


def _only(text: str) -> list:
    """--only's labels: separated by ';' if there is one (a label has a comma in it), else by
    ','.
    """
    return [label.strip() for label in text.split(';' if ';' in text else ',')]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--rates', default='1000,2000,4000,6000,8000,10000,12000,16000,20000')
    parser.add_argument('--seconds', type=float, default=2.0)
    parser.add_argument(
        '--trials',
        type=int,
        default=1,
        help=(
            'runs of each rate (1-20); zero-loss needs every one whole, 1 kHz figures are medians'
        ),
    )
    parser.add_argument('--domain', type=int, default=int(os.environ.get('ROS_DOMAIN_ID', '77')))
    parser.add_argument(
        '--refit', metavar='BAG', help='measure latency quiet and during ~/refit of BAG'
    )
    parser.add_argument(
        '--only',
        help='subset of: harness ceiling; bare relay; raw relay; '
        f'{BOTH_TOPICS}; {PURE_CORE}; balance_calibrator; {WRENCH_ONLY} (separated by ";", '
        'or by "," when none has a comma)',
    )
    parser.add_argument(
        '--calibrator-parameter',
        action='append',
        default=[],
        metavar='NAME:=VALUE',
        help='extra balance_calibrator parameter (repeatable), e.g. publish_uncertainty:=false',
    )
    parser.add_argument(
        '--node', choices=['raw-relay', 'raw-relay-both', 'sink'], help=argparse.SUPPRESS
    )
    parser.add_argument('--topic', action='append', help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if not 1 <= args.trials <= 20:
        parser.error(f'--trials {args.trials}: must be 1 to 20')
    if args.node in ('raw-relay', 'raw-relay-both'):
        raw_relay_main(args.node == 'raw-relay-both')
        return
    if args.node == 'sink':
        sink_main(args.topic or ['/balance/wrench'])
        return
    os.environ.update(ROS_DOMAIN_ID=str(args.domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    if args.refit:
        refit_latency(args.refit, args.seconds)
    else:
        throughput(
            [float(r) for r in args.rates.split(',')],
            args.seconds,
            _only(args.only) if args.only else None,
            args.calibrator_parameter,
            args.trials,
        )


if __name__ == '__main__':
    main()
