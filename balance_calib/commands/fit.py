"""balance-calib fit TABLE.csv ... --out DIR (interfaces.md, "Calibration data tables from other
tools"), and balance-calib export-table BAG ... --balance CONFIG --out FILE.csv (a bag campaign as
a table).
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
import shutil

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
    from ..output_dir import check_out_dir, OutputError
    from ..tables.balfit_reader import read_tables, TableError
    from ..tables.calibrate import calibrate_table, TableCalibrationError
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
        result = calibrate_table(
            table,
            method=args.method,
            terms=args.terms,
            validation=validation,
            excitation_v=args.excitation_v,
            select=args.select,
            force=args.force,
        )
    except (TableError, TableCalibrationError, OutputError) as err:
        raise CommandError(str(err)) from None
    from ..record import signed_record

    if args.serial:
        result.calibration.extra['serial'] = args.serial  # type: ignore[index]
    result.report['record'] = signed_record(
        balance=result.report['balance'],
        serial=args.serial,
        operator=args.operator,
        inputs=[*args.tables, *args.validate],
        calibration=result.calibration,
    )
    try:
        out = write_fit_outputs(
            result, Path(args.out), plots=not args.no_plots, overwrite=args.overwrite
        )
    except OutputError as err:
        raise CommandError(str(err)) from None
    except OSError as err:  # the disk filled, a file vanished: one line naming it
        raise CommandError(f'{err.filename or args.out}: {err.strerror or err}') from None
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


def write_fit_outputs(
    result, out_dir: Path, *, plots: bool = True, overwrite: bool = True
) -> Path:
    """Everything into a staging directory first, then moved in (nothing half-written;
    output_dir.py: an earlier calibration record is replaced only with overwrite, and then no
    file of it stays).
    """
    from ..calibration_file import save_calibration
    from ..output_dir import check_out_dir, install_outputs, make_staging

    out_dir = Path(out_dir)
    staging = make_staging(out_dir, check_out_dir(out_dir, overwrite=overwrite), 'fit')
    try:
        save_calibration(staging / 'calibration.yaml', result.calibration)
        (staging / 'point_uncertainty.csv').write_text(_rows_csv(result.point_rows))
        figures = _plots(result, staging) if plots else []
        result.report['plots'] = [f.name for f in figures]
        (staging / 'report.json').write_text(
            json.dumps(result.report, indent=2, allow_nan=False) + '\n'
        )
        (staging / 'report.md').write_text(report_markdown(result.report))
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return install_outputs(staging, out_dir, overwrite=overwrite)


def _rows_csv(rows) -> str:
    buffer = io.StringIO()
    if rows:
        writer = csv.DictWriter(buffer, fieldnames=list(rows[0]), lineterminator='\n')
        writer.writeheader()
        for row in rows:
            writer.writerow(
                {k: (f'{v:.6g}' if isinstance(v, float) else v) for k, v in row.items()}
            )
    return buffer.getvalue()


def _plots(result, directory: Path):
    from ..tables.plots import residual_figure

    table = result.table
    capacity = table.load_capacity_si
    return [
        residual_figure(
            fit.load_residuals / capacity * 100.0,
            table.load_symbols,
            f'{table.balance_name or "balance"}: {method} method residuals',
            directory / f'residuals_{method}.png',
        )
        for method, fit in result.fits.items()
    ]


def sigma_headline(report) -> str:
    """One line: σ % capacity in-sample, cross-validated and (when validated) validation, per
    load.
    """
    sigma = report['sigma_pct_capacity']
    parts = [
        (name, sigma[key])
        for name, key in (
            ('in-sample', 'calibration'),
            ('cross-validated', 'crossval'),
            ('validation', 'validation'),
        )
        if key in sigma
    ]
    return 'σ % capacity ' + '; '.join(
        f'{name} ' + ' '.join(f'{k} {v:.4f}' for k, v in values.items()) for name, values in parts
    )


def _gates_and_selection(report) -> list[str]:
    """report.md: the acceptance gates, the models compared and the terms dropped."""
    lines = [
        '## Acceptance gates'
        + (' (written with --force although one failed)' if report.get('forced') else ''),
        '',
    ]
    lines += [
        f'- {g["name"]}: {"passed" if g["passed"] else "FAILED"}: {g["reason"]}'
        for g in report.get('gates', [])
    ]
    lines += ['', '## Models compared (cross-validated σ, mean over loads, % capacity)', '']
    for c in report.get('model_selection', {}).get('candidates', []):
        figure = (
            f'{c["crossval_mean"]:.4f}' if 'crossval_mean' in c else f'not fitted: {c["error"]}'
        )
        lines.append(f'- {c["method"]}, {c["term_set"]} ({c["terms"]} terms): {figure}')
    for method, dropped in report.get('terms_dropped', {}).items():
        if dropped:
            shown = '; '.join(f'{d["term"]} ({d["why"]})' for d in dropped[:12])
            more = f' … and {len(dropped) - 12} more in report.json' if len(dropped) > 12 else ''
            lines.append(f'- {method}, terms dropped: {shown}{more}')
    return lines + [''] + _signing(report)


def _signing(report) -> list[str]:
    """report.md: identification, largest residuals, effects offered, the adopted coefficients."""
    from ..accuracy.tables import weak_coefficients, WEAK_MARK, WEAK_NOTE

    ident = report.get('identification', {})
    lines = [
        '## Identification',
        '',
        f'Balance {ident.get("balance_name") or "-"}: {ident.get("description") or "-"}; '
        f'fitted by {ident.get("package", "balance_calib")} {ident.get("package_version", "")}. '
        f'Rated loads: '
        + ', '.join(
            f'{s} {r["capacity"]:g} {r["unit"]}' for s, r in report.get('rated_loads', {}).items()
        )
        + '.',
        '',
        '## Largest residual of each load (% capacity, point id)',
        '',
    ]
    for name, per_load in report.get('largest_residual', {}).items():
        lines.append(
            f'- {name}: '
            + ', '.join(
                f'{s} {v["residual_pct_capacity"]:+.4f} ({v["point_id"]})'
                for s, v in per_load.items()
            )
        )
    for effect in report.get('effects', []):
        how = 'adopted' if effect.get('adopted') else 'offered, not adopted'
        channel = f' (channel {effect["channel"]})' if effect.get('channel') else ''
        lines.append(
            f'- {how}: {effect["name"]}{channel} on {", ".join(effect["components"])}: '
            f'{effect["evidence"]}'
        )
    if report.get('requires'):
        lines.append(
            f'- the adopted model reads channel(s) {", ".join(report["requires"])} '
            '(calibration.yaml `requires`)'
        )
    coefficients = report.get('coefficients')
    if coefficients:
        targets = coefficients['targets']
        lines += [
            '',
            f'## Coefficients of the adopted {coefficients["form"]} model ± standard error '
            f'({coefficients["units"]})',
            '',
            f'{WEAK_NOTE}.',
            '',
            '| term | ' + ' | '.join(targets) + ' |',
            '|---|' + '---|' * len(targets),
        ]
        weak = {
            t: weak_coefficients(coefficients['values'][t], coefficients['standard_errors'][t])
            for t in targets
        }
        for j, term in enumerate(coefficients['terms']):
            lines.append(
                f'| {term} | '
                + ' | '.join(
                    f'{coefficients["values"][t][j]:.6g} ± '
                    f'{coefficients["standard_errors"][t][j]:.2g}'
                    f'{WEAK_MARK if weak[t][j] else ""}'
                    for t in targets
                )
                + ' |'
            )
    return lines + ['']


def report_markdown(report) -> str:
    from ..accuracy.sigma import format_sigma_table
    from ..record import identification_markdown, signature_markdown

    loads = report['load_symbols']
    lines = (
        [
            f'# Calibration from tables: {report["balance"]}',
            '',
            *identification_markdown(report.get('record') or {'balance': report['balance']}),
            f'{report["points"]["calibration"]} calibration points, '
            f'{report["points"]["validation"]} validation points '
            f'({report["disabled_points"]["calibration"]} + '
            f'{report["disabled_points"]["validation"]} switched off). Loads '
            f'{", ".join(f"{s} [{u}]" for s, u in zip(loads, report["load_units"]))}.',
            '',
            f'**Method adopted: {report["method"]}** ({len(report["terms"])} terms, set '
            f'{report["term_set"]}). Why: {report["method_choice"]}.',
            '',
            f'**{sigma_headline(report)}**',
            '',
        ]
        + _gates_and_selection(report)
        + ['## σ in % of capacity (sample standard deviation of applied − predicted)', '', '```']
    )
    rows = {}
    for method, entry in report['methods_compared'].items():
        rows[f'{method} / calibration'] = entry['calibration']
        rows[f'{method} / cross-validated'] = entry['crossval']
        if 'validation' in entry:
            rows[f'{method} / validation'] = entry['validation']
    rows['95 % prediction interval (RMS)'] = report['prediction_interval_95_pct_capacity']
    lines += [format_sigma_table(rows, loads, digits=4).replace('(%)', '   '), '```', '']
    coverage = {
        m: e.get('validation_coverage_1.96u')
        for m, e in report['methods_compared'].items()
        if 'validation_coverage_1.96u' in e
    }
    if coverage:
        lines += [
            'Validation points inside ±1.96 u: '
            + ', '.join(f'{m} {100 * c:.1f} %' for m, c in coverage.items()),
            '',
        ]
    lines += [
        '## Series tares (file units; total = applied + tare) ± standard error',
        '',
        '| series | ' + ' | '.join(loads) + ' |',
        '|---|' + '---|' * len(loads),
    ]
    for series, tares in report['series_tares'].items():
        sig = report['series_tares_sigma'][series]
        lines.append(
            f'| {series} | ' + ' | '.join(f'{tares[s]:.4g} ± {sig[s]:.2g}' for s in loads) + ' |'
        )
    lines += ['', '## Terms (VIF, significance, PRESS)', '']
    for method, rows_ in report.get('term_statistics', {}).items():
        weak = report['weak_terms'].get(method, [])
        high_vif = [r['term'] for r in rows_ if r['vif'] > 10]
        lines += [
            f'- {method}: {len(rows_)} terms; {len(high_vif)} with VIF > 10; '
            f'{len(weak)} insignificant everywhere (p ≥ 0.01) whose removal lowers PRESS: '
            f'{", ".join(weak[:20]) or "none"}{" ..." if len(weak) > 20 else ""}'
        ]
    for method, selection in report.get('term_selection', {}).items():
        removed = selection['removed']
        lines += [
            f'- {method}, --select: kept {selection["kept"]} terms, removed {len(removed)}: '
            f'{", ".join(removed[:30]) or "none"}{" ..." if len(removed) > 30 else ""}'
        ]
    lines += [
        '',
        'Per term and load in report.json (`term_statistics`): VIF, p-value of the coefficient, '
        'PRESS without the term / PRESS with it.',
        '',
        '## Uncertainty of each point',
        '',
        'k = 1 standard uncertainty from the coefficient covariance, the residual scatter and '
        'the series '
        f'tare; 95 % prediction interval = t × u, t = {report["uncertainty"]["t_95"]} (Student, '
        '97.5 %, the '
        f"fit's degrees of freedom). Every point in "
        f'`point_uncertainty.csv`.',
        '',
    ]
    lines += ['## What the residuals still follow', '']
    if report.get('unexplained'):
        lines += [
            f'- {", ".join(u["components"])}: {u["evidence"]}' for u in report['unexplained']
        ]
    else:
        lines.append(
            f'Nothing: residuals examined against {", ".join(report["diagnosis"]["examined"])}.'
        )
    lines += (
        ['']
        + [
            f'- not examined, {name}: {why}'
            for name, why in report['diagnosis']['skipped'].items()
        ]
        + ['']
    )
    if report.get('warnings'):
        lines += ['## Warnings', ''] + [f'- {w}' for w in report['warnings']] + ['']
    if report.get('plots'):
        lines += ['## Residual plots', ''] + [f'![{p}]({p})' for p in report['plots']] + ['']
    lines += [f'Fitted {report["fitted_at"]} from {", ".join(report["sources"])}.']
    lines += signature_markdown('calibration')
    return '\n'.join(lines) + '\n'


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
