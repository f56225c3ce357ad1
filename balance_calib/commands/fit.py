"""balance-calib fit TABLE.csv ... --out DIR (interfaces.md, "Calibration data tables from other
tools"), and balance-calib export-table BAG ... --balance CONFIG --out FILE.csv (a bag campaign as
a table).
"""

from __future__ import annotations

from pathlib import Path
from typing import cast

from .record_arguments import add_record_arguments


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'fit',
        help='calibrate from BALFIT-style tables (direct TM-663 or iterative AIAA R-091 method)',
        description=(
            'Fit a calibration with series tares from calibration tables and write '
            'calibration.yaml, report.json, report.md, point_uncertainty.csv and residual plots '
            'into DIR.'
        ),
    )
    parser.add_argument('tables', nargs='+', help='calibration table(s) of one campaign (CSV)')
    parser.add_argument('--out', required=True, help='output directory')
    parser.add_argument(
        '--overwrite',
        action='store_true',
        help='replace the calibration record of an earlier run in --out (its files are removed)',
    )
    parser.add_argument(
        '--validate',
        nargs='+',
        default=[],
        metavar='VAL.csv',
        help='validation table(s): series the calibration has get its tares; other '
        'series (other setups) their own, estimated with the model held fixed',
    )
    parser.add_argument(
        '--method',
        default='auto',
        choices=['auto', 'direct', 'iterative'],
        help='direct: loads as a polynomial of the outputs (TM-663); iterative: outputs as a '
        'polynomial of the loads, inverted per point (AIAA R-091); auto: the one with the lower '
        'cross-validated σ, within 2 %% the one with fewer non-normal residuals, else '
        "TM-663's direct form unless the iterative one is lower on every load (default auto)",
    )
    parser.add_argument(
        '--terms',
        default='auto',
        help='auto (compare linear, tm663-quadratic, tm663-cubic and r091-96, each restricted '
        'to the terms the schedule determines, by cross-validated σ, then prune by PRESS), '
        'tm663-cubic, r091-96 or a file of term names',
    )
    parser.add_argument(
        '--excitation-v',
        type=float,
        default=None,
        help='bridge excitation (V): turns mV/V tables into mV calibrations '
        '(refused on outputs in mV, V, counts or -)',
    )
    parser.add_argument(
        '--axes',
        default=None,
        metavar='FX,FY,FZ,MX,MY,MZ',
        help='name the loads (in column order) as these TM-663 components, and the bridge '
        'outputs FXV..MZV likewise, so balance_calibrator can run the calibration '
        '(e.g. a table whose loads are FX..MZ under other symbols)',
    )
    parser.add_argument(
        '--select',
        action='store_true',
        help='drop terms by backward elimination (insignificant everywhere and lowering PRESS)',
    )
    parser.add_argument(
        '--force',
        action='store_true',
        help='write the calibration even when an acceptance gate fails (report.json '
        'gates says which, forced: true)',
    )
    parser.add_argument('--no-plots', action='store_true', help='skip the residual figures')
    add_record_arguments(parser, serial_default='null')
    parser.set_defaults(func=run)

    export = subparsers.add_parser(
        'export-table',
        help='write a recorded campaign (bags) as a BALFIT-style table',
        description=(
            'Cut the bags into load points, apply the zero points and the calibration-body tare '
            'as refit does, and write the corrected points as one load series.'
        ),
    )
    export.add_argument(
        'bags', nargs='+', help='rosbag2 directories or bare .mcap files of one campaign'
    )
    export.add_argument(
        '--balance', required=True, help='balance config: lmc6522, b660h or a path'
    )
    export.add_argument('--out', required=True, help='CSV file to write')
    export.add_argument('--overwrite', action='store_true', help='replace --out if it exists')
    export.set_defaults(func=run_export)


def run(args) -> int:
    from ..calibrate.path import calibrate
    from ..calibration_settings import CalibrationSettings, RecordOptions, TableOptions
    from ..output_dir import check_out_dir, OutputError
    from ..tables.balfit_reader import read_tables, TableError
    from ..tables.calibrate import TableCalibration, TableCalibrationError
    from ..tables.table_markdown import sigma_headline
    from ..tables.table_points import table_calibration_points
    from .errors import CommandError

    if args.excitation_v is not None and not args.excitation_v > 0:
        raise CommandError(f'--excitation-v must be positive, not {args.excitation_v}')
    try:
        check_out_dir(args.out, overwrite=args.overwrite)
        table = read_tables(args.tables)
        validation = (
            read_tables(args.validate, natural_zeros_from=table) if args.validate else None
        )
        if args.axes:
            from ..tables.calibrate import rename_axes

            table = rename_axes(table, args.axes)
            validation = rename_axes(validation, args.axes) if validation is not None else None
        settings = CalibrationSettings(
            force=args.force,
            serial=args.serial,
            operator=args.operator,
            table=TableOptions(
                method=args.method,
                terms=args.terms,
                validation=validation,
                excitation_v=args.excitation_v,
                select=args.select,
                inputs=(*args.tables, *args.validate),
            ),
            out=RecordOptions(Path(args.out), plots=not args.no_plots, overwrite=args.overwrite),
        )
        result = cast(TableCalibration, calibrate(table_calibration_points(table), settings))
    except (TableError, TableCalibrationError, OutputError) as err:
        raise CommandError(str(err)) from None
    except OSError as err:  # the disk filled, a file vanished: one line naming it
        raise CommandError(f'{err.filename or args.out}: {err.strerror or err}') from None
    out = Path(args.out)
    report = result.report
    print(
        f'{report["balance"]}: {report["points"]["calibration"]} points, method '
        f'{report["method"]} ({report["method_choice"]})'
    )
    print(sigma_headline(report))
    if report.get('forced'):
        import sys

        failed = [g['name'] for g in report['gates'] if not g['passed']]
        print(
            'balance-calib fit: written with --force although gate(s) failed: '
            f'{", ".join(failed)}',
            file=sys.stderr,
        )
    print(f'report: {out / "report.md"}')
    return 0


def run_export(args) -> int:
    from ..output_dir import check_out_file, OutputError
    from ..tables.export import export_bags_table, ExportError
    from .errors import CommandError

    try:
        check_out_file(args.out, overwrite=args.overwrite)
        path, points = export_bags_table(args.bags, args.balance, Path(args.out))
    except (ExportError, OutputError) as err:
        raise CommandError(str(err)) from None
    except OSError as err:
        raise CommandError(f'{err.filename or args.out}: {err.strerror or err}') from None
    print(f'wrote {points} points to {path}')
    return 0
