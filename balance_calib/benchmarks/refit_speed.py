"""Refit wall time on a full campaign bag beside the time rosbags needs only to read that bag.

    python -m balance_calib.benchmarks.refit_speed [--seconds-per-point 2] [--rate 100]

Writes one simulated LMC6522 campaign (328 points) as an MCAP bag, then measures in this process:
  read_raw     rosbags AnyReader iterating every message (bytes only)
  read_decode  the same plus rosbags deserialize_cdr of every message (what a user script does)
  refit        run_refit: read + cut + zero/tare + 3 fits + diagnosis + report + plots
  written      the same run until calibration.yaml, report.json and report.md are in place (what
               ~/refit's reply waits for; the figures are drawn after)
and prints the ratios. Targets: the whole refit with its figures within 2x
read+deserialize, without figures within 1x.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import platform
import tempfile
import time

from .timing import best_of as _best_of


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--seconds-per-point', type=float, default=2.0)
    parser.add_argument('--rate', type=float, default=100.0)
    parser.add_argument('--repeat', type=int, default=3)
    args = parser.parse_args(argv)

    from rosbags.highlevel import AnyReader
    from rosbags.typesys import get_typestore, Stores

    from balance_calib.calibrate.from_bags import RefitSettings, run_refit
    from balance_calib.config import load_balance_config
    from balance_calib.simulation.balance_sim import (
        simulate_campaign,
        SimulationSettings,
        table17_noise,
    )
    from balance_calib.simulation.campaign_bag import write_campaign_bag

    config = load_balance_config('lmc6522')
    samples = int(args.seconds_per_point * args.rate)
    settings = SimulationSettings(
        samples_per_point=samples,
        transition_samples=max(1, samples // 4),
        point_duration_s=args.seconds_per_point,
        transition_s=args.seconds_per_point / 4,
        noise_sigma_pct_fs=table17_noise(config),
        seed=1,
    )
    with tempfile.TemporaryDirectory() as tmp:
        bag = write_campaign_bag(
            simulate_campaign(config, settings=settings),
            Path(tmp) / 'campaign',
            temperature_every=int(args.rate),
        )  # 1 Hz temperature
        size_mb = sum(f.stat().st_size for f in bag.iterdir()) / 1e6
        store = get_typestore(Stores.ROS2_JAZZY)

        def read_raw():
            with AnyReader([bag], default_typestore=store) as reader:
                return sum(1 for _ in reader.messages())

        def read_decode():
            with AnyReader([bag], default_typestore=store) as reader:
                for connection, _, data in reader.messages():
                    reader.deserialize(data, connection.msgtype)

        messages = read_raw()
        t_raw = _best_of(read_raw, args.repeat)
        t_decode = _best_of(read_decode, args.repeat)
        written: list[float] = []

        def refit_with_figures():
            start = time.perf_counter()
            run_refit(
                [bag],
                'lmc6522',
                Path(tmp) / 'out',
                RefitSettings(written=lambda _: written.append(time.perf_counter() - start)),
            )

        t_refit = _best_of(refit_with_figures, args.repeat)
        t_written = min(written)
        t_refit_noplots = _best_of(
            lambda: run_refit([bag], 'lmc6522', Path(tmp) / 'out2', RefitSettings(plots=False)),
            args.repeat,
        )

    print(
        f'machine: {platform.machine()}, {os.cpu_count()} cores, Python '
        f'{platform.python_version()}'
    )
    print(
        f'bag: 328 points x {args.seconds_per_point:g} s at {args.rate:g} Hz = {messages} '
        f'messages, {size_mb:.1f} MB (MCAP, zstd chunks)'
    )
    print(f'rosbags read (bytes only)           {t_raw:7.2f} s')
    print(f'rosbags read + deserialize          {t_decode:7.2f} s')
    print(
        f'refit (all, incl. 3 PNG plots)      {t_refit:7.2f} s   = {t_refit / t_decode:.2f} x '
        f'read+deserialize, {t_refit / t_raw:.2f} x bytes-only read'
    )
    print(
        f'  of which until the record is written {t_written:7.2f} s   = '
        f'{t_written / t_decode:.2f} x read+deserialize (calibration, report.json, report.md; '
        'figures after)'
    )
    print(
        f'refit without plots                 {t_refit_noplots:7.2f} s   = '
        f'{t_refit_noplots / t_decode:.2f} x read+deserialize, {t_refit_noplots / t_raw:.2f} x '
        'bytes-only read'
    )
    print('targets: refit with its figures within 2x read+deserialize, without within 1x')


if __name__ == '__main__':
    main()
