"""balance-calib refit BAG [BAG ...] --balance CONFIG --out DIR (interfaces.md, Command line)."""

from __future__ import annotations

import argparse
from pathlib import Path
import sys

from .record_arguments import add_record_arguments


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'refit',
        help='refit the calibration from recorded campaign bags',
        description='Run the refit pipeline behind ~/refit on bags and write '
        'calibration.yaml, report.json, report.md and residual plots.',
    )
    parser.add_argument(
        'bags', nargs='+', help='rosbag2 directories or bare .mcap files of one campaign'
    )
    parser.add_argument(
        '--balance', required=True, help='balance config: lmc6522, b660h or a path'
    )
    parser.add_argument('--out', required=True, help='output directory')
    parser.add_argument(
        '--overwrite',
        action='store_true',
        help='replace the calibration record of an earlier run in --out (its '
        'files are removed; without this an --out holding calibration.yaml '
        'or report.json is refused)',
    )
    parser.add_argument(
        '--model',
        default='cubic',
        choices=['linear', 'quadratic', 'cubic'],
        help='base model of TM-663 §2 (default cubic)',
    )
    parser.add_argument(
        '--no-diagnosis', action='store_true', help='do not look for effects the model lacks'
    )
    parser.add_argument(
        '--declared-body',
        action='store_true',
        help='use the declared calibration body instead of estimating it from zero points',
    )
    parser.add_argument(
        '--report-units',
        default='si',
        choices=['si', 'lbf', 'kgf'],
        help='also show loads in report.md in these lab units: lbf and in-lbf, or kgf and '
        'kgf·m (default si: N and N·m only; the calibration itself is always SI)',
    )
    parser.add_argument(
        '--force',
        action='store_true',
        help='write the calibration even if an acceptance gate fails (marked in the report)',
    )
    parser.add_argument(
        '--salvage',
        action='store_true',
        help='read what is intact of damaged bags; the report says exactly what was lost',
    )
    parser.add_argument(
        '--active',
        metavar='CAL.yaml',
        default=None,
        help='the calibration in use: the new sensitivities must stay near its ones',
    )
    parser.add_argument(
        '--schedule',
        metavar='FILE',
        default=None,
        help='the load schedule the campaign ran (layout of the Appendix A/B '
        'sheets, e.g. from balance-calib design) when it is not the balance '
        "config's own; the gates judge the campaign against it",
    )
    add_record_arguments(parser)
    parser.add_argument(
        '--progress',
        action=argparse.BooleanOptionalAction,
        default=None,
        help='progress lines on stderr (default: when stderr is a terminal)',
    )
    parser.set_defaults(func=run)


def run(args) -> int:
    from ..calibrate.from_bags import RefitSettings, run_refit
    from ..refit.errors import RefitError
    from .errors import CommandError

    def progress(message: str) -> None:
        if args.progress or (args.progress is None and sys.stderr.isatty()):
            print(f'[refit] {message}', file=sys.stderr, flush=True)

    try:
        result = run_refit(
            args.bags,
            args.balance,
            Path(args.out),
            RefitSettings(
                model=args.model,
                diagnose=not args.no_diagnosis,
                estimate_body=not args.declared_body,
                progress=progress,
                force=args.force,
                salvage=args.salvage,
                active_calibration=args.active,
                schedule=args.schedule,
                overwrite=args.overwrite,
                serial=args.serial,
                operator=args.operator,
            ),
        )
    except RefitError as err:
        raise CommandError(_one_line(str(err))) from None
    except OSError as err:  # the disk filled, a file vanished: still one line naming it
        raise CommandError(
            _one_line(f'{err.filename or args.out}: {err.strerror or err}')
        ) from None
    acceptance = result.report.get('acceptance', {})
    if acceptance.get('forced'):
        failed = [g['name'] for g in acceptance['gates'] if not g['passed']]
        print(
            'balance-calib refit: written with --force although gate(s) failed: '
            f'{", ".join(failed)}',
            file=sys.stderr,
        )
    if args.report_units != 'si':
        from ..refit.report_sections import add_lab_units_to_report

        add_lab_units_to_report(result.out_dir / 'report.md', result.report, args.report_units)
    print(result.summary)
    for warning in result.report.get('warnings', []):
        print(f'warning: {warning}')
    print(f'report: {result.out_dir / "report.md"}')
    return 0


def _one_line(text: str) -> str:
    return ' '.join(text.split())
