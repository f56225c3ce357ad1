"""balance-calib check CAL.yaml (TABLE.csv | BAG ...) [--out DIR] [--k 2] (interfaces.md,
"Check loads, and comparing two calibrations"). Exit 0 pass or marginal, 3 fail.
"""

from __future__ import annotations

import json
from pathlib import Path

from .record_arguments import add_record_arguments

EXIT_FAIL = 3


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'check',
        help='check loads before a tunnel entry: pass, marginal or fail (exit 3)',
        description='Read known check loads (a BALFIT-style table, or campaign bags with zero '
        'points) through a calibration after their own zero and tare handling (a table: '
        'series tares estimated with the calibration held fixed; a bag: its zero points and the '
        "calibration's body) and compare each point-component with the applied load: it passes "
        'when |error| <= k·u (u: the uncertainty of the reading as /balance/wrench_uncertainty '
        "gives it, with the point's own scatter). Verdict pass (all pass), marginal (at most 5 "
        '%% fail, each within 1.5·k·u) or fail; check points outside the calibrated range are '
        'named. Prints one line per failed component and the verdict; with --out writes '
        "check.json (also as report.json, the record's file), check.md and check.png. Exit 0 "
        'pass or marginal, 3 fail, 2 bad input.',
    )
    parser.add_argument('calibration', help='calibration.yaml written by refit or fit')
    parser.add_argument(
        'inputs',
        nargs='+',
        help='one check table (.csv, BALFIT-style) or campaign bags (rosbag2 directories or '
        '.mcap files)',
    )
    parser.add_argument(
        '--out', help='directory for check.json (report.json: the same), check.md, check.png'
    )
    parser.add_argument(
        '--k', type=float, default=2.0, help='coverage factor of the limit k·u (default 2)'
    )
    parser.add_argument(
        '--model', default='adopted', help='calibration model (default: the adopted one)'
    )
    add_record_arguments(parser, serial_default="the calibration's `serial`")
    parser.set_defaults(func=run)


def run(args) -> int:
    from ..bags.errors import BagError
    from ..calibration_file import ConfigError, load_calibration, write_text_atomically
    from ..checks.check_loads import CheckInputError, judge, read_check_inputs
    from ..checks.plots import check_figure
    from ..checks.report import check_markdown, failed_lines
    from ..model.inverse import InverseDidNotConverge
    from ..model.uncertainty import UncertaintyUnavailable
    from ..record import signed_record
    from ..refit.load_points import LoadPointError
    from ..tables.balfit_reader import TableError
    from ..zero_points import ZeroPointError
    from .errors import CommandError

    try:
        calibration = load_calibration(args.calibration)
        readings = read_check_inputs(calibration, args.inputs, args.model)
        result = judge(readings, args.k)
    except (
        ConfigError,
        CheckInputError,
        TableError,
        BagError,
        LoadPointError,
        ZeroPointError,
        UncertaintyUnavailable,
        InverseDidNotConverge,
        ValueError,
    ) as err:
        raise CommandError(' '.join(str(err).split())) from None
    summary = result.summary()
    summary['record'] = signed_record(
        balance=calibration.balance,
        serial=args.serial or (calibration.extra or {}).get('serial'),
        operator=args.operator,
        inputs=[args.calibration, *args.inputs],
        calibration=calibration,
        model=readings.model_name,
    )
    for line in failed_lines(summary):
        print(line)
    if args.out:
        out = Path(args.out)
        try:
            out.mkdir(parents=True, exist_ok=True)
            check_figure(result, out / 'check.png')
            write_text_atomically(out / 'check.md', check_markdown(summary, summary['record']))
            text = json.dumps(summary, indent=2, allow_nan=False) + '\n'
            write_text_atomically(out / 'check.json', text)
            # interfaces.md, "A record a laboratory signs": report.json of refit, fit and check
            # carries `record`; check's report.json is its check.json, record included
            write_text_atomically(out / 'report.json', text)
        except OSError as err:
            raise CommandError(f'{err.filename or out}: {err.strerror or err}') from None
        print(f'check: {out / "check.md"}')
    return EXIT_FAIL if result.verdict == 'fail' else 0
