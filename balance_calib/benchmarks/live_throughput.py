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
  (BALANCE_CALIB_LONE_KERNEL=0, live/sample_kernel.py): the kernel's baseline, same run;
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

`--refit BAG` measures what ~/refit must keep: the calibrator's latency at 1 kHz while quiet
and while ~/refit fits BAG (in its own process), p50/p99/max, and that no sample is lost.

The harness is dds_harness.py, the summary's rules loss_summary.py.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time

import numpy as np

from .dds_harness import (
    Harness,
    machine_line,
    QOS_DEPTH,
    raw_relay_main,
    sink_main,
    start_process,
    stop_process,
)
from .loss_summary import cpu_budget, first_loss_rate, medians_at_1k, zero_loss_rate

BOTH_TOPICS = 'raw relay, 2 topics'
PURE_CORE = 'calibrator, pure core'
WRENCH_ONLY = 'calibrator, wrench only'


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
                else start_process(
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
                    stop_process(process)
    finally:
        rclpy.try_shutdown()

    best, first_loss, at_1k = zero_loss_rate, first_loss_rate, medians_at_1k
    print('\n' + machine_line())
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
    process = start_process(command, dict(os.environ))
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
        stop_process(process)
        rclpy.try_shutdown()
    print(machine_line())
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
