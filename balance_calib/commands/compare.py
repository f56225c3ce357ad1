"""balance-calib compare CAL_A.yaml CAL_B.yaml [--loads LOADS.csv] [--out DIR] (interfaces.md,
"Check loads, and comparing two calibrations"). Exit 0 when nothing changed, 3 when a component
did.
"""

from __future__ import annotations

import json
from pathlib import Path

EXIT_CHANGED = 3


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'compare',
        help='did the balance change between two calibrations? (exit 3 when it did)',
        description="Read the bridge outputs calibration A reads as its own calibration points' "
        'total loads (or the loads of --loads) through both calibrations of one balance; per '
        'component the difference B − A in %% FS, RMS and worst, against the combined standard '
        'uncertainty √(u_A² + u_B²): changed when the RMS difference exceeds twice the RMS '
        'combined u. Also the change of each primary sensitivity, (S_B/S_A − 1)·100. Two '
        'calibrations of different balances, components or units are refused. With --out writes '
        'compare.json, compare.md and compare.png. Exit 0 unchanged, 3 changed, 2 bad input.',
    )
    parser.add_argument('calibration_a', help='the earlier calibration.yaml (A)')
    parser.add_argument('calibration_b', help='the later calibration.yaml (B)')
    parser.add_argument(
        '--loads',
        metavar='LOADS.csv',
        help='compare at these loads (header FX,FY,FZ,MX,MY,MZ, N and N·m, balance axes, total '
        "loads) instead of A's own calibration points",
    )
    parser.add_argument('--out', help='directory for compare.json, compare.md and compare.png')
    parser.add_argument(
        '--model', default='adopted', help='model of both calibrations (default: the adopted)'
    )
    parser.set_defaults(func=run)


def run(args) -> int:
    from ..calibration_file import ConfigError, load_calibration, write_text_atomically
    from ..checks.check_loads import CheckInputError
    from ..checks.compare import compare_calibrations, refuse_unlike
    from ..checks.plots import compare_figure
    from ..checks.report import compare_lines, compare_markdown
    from ..coverage.run_inputs import read_loads_csv, RunInputError
    from ..model.inverse import InverseDidNotConverge
    from ..model.uncertainty import UncertaintyUnavailable
    from .errors import CommandError

    try:
        a = load_calibration(args.calibration_a)
        b = load_calibration(args.calibration_b)
        refuse_unlike(a, b, args.calibration_a, args.calibration_b)
        loads = None if args.loads is None else read_loads_csv(args.loads, a.components)
        comparison = compare_calibrations(
            a, b, loads, points_from=f'the loads of {args.loads}', model=args.model
        )
    except (
        ConfigError,
        CheckInputError,
        RunInputError,
        UncertaintyUnavailable,
        InverseDidNotConverge,
        ValueError,
    ) as err:
        raise CommandError(' '.join(str(err).split())) from None
    summary = comparison.summary()
    for line in compare_lines(summary):
        print(line)
    if args.out:
        out = Path(args.out)
        try:
            out.mkdir(parents=True, exist_ok=True)
            compare_figure(comparison, out / 'compare.png')
            write_text_atomically(
                out / 'compare.md',
                compare_markdown(summary, args.calibration_a, args.calibration_b),
            )
            write_text_atomically(
                out / 'compare.json', json.dumps(summary, indent=2, allow_nan=False) + '\n'
            )
        except OSError as err:
            raise CommandError(f'{err.filename or out}: {err.strerror or err}') from None
        print(f'compare: {out / "compare.md"}')
    return EXIT_CHANGED if summary['changed'] else 0
