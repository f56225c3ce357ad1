"""The live calibrator's per-sample work in-process: the C kernel against the pure core, same
process.

    python -m balance_calib.benchmarks.sample_kernel [--repeats 3000]

CalibratorSession.on_samples (serialized samples in, serialized wrench and uncertainty out,
counters, input monitor and overload included; no DDS) on the memo's cubic LMC6522 with a
coefficient covariance, µs of thread CPU per sample:
- batches of 1, 2, 3, 10, 100 and 1000 samples, back to back (warm caches), best of the repeats;
- lone samples with 1 ms of sleep before each (caches gone cold, as at 1 kHz), mean.
Each figure with the kernel and with the pure core (sample_kernel.available switched off), and
their ratio. The samples are serialized before timing; the timer's own cost is printed first.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

from ..live import sample_kernel
from ..live.parameters import PARAMETERS
from ..live.session import CalibratorSession
from .dds_harness import raw_template, stamped
from .live_throughput import calibration_with_covariance

BATCHES = (1, 2, 3, 10, 100, 1000)


def _messages(count: int, start_ns: int) -> list[bytes]:
    template = raw_template()
    return [stamped(template, start_ns + k * 100_000) for k in range(count)]


def _session(directory: str) -> CalibratorSession:
    values = {name: spec.default for name, spec in PARAMETERS.items()}
    values.update(
        calibration_file=calibration_with_covariance(directory),
        tare_file=os.path.join(directory, 'tare.yaml'),
    )
    return CalibratorSession(lambda name: values[name], 'benchmark', lambda level, line: None)


def measure(repeats: int) -> dict:
    directory = tempfile.mkdtemp(prefix='sample_kernel_')
    results = {}
    built = sample_kernel.available
    for label, kernel in (('kernel', True), ('pure core', False)):
        if kernel and not built:
            print(
                f'the C kernel is not built ({sample_kernel.unavailable_reason}): pure core only'
            )
            continue
        sample_kernel.available = kernel
        try:
            session = _session(directory)
            stamp = time.time_ns()
            for n in BATCHES:
                batch, best = _messages(n, stamp), float('inf')
                stamp += n * 100_000
                for _ in range(max(3, repeats // n)):
                    start = time.thread_time_ns()
                    out = session.on_samples(batch, True)
                    uncertainty = out.uncertainty()
                    best = min(best, time.thread_time_ns() - start)
                    assert len(out.wrench) == len(uncertainty) == n
                results[(label, f'batch of {n}, warm')] = best / n / 1e3
            lone = _messages(min(repeats, 2000), stamp)
            total = 0
            for data in lone:
                time.sleep(0.001)
                start = time.thread_time_ns()
                out = session.on_samples([data], True)
                out.uncertainty()
                total += time.thread_time_ns() - start
            results[(label, 'lone, 1 ms apart (cold)')] = total / len(lone) / 1e3
        finally:
            sample_kernel.available = built
    return results


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument(
        '--repeats', type=int, default=3000, help='samples per batch size (default 3000)'
    )
    args = parser.parse_args(argv)
    best = float('inf')
    for _ in range(10_000):  # the timer pair around nothing: the harness's own floor
        start = time.thread_time_ns()
        best = min(best, time.thread_time_ns() - start)
    print(
        'harness: the samples are serialized before timing; the timer pair itself costs '
        f'{best / 1e3:.2f} µs '
        f"(a lone sample's figure includes it once)"
    )
    results = measure(args.repeats)
    cases = list(dict.fromkeys(case for _, case in results))
    print(f'{"µs of CPU per sample":28s} {"kernel":>8s} {"pure core":>10s} {"ratio":>7s}')
    for case in cases:
        kernel, core = results.get(('kernel', case)), results.get(('pure core', case))
        ratio = f'{kernel / core:7.2f}' if kernel and core else ''
        print(f'{case:28s} {kernel if kernel else float("nan"):8.1f} {core:10.1f} {ratio}')


if __name__ == '__main__':
    main()
