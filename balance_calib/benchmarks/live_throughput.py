"""The live calibrator beside rclpy relays, measured the same way in the same run.

    python -m balance_calib.benchmarks.live_throughput [--rates 1000,2000,4000,...] [--seconds 2]
    python -m balance_calib.benchmarks.live_throughput --refit BAG [--seconds 5]

The harness measures the node, not itself: the source publishes pre-serialized samples (a byte
template with the stamp patched in) and the sink takes bytes (`raw=True`) and reads only the stamp,
so the harness's own ceiling -- source straight to sink, no node between -- is printed first. Then,
each as a subprocess between the same source and sink (reliable, depth 1000 both ways):

- bare relay: Python messages, the default executor, what users write (relay_node.py);
- raw relay: bytes in, bytes out, the calibrator's executor (`--node raw-relay` of this module):
  rclpy's own ceiling for a node;
- balance_calibrator: the memo's cubic matrix with a coefficient covariance (so balance/wrench_uncertainty
  is published too, one more message per sample), diagnostics at 1 Hz.

Per rate: messages back / sent and latency p50/p99 (receive time minus the sample's stamp). Per node:
the highest rate with zero loss, and at 1 kHz the process CPU time per sample (/proc/PID/stat
utime + stime over the samples of that step) and p50/p99 latency.

`--refit BAG` measures what issue 12 asks of ~/refit: the calibrator's latency at 1 kHz while quiet
and while ~/refit fits BAG (in its own process), p50/p99/max, and that no sample is lost.
"""
from __future__ import annotations

import argparse
import os
import platform
import signal
import subprocess
import sys
import threading
import time

import numpy as np

QOS_DEPTH = 1000
CDR_LE = b'\x00\x01\x00\x00'


def _raw_template(frame_id: str = 'LMC6522') -> bytearray:
    from balance_calib.live.raw_codec import WrenchEncoder
    encoder = WrenchEncoder(frame_id)
    values = np.zeros((1, 6))
    values[0, :3] = 0.1, 0.0, 0.2           # inside the calibrated envelope
    return bytearray(encoder.encode(np.zeros(1, np.int64), values)[0])


def _clock_ticks() -> float:
    return float(os.sysconf('SC_CLK_TCK'))


def _cpu_seconds(pid: int) -> float:
    """utime + stime of a process, s (Linux /proc)."""
    with open(f'/proc/{pid}/stat') as handle:
        fields = handle.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / _clock_ticks()


class Harness:
    """Source (pre-serialized) and sink (bytes, stamp only) in this process, on their own executor thread."""

    def __init__(self, node, sink_topic: str):
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from geometry_msgs.msg import WrenchStamped
        qos = QoSProfile(depth=QOS_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
        self.node = node
        self.publisher = node.create_publisher(WrenchStamped, '/balance/raw', qos)
        self.latencies_ns: list[int] = []
        self.lock = threading.Lock()
        self.subscription = node.create_subscription(WrenchStamped, sink_topic, self._on_bytes, qos, raw=True)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(node)
        self.spinning = True
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()
        self.template = _raw_template()

    def _spin(self):
        while self.spinning:
            self.executor.spin_once(timeout_sec=0.05)

    def _on_bytes(self, data: bytes):
        now = time.time_ns()
        stamp = int.from_bytes(data[4:8], 'little', signed=True) * 1_000_000_000 + int.from_bytes(data[8:12], 'little')
        with self.lock:
            self.latencies_ns.append(now - stamp)

    def wait_connected(self, timeout_s: float = 30.0) -> None:
        deadline = time.monotonic() + timeout_s
        while (self.publisher.get_subscription_count() == 0 or self.subscription.get_publisher_count() == 0) \
                and time.monotonic() < deadline:
            time.sleep(0.05)
        for _ in range(100):      # warm-up: discovery on the writer side and first allocations, not measured
            self.send()
            time.sleep(0.005)
        time.sleep(0.5)

    def send(self) -> None:
        sec, nsec = divmod(time.time_ns(), 1_000_000_000)
        message = self.template
        message[4:8] = sec.to_bytes(4, 'little', signed=True)
        message[8:12] = nsec.to_bytes(4, 'little')
        self.publisher.publish(bytes(message))

    def run(self, rate: float, seconds: float, pid: int | None) -> dict:
        with self.lock:
            self.latencies_ns.clear()
        total = int(rate * seconds)
        cpu_before = _cpu_seconds(pid) if pid else 0.0
        start = time.monotonic()
        for i in range(total):
            delay = start + i / rate - time.monotonic()
            if delay > 0.0005:
                time.sleep(delay)
            self.send()
        achieved = total / (time.monotonic() - start)
        settle = time.monotonic() + 3.0
        while time.monotonic() < settle:
            with self.lock:
                if len(self.latencies_ns) >= total:
                    break
            time.sleep(0.02)
        cpu = (_cpu_seconds(pid) - cpu_before) if pid else float('nan')
        with self.lock:
            latencies = np.array(self.latencies_ns, dtype=float) / 1e6
        return {'rate': rate, 'achieved': achieved, 'sent': total, 'received': len(latencies),
                'p50_ms': float(np.percentile(latencies, 50)) if len(latencies) else float('nan'),
                'p99_ms': float(np.percentile(latencies, 99)) if len(latencies) else float('nan'),
                'cpu_us_per_sample': cpu / total * 1e6}

    def close(self):
        self.spinning = False
        self.thread.join(timeout=2)
        self.executor.remove_node(self.node)
        self.node.destroy_node()


def calibration_with_covariance(directory: str) -> str:
    """The memo's LMC6522 cubic matrix with a coefficient covariance and residual σ (from 300 synthetic
    points), so that the calibrator publishes balance/wrench_uncertainty as a refit's calibration makes it."""
    from dataclasses import replace

    from balance_calib.calibration_file import load_calibration, save_calibration
    from balance_calib.model.uncertainty import with_fitted_covariance
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
    raw_relay = [sys.executable, '-m', 'balance_calib.benchmarks.live_throughput', '--node', 'raw-relay']
    calibrator = ['balance_calibrator', '--ros-args', '-p', f'calibration_file:={calibration_file}',
                  '-p', 'diagnostics_period_s:=1.0', '-p', f'input_depth:={QOS_DEPTH}']
    return [('harness ceiling', None), ('bare relay', relay), ('raw relay', raw_relay),
            ('balance_calibrator', calibrator)]


def raw_relay_main() -> None:
    """bytes in, bytes out, the calibrator's executor (rclpy.spin: SingleThreadedExecutor)."""
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.executors import ExternalShutdownException
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    rclpy.init()
    node = rclpy.create_node('raw_relay')
    qos = QoSProfile(depth=QOS_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
    publisher = node.create_publisher(WrenchStamped, '/balance/wrench', qos)
    node.create_subscription(WrenchStamped, '/balance/raw', publisher.publish, qos, raw=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def _start(command, env):
    return subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)


def _stop(process):
    os.killpg(process.pid, signal.SIGINT)
    try:
        process.wait(timeout=10)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)


def _machine_line() -> str:
    load = os.getloadavg()
    return (f'machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, '
            f'{os.environ.get("RMW_IMPLEMENTATION", "default rmw")}; load average {load[0]:.1f} '
            f'(shared machine: other work was running)')


def throughput(rates, seconds) -> None:
    import tempfile

    import rclpy
    env = dict(os.environ)
    summary = {}
    calibration_file = calibration_with_covariance(tempfile.mkdtemp(prefix='live_throughput_'))
    rclpy.init()
    try:
        for label, command in _node_commands(calibration_file):
            print(f'{label}:', flush=True)
            process = None if command is None else _start(command, env)
            harness = Harness(rclpy.create_node(f'benchmark_{label.replace(" ", "_")}'),
                              '/balance/raw' if command is None else '/balance/wrench')
            try:
                harness.wait_connected()
                summary[label] = []
                for rate in rates:
                    result = harness.run(rate, seconds, None if process is None else process.pid)
                    summary[label].append(result)
                    print(f'  {rate:6.0f} Hz (sent at {result["achieved"]:6.0f}): {result["received"]}/'
                          f'{result["sent"]} back, p50 {result["p50_ms"]:.3f} ms, p99 {result["p99_ms"]:.3f} ms, '
                          f'CPU {result["cpu_us_per_sample"]:.1f} µs/sample', flush=True)
                    if result['received'] < 0.5 * result['sent']:
                        break                  # far beyond this node's rate: the next steps say nothing new
            finally:
                harness.close()
                if process is not None:
                    _stop(process)
    finally:
        rclpy.try_shutdown()

    def best(results):
        lossless = [r['rate'] for r in results if r['received'] == r['sent'] and r['achieved'] >= 0.95 * r['rate']]
        return max(lossless) if lossless else 0.0

    def at_1k(results):
        return next((r for r in results if r['rate'] == 1000.0), None)

    print('\n' + _machine_line())
    print(f'{"":20s} {"zero-loss Hz":>12s} {"CPU µs/sample @1k":>18s} {"p50 ms @1k":>11s} {"p99 ms @1k":>11s}')
    for label, results in summary.items():
        one = at_1k(results) or {}
        print(f'{label:20s} {best(results):12.0f} {one.get("cpu_us_per_sample", float("nan")):18.1f} '
              f'{one.get("p50_ms", float("nan")):11.3f} {one.get("p99_ms", float("nan")):11.3f}')
    bare, raw, cal = (summary.get(k) for k in ('bare relay', 'raw relay', 'balance_calibrator'))
    if bare and raw and cal:
        ceiling = best(summary['harness ceiling'])
        print(f'harness ceiling / bare relay rate: {ceiling / max(best(bare), 1):.1f} (should be >= 3)')
        print(f'calibrator zero-loss rate: {best(cal) / max(best(bare), 1):.2f} x bare relay (target >= 2.0), '
              f'{best(cal) / max(best(raw), 1):.2f} x raw relay (target >= 0.8)')
        if at_1k(cal) and at_1k(bare) and at_1k(raw):
            print(f'calibrator CPU per sample: {at_1k(cal)["cpu_us_per_sample"] / at_1k(bare)["cpu_us_per_sample"]:.2f}'
                  f' x bare relay (target <= 0.5); added p99 over the raw relay: '
                  f'{at_1k(cal)["p99_ms"] - at_1k(raw)["p99_ms"]:+.3f} ms (target <= 0.2)')


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
    command = ['balance_calibrator', '--ros-args', '-p', f'calibration_file:={calibration_file}',
               '-p', f"calibration_bags:=['{bag}']", '-p', f'report_dir:={workdir}/reports']
    process = _start(command, dict(os.environ))
    harness = Harness(rclpy.create_node('benchmark_refit'), '/balance/wrench')
    client = harness.node.create_client(Trigger, '/balance_calibrator/refit')
    try:
        harness.wait_connected()
        quiet = harness.run(1000.0, seconds, process.pid)
        with harness.lock:
            harness.latencies_ns.clear()
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
        while time.monotonic() < settle and len(harness.latencies_ns) < sent:
            time.sleep(0.02)
        with harness.lock:
            during = np.array(harness.latencies_ns, dtype=float) / 1e6
    finally:
        harness.close()
        _stop(process)
        rclpy.try_shutdown()
    print(_machine_line())
    print(f'quiet, 1 kHz {seconds:g} s: {quiet["received"]}/{quiet["sent"]} back, p50 {quiet["p50_ms"]:.3f} ms, '
          f'p99 {quiet["p99_ms"]:.3f} ms')
    print(f'during ~/refit ({refit_s:.1f} s, reply: {future.result().message[:100]}...): {len(during)}/{sent} back, '
          f'p50 {np.percentile(during, 50):.3f} ms, p99 {np.percentile(during, 99):.3f} ms, max {during.max():.1f} ms')
    print(f'p99 during / quiet: {np.percentile(during, 99) / quiet["p99_ms"]:.2f} (target <= 2)')


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--rates', default='1000,2000,4000,6000,8000,10000,12000,16000,20000')
    parser.add_argument('--seconds', type=float, default=2.0)
    parser.add_argument('--domain', type=int, default=int(os.environ.get('ROS_DOMAIN_ID', '77')))
    parser.add_argument('--refit', metavar='BAG', help='measure latency quiet and during ~/refit of BAG')
    parser.add_argument('--node', choices=['raw-relay'], help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.node == 'raw-relay':
        raw_relay_main()
        return
    os.environ.update(ROS_DOMAIN_ID=str(args.domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    if args.refit:
        refit_latency(args.refit, args.seconds)
    else:
        throughput([float(r) for r in args.rates.split(',')], args.seconds)


if __name__ == '__main__':
    main()
