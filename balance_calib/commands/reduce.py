"""balance-calib reduce BAG [BAG ...] --calibration CAL.yaml --model MODEL.yaml --out DIR
[--compare linear,quadratic,cubic] (interfaces.md, "Wind-tunnel data reduction").
"""

from __future__ import annotations

import math
from pathlib import Path

from .run_arguments import add_model_arguments


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'reduce',
        help='wind-on bags -> aerodynamic coefficients per held attitude (TM-663 §10.3-10.4)',
        description=(
            'Find the held attitudes of a wind-on run, average them, subtract the model weight '
            'tare (load space, from the wind-off sweep or the model file), correct the attitude '
            'for deflection, transfer the moments to the moment reference centre and write '
            'coefficients.csv, report.md and one figure per coefficient against α.'
        ),
    )
    parser.add_argument(
        'bags', nargs='+', help='rosbag2 directories or bare .mcap files of one run'
    )
    parser.add_argument(
        '--calibration',
        required=True,
        help='calibration.yaml, or a balance config (lmc6522, b660h)',
    )
    add_model_arguments(parser, model_default=None, permutations=True)
    parser.add_argument('--out', required=True, help='output directory')
    parser.add_argument(
        '--compare',
        default='',
        help='other calibration models to reduce the same run through, '
        'e.g. linear,quadratic,cubic',
    )
    parser.add_argument(
        '--calibration-model',
        default='adopted',
        help="the model of the main columns (default: the calibration's adopted model)",
    )
    parser.add_argument(
        '--estimate-weight',
        action='store_true',
        help='estimate weight and CG from the wind-off sweep even if the model file declares them',
    )
    parser.add_argument(
        '--settle-samples', type=int, default=0, help='samples skipped at the start of each hold'
    )
    parser.add_argument(
        '--point-samples',
        type=int,
        default=0,
        help='average this many samples of each hold (0: the whole hold)',
    )
    parser.add_argument(
        '--min-samples', type=int, default=5, help='shorter holds are transients (default 5)'
    )
    parser.add_argument(
        '--attitude-tolerance-deg',
        type=float,
        default=math.degrees(1e-4),
        help='a support angle moving more than this between samples starts a new hold',
    )
    parser.add_argument(
        '--max-input-age-s',
        type=float,
        default=0.5,
        help='attitude and q∞ older than this at a raw sample make it stale (left out)',
    )
    parser.add_argument(
        '--electrical-zero-mv',
        default='',
        help="six bridge outputs with nothing on the balance (the calibrator's ~/zero), mV, "
        'comma-separated: subtracted in output space before the calibration (default: the '
        "zero a live balance_calibrator stated in the bags' /diagnostics, if any)",
    )
    parser.add_argument(
        '--zero-drift',
        choices=('linear', 'none'),
        default='linear',
        help='linear (default): the wind-off offsets interpolated in time between the pre-run '
        'and post-run wind-off sweeps (same attitudes); none: the pre-run offsets throughout',
    )
    parser.add_argument(
        '--raw-topic',
        default='/balance/raw',
        help='topic of the bridge outputs in the bags (default /balance/raw)',
    )
    parser.add_argument(
        '--attitude-topic',
        default='/model/attitude',
        help='topic of the support attitude φ, α, β in the bags (default /model/attitude)',
    )
    parser.add_argument(
        '--dynamic-pressure-topic',
        default='/tunnel/dynamic_pressure',
        help='topic of q∞ in the bags (default /tunnel/dynamic_pressure)',
    )
    parser.set_defaults(func=run)


def run(args) -> int:
    from ..aero.held_points import HoldSettings
    from ..aero.pipeline import reduce_bags, ReduceError, ReduceOptions
    from ..aero.report import write_outputs
    from ..bags.errors import BagError
    from ..config import ConfigError
    from .errors import CommandError

    compare = [c.strip() for c in args.compare.split(',') if c.strip()]
    try:
        settings = HoldSettings(
            attitude_tolerance_rad=math.radians(args.attitude_tolerance_deg),
            settle_samples=args.settle_samples,
            point_samples=args.point_samples,
            min_samples=args.min_samples,
        )
        if not args.max_input_age_s > 0:
            raise ValueError(f'--max-input-age-s must be positive, not {args.max_input_age_s}')
        zero = None
        if args.electrical_zero_mv.strip():
            try:
                zero = [float(v) for v in args.electrical_zero_mv.split(',')]
            except ValueError:
                zero = []
            if len(zero) != 6 or not all(math.isfinite(v) for v in zero):
                raise ValueError(
                    f'--electrical-zero-mv {args.electrical_zero_mv!r}: give six numbers in mV, '
                    f'F_XV,F_YV,F_ZV,M_XV,M_YV,M_ZV'
                )
        options = ReduceOptions(
            compare=compare,
            calibration_model=args.calibration_model,
            installation=args.installation,
            settings=settings,
            max_input_age_s=args.max_input_age_s,
            estimate_weight=args.estimate_weight,
            raw_topic=args.raw_topic,
            attitude_topic=args.attitude_topic,
            dynamic_pressure_topic=args.dynamic_pressure_topic,
            electrical_zero_mv=zero,
            zero_drift=args.zero_drift,
        )
        reduction = reduce_bags(args.bags, args.calibration, args.model, options)
    except (ReduceError, BagError, ConfigError, ValueError) as err:
        raise CommandError(str(err)) from None
    written = write_outputs(reduction, Path(args.out))
    points = reduction.main.result.wind_on
    print(
        f'{reduction.model.name} on {reduction.calibration.balance}: {len(points)} held wind-on '
        f'attitudes reduced through {", ".join(r.name for r in reduction.runs)}'
    )
    if reduction.electrical_zero_source and reduction.electrical_zero_mv is not None:
        from ..aero.report import electrical_zero_text

        print(f'electrical zero: {electrical_zero_text(reduction)}')
    main = reduction.main
    drift = main.zero_drift
    if drift.shift is None:
        print(f'zero drift: not corrected: {drift.reason}')
    elif main.zero_shift_pct_fs is not None:
        shift = ', '.join(
            f'{c} {v:+.4f}'
            for c, v in zip(reduction.calibration.components, main.zero_shift_pct_fs)
        )
        how = 'interpolated linearly in time' if drift.corrected else 'not corrected (none)'
        print(f'zero drift ({main.name}): shift post − pre % FS {shift}; {how}')
    for warning in (w for r in reduction.runs for w in r.result.warnings):
        print(f'warning: {warning}')
    print(f'coefficients: {written[0]}')
    print(f'report: {written[1]}')
    return 0
