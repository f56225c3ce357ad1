"""balance-calib coverage CAL.yaml (BAG ... | LOADS.csv) [--out DIR] (interfaces.md, "Coverage
of a run, and design of calibration points").
"""

from __future__ import annotations

import json
from pathlib import Path
import sys

SIX = ('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ')


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'coverage',
        help='does a calibration cover a run? predicted uncertainty at every load',
        description='At every load of a run (the /balance/wrench of wind-on bags, or a CSV '
        'FX,FY,FZ,MX,MY,MZ in N and N·m, balance axes) the standard uncertainty '
        '(k = 1) the calibration predicts from its coefficient covariance (as '
        'balance_calibrator publishes it on /balance/wrench_uncertainty), and the '
        "share of the run outside the support of the calibration's schedule, per "
        "component against the calibration's σ. Prints the summary; with --out "
        "writes coverage.json and coverage.png. A bag's wrenches are what the "
        "calibrator published: a live tare has taken the model's weight out of them. A bag "
        'without them (launchless_scripts/windon records none) is read from its /balance/raw '
        "through the calibration: the loads the balance carried, the model's weight included.",
    )
    parser.add_argument('calibration', help='calibration.yaml written by refit or fit')
    parser.add_argument(
        'run', nargs='+', help='wind-on bags (rosbag2 directories or .mcap files) or one LOADS.csv'
    )
    parser.add_argument('--out', help='directory for coverage.json and coverage.png')
    parser.add_argument(
        '--model', default='adopted', help='calibration model (default: the adopted one)'
    )
    parser.add_argument(
        '--installation',
        default='upright',
        help='bags: how the balance was installed, to turn /balance/wrench '
        '(tunnel axes) back into balance axes: upright, inverted or a '
        'signed permutation (default upright)',
    )
    parser.add_argument(
        '--wrench-topic',
        default='/balance/wrench',
        help='bags: topic of the calibrated loads (default /balance/wrench)',
    )
    parser.set_defaults(func=run)


def run(args) -> int:
    from ..bags.errors import BagError
    from ..calibration_file import ConfigError, load_calibration, write_text_atomically
    from ..coverage.plots import coverage_figure
    from ..coverage.run import run_coverage, summary_table
    from ..coverage.run_inputs import (
        read_loads_csv,
        read_raw_bags,
        read_wrench_bags,
        RunInputError,
    )
    from ..model.inverse import InverseDidNotConverge
    from ..model.uncertainty import UncertaintyUnavailable
    from ..tunnel_axes import parse_installation
    from .errors import CommandError

    try:
        calibration = load_calibration(args.calibration)
        time_s, loads, outputs = None, None, None
        first = Path(args.run[0])
        if len(args.run) == 1 and first.suffix.lower() == '.csv':
            loads = read_loads_csv(first, calibration.components)
        else:
            if tuple(calibration.components) != SIX:
                raise CommandError(
                    f'{args.calibration}: bags carry six-component wrenches; this '
                    f'calibration has components '
                    f'{", ".join(calibration.components)}: give a LOADS.csv'
                )
            try:
                time_s, loads = read_wrench_bags(
                    args.run, parse_installation(args.installation), args.wrench_topic
                )
            except BagError as err:
                if f'no messages on {args.wrench_topic}' not in str(err):
                    raise
                # a run recorded without a calibrator (launchless_scripts/windon): its raw outputs
                time_s, outputs = read_raw_bags(args.run, calibration.model(args.model).inputs)
                print(
                    f'coverage: no {args.wrench_topic} in the bags: the loads are the '
                    "calibration's reading of /balance/raw (the model's weight included)",
                    file=sys.stderr,
                )
        coverage = (
            run_coverage(calibration, loads, model=args.model)
            if outputs is None
            else run_coverage(calibration, outputs_mv=outputs, model=args.model)
        )
    except (
        ConfigError,
        RunInputError,
        BagError,
        UncertaintyUnavailable,
        InverseDidNotConverge,
        ValueError,
    ) as err:
        raise CommandError(' '.join(str(err).split())) from None
    summary = coverage.summary()
    print(summary_table(summary, coverage.components))
    if args.out:
        out = Path(args.out)
        try:
            out.mkdir(parents=True, exist_ok=True)
            write_text_atomically(out / 'coverage.json', json.dumps(summary, indent=2) + '\n')
            coverage_figure(coverage, out / 'coverage.png', time_s)
        except OSError as err:
            raise CommandError(f'{err.filename or out}: {err.strerror or err}') from None
        print(f'coverage: {out / "coverage.json"}')
    return 0
