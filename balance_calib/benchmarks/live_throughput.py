"""The live calibrator beside a bare rclpy relay, measured the same way in the same run.

    python -m balance_calib.benchmarks.live_throughput [--rates 250,500,1000,2000,4000] [--seconds 3]

For each node under test (the bare relay of relay_node.py: subscribe, copy, publish; then
balance_calibrator with the memo's cubic matrix) a subprocess is started, and this process
publishes /balance/raw at each rate for a few seconds and counts what comes back on
/balance/wrench (reliable QoS, depth 1000 both ways). Printed per rate: messages out/in (zero loss
or not) and the added latency p50/p99 (receive time minus the raw sample's stamp, which both
nodes copy). The highest rate with zero loss and the latencies at 1 kHz are compared as ratios.
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


def _node_commands(domain: int):
    relay = [sys.executable, '-m', 'balance_calib.benchmarks.relay_node']
    calibrator = ['balance_calibrator', '--ros-args', '-p', 'calibration_file:=lmc6522',
                  '-p', 'diagnostics_period_s:=1.0', '-p', f'input_depth:={QOS_DEPTH}']
    return [('bare relay', relay), ('balance_calibrator', calibrator)]


def _measure(node, publisher, rates, seconds, msg_type, log):
    from rclpy.executors import SingleThreadedExecutor

    received = []
    lock = threading.Lock()

    def on_wrench(msg):
        now = time.time_ns()
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        with lock:
            received.append(now - stamp)

    from rclpy.qos import QoSProfile, ReliabilityPolicy
    qos = QoSProfile(depth=QOS_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
    subscription = node.create_subscription(msg_type, '/balance/wrench', on_wrench, qos)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spinning = threading.Event()
    spinning.set()

    def spin():
        while spinning.is_set():
            executor.spin_once(timeout_sec=0.05)

    thread = threading.Thread(target=spin, daemon=True)
    thread.start()
    # wait until the node under test is connected both ways
    deadline = time.monotonic() + 30
    while (publisher.get_subscription_count() == 0 or node.count_publishers('/balance/wrench') == 0) \
            and time.monotonic() < deadline:
        time.sleep(0.05)
    results = []
    try:
        message = msg_type()
        message.wrench.force.x, message.wrench.force.z = 0.1, 0.2
        for _ in range(100):      # warm-up: discovery and first allocations, not measured
            publisher.publish(message)
            time.sleep(0.005)
        time.sleep(0.5)
        for rate in rates:
            with lock:
                received.clear()
            total = int(rate * seconds)
            start = time.monotonic()
            for i in range(total):
                target = start + i / rate
                delay = target - time.monotonic()
                if delay > 0.0005:
                    time.sleep(delay)
                now = time.time_ns()
                message.header.stamp.sec, message.header.stamp.nanosec = divmod(now, 1_000_000_000)
                message.wrench.torque.x = 0.001 * (i % 100)     # inside the calibrated envelope
                publisher.publish(message)
            achieved = total / (time.monotonic() - start)
            settle = time.monotonic() + 3.0
            while time.monotonic() < settle:
                with lock:
                    if len(received) >= total:
                        break
                time.sleep(0.02)
            with lock:
                latencies = np.array(received, dtype=float) / 1e6
            results.append({'rate': rate, 'achieved': achieved, 'sent': total, 'received': len(latencies),
                             'p50_ms': float(np.percentile(latencies, 50)) if len(latencies) else float('nan'),
                             'p99_ms': float(np.percentile(latencies, 99)) if len(latencies) else float('nan')})
            log(f'  {rate:6.0f} Hz (sent at {achieved:6.0f}): {len(latencies)}/{total} back, '
                f'p50 {results[-1]["p50_ms"]:.3f} ms, p99 {results[-1]["p99_ms"]:.3f} ms')
    finally:
        spinning.clear()
        thread.join(timeout=2)
        executor.remove_node(node)
        node.destroy_subscription(subscription)
    return results


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--rates', default='500,1000,2000,3000,4000,5000,6000,7000,8000,10000')
    parser.add_argument('--seconds', type=float, default=3.0)
    parser.add_argument('--domain', type=int, default=int(os.environ.get('ROS_DOMAIN_ID', '77')))
    args = parser.parse_args(argv)
    rates = [float(r) for r in args.rates.split(',')]
    env = dict(os.environ, ROS_DOMAIN_ID=str(args.domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    os.environ.update(ROS_DOMAIN_ID=str(args.domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')

    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    rclpy.init()
    summary = {}
    try:
        for label, command in _node_commands(args.domain):
            print(f'{label}:', flush=True)
            process = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                       start_new_session=True)
            node = rclpy.create_node(f'benchmark_source_{label.replace(" ", "_")}')
            publisher = node.create_publisher(WrenchStamped, '/balance/raw',
                                              QoSProfile(depth=QOS_DEPTH, reliability=ReliabilityPolicy.RELIABLE))
            try:
                summary[label] = _measure(node, publisher, rates, args.seconds, WrenchStamped,
                                          lambda s: print(s, flush=True))
            finally:
                node.destroy_node()
                os.killpg(process.pid, signal.SIGINT)
                try:
                    process.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    os.killpg(process.pid, signal.SIGKILL)
    finally:
        rclpy.try_shutdown()

    def best_rate(results, max_p50_ms=float('inf')):
        lossless = [r['rate'] for r in results if r['received'] == r['sent'] and r['p50_ms'] <= max_p50_ms]
        return max(lossless) if lossless else 0.0

    def at(results, rate):
        return next((r for r in results if r['rate'] == rate), None)

    relay, calibrator = summary['bare relay'], summary['balance_calibrator']
    print(f'\nmachine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, '
          f'{os.environ.get("RMW_IMPLEMENTATION", "default rmw")}')
    r_best, c_best = best_rate(relay), best_rate(calibrator)
    print(f'highest rate with zero loss: relay {r_best:.0f} Hz, calibrator {c_best:.0f} Hz '
          f'-> {c_best / r_best if r_best else float("nan"):.2f} x relay (target >= 0.9)')
    # zero loss can hide a backlog that only drained after the run; also require it to keep up
    r_kept, c_kept = best_rate(relay, 10.0), best_rate(calibrator, 10.0)
    print(f'highest rate with zero loss and p50 latency under 10 ms (no growing backlog): relay {r_kept:.0f} Hz, '
          f'calibrator {c_kept:.0f} Hz -> {c_kept / r_kept if r_kept else float("nan"):.2f} x relay')
    r1k, c1k = at(relay, 1000.0), at(calibrator, 1000.0)
    if r1k and c1k:
        print(f'latency at 1 kHz: relay p50 {r1k["p50_ms"]:.3f} ms, p99 {r1k["p99_ms"]:.3f} ms; calibrator p50 '
              f'{c1k["p50_ms"]:.3f} ms, p99 {c1k["p99_ms"]:.3f} ms (added by calibration: p50 '
              f'{c1k["p50_ms"] - r1k["p50_ms"]:+.3f} ms, p99 {c1k["p99_ms"] - r1k["p99_ms"]:+.3f} ms)')


if __name__ == '__main__':
    main()
