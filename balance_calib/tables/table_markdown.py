"""report.md of a table calibration (interfaces.md, "Calibration data tables from other tools")."""

from __future__ import annotations


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
