"""The DDS harness of the live benchmarks (live_throughput.py, daq_throughput.py): a source that
publishes pre-serialized samples (a byte template with the stamp patched in), a sink in its own
process that reads only the stamp, the raw relay node, CPU per thread from /proc, and starting and
stopping the nodes measured.
"""

from __future__ import annotations

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


def start_process(command: list[str], env: dict[str, str]) -> subprocess.Popen:
    """Start a measured node in its own session, its output discarded; stop_process ends it."""
    return subprocess.Popen(
        command,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )


def stop_process(process: subprocess.Popen) -> None:
    """SIGINT to the node's process group; SIGKILL when it has not ended within 10 s."""
    os.killpg(process.pid, signal.SIGINT)
    try:
        process.wait(timeout=10)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)


def machine_line() -> str:
    """The machine, Python and rmw the benchmark ran on and the load average, as one line."""
    load = os.getloadavg()
    return (
        f'machine: {platform.machine()}, {os.cpu_count()} cores, Python '
        f'{platform.python_version()}, '
        f'{os.environ.get("RMW_IMPLEMENTATION", "default rmw")}; load average {load[0]:.1f} '
        'over the last '
        f"minute (the benchmark's own processes included)"
    )
