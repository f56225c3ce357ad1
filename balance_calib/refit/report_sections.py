"""What a balance laboratory puts in a calibration record, beside TM-663's own tables.

`calibration_record` collects it (report.json key "record", plain numbers); `record_markdown`,
`residual_markdown`, `coefficient_quality_markdown` and `lab_units_markdown` render it in
report.md:

- rated loads and rated outputs (TM-663 Tables 3, 6), so that "% FS" says what full scale is;
- the excitation, the temperature range, the campaign's time span, the source files;
- the load-point breakdown by loading type (Table 2) and by number of loaded components;
- the calibration body's loads in every orientation used (Tables 9, 13);
- per model and component: σ (eqs. (44)-(49)), 2σ, the largest residual and its point, the points
  beyond the ±0.5 % FS plot range;
- the coefficients' standard errors and each fit's condition number and rank.
"""

from __future__ import annotations

import datetime as _dt
from typing import Mapping, Sequence

import numpy as np

from ..units import implied_excitation_v, load_unit, LOAD_UNIT_SYSTEMS, loads_to_display

PLOT_RANGE_PCT_FS = 0.5  # the memo's vertical range of Figs. 4-9
TABLE2_TITLES = {
    'component': 'single-component loads',
    'longitudinal_combined': 'longitudinal three-component combined (F_X, F_Z, M_Y)',
    'six_component_combined': 'six-component combined',
    'longitudinal_plus_roll': 'longitudinal three-component + roll (M_X)',
    'lateral_plus_axial': 'lateral three-component (F_Y, M_X, M_Z) + axial',
}


def loaded_component_count(applied_loads, capacity) -> np.ndarray:
    """Number of components carrying an applied load above 0.1 % of its rating, per point (P,)."""
    applied = np.asarray(applied_loads, dtype=float)
    return np.sum(np.abs(applied) > 1e-3 * np.asarray(capacity, dtype=float), axis=1)


def combined_load_mask(points, config) -> np.ndarray:
    """True for points of the combined-load blocks (Table 2 ranges of the config when it has them,
    else points loading two or more components); zero points are False.
    """
    labels = np.asarray(points.label)
    zero = np.asarray(points.is_zero_point)
    ranges = (config.raw or {}).get('load_types') or {}
    if 'component' in ranges:
        low, high = ranges['component']
        single = (labels >= low) & (labels <= high)
        known = np.zeros(len(labels), bool)
        for low_, high_ in ranges.values():
            known |= (labels >= low_) & (labels <= high_)
        combined = known & ~single
        unknown = ~known
        combined[unknown] = (
            loaded_component_count(points.applied_loads[unknown], config.capacity) >= 2
        )
    else:
        combined = loaded_component_count(points.applied_loads, config.capacity) >= 2
    return combined & ~zero


def _residual_stats(residual_loads, capacity, labels, components) -> dict:
    pct = np.asarray(residual_loads, dtype=float) / np.asarray(capacity, dtype=float) * 100.0
    sigma = np.sqrt(np.mean(pct**2, axis=0))  # TM-663 eqs. (44)-(49)
    worst = np.argmax(np.abs(pct), axis=0)
    return {
        c: {
            'sigma_pct_fs': round(float(sigma[k]), 4),
            'two_sigma_pct_fs': round(float(2 * sigma[k]), 4),
            'max_abs_pct_fs': round(float(abs(pct[worst[k], k])), 4),
            'max_signed_pct_fs': round(float(pct[worst[k], k]), 4),
            'max_at_point': int(labels[worst[k]]),
            'beyond_plot_range': int(np.sum(np.abs(pct[:, k]) > PLOT_RANGE_PCT_FS)),
        }
        for k, c in enumerate(components)
    }


def calibration_record(config, points, reduction, fits, diagnosis, body) -> dict:
    """The record's numbers (JSON-ready). `body` is the calibration body the adopted fit used."""
    from ..tare.calibration_body import tare_loads

    components = list(config.components)
    capacity = np.asarray(config.capacity, dtype=float)
    labels = np.asarray(points.label)
    raw = config.raw or {}

    strain = raw.get('rated_output_microstrain') or {}
    if raw.get('excitation_v') is not None:
        excitation = {'volts': float(raw['excitation_v']), 'source': 'balance config'}
    else:
        volts = (
            implied_excitation_v(
                config.rated_output_mv, [strain.get(v, np.nan) for v in config.bridge_outputs]
            )
            if strain
            else None
        )
        excitation = (
            {
                'volts': round(volts, 3),
                'source': 'implied by the rated outputs in mV and in µst '
                '(Tables 3, 6) at gauge factor 2.0',
            }
            if volts
            else {'volts': None, 'source': 'not recorded in the bags or the balance config'}
        )

    temperature = np.asarray(points.temperature_c, dtype=float)
    finite = temperature[np.isfinite(temperature)]
    times = np.asarray(points.times_s, dtype=float)
    campaign: dict[str, float | str] = {
        'first_point_s': float(times.min()),
        'last_point_s': float(times.max()),
        'duration_h': round(float(times.max() - times.min()) / 3600.0, 3),
    }
    if times.min() > 1e9:  # a wall-clock stamp (after 2001), not a simulation's clock from zero
        campaign['first_point_utc'] = _iso(times.min())
        campaign['last_point_utc'] = _iso(times.max())

    zero = np.asarray(points.is_zero_point)
    breakdown = []
    for name, (low, high) in (raw.get('load_types') or {}).items():
        inside = (labels >= low) & (labels <= high)
        breakdown.append(
            {
                'load_type': name,
                'title': TABLE2_TITLES.get(name, name.replace('_', ' ')),
                'points_table2': [int(low), int(high)],
                'points': int(inside.sum()),
                'loaded': int((inside & ~zero).sum()),
                'zero_points': int((inside & zero).sum()),
            }
        )
    counts = loaded_component_count(points.applied_loads[~zero], capacity)
    by_count = {str(n): int(np.sum(counts == n)) for n in sorted(set(counts.tolist()))}

    orientation_rows = []
    for orientation in sorted(set(np.asarray(points.orientation).tolist())):
        rows = np.asarray(points.orientation) == orientation
        gravity = np.asarray(points.gravity)[rows][0]
        loads = tare_loads(body, gravity)
        orientation_rows.append(
            {
                'orientation': int(orientation),
                'gravity': [round(float(g), 4) for g in gravity],
                'points': int(rows.sum()),
                'body_loads': {c: round(float(v), 4) for c, v in zip(components, loads)},
            }
        )

    residuals = {
        order: _residual_stats(f.fit.residuals, capacity, labels, components)
        for order, f in fits.items()
    }
    if diagnosis is not None and getattr(diagnosis, 'effects', None):
        residuals['adopted'] = _residual_stats(
            diagnosis.residuals_after, capacity, np.asarray(diagnosis.point_labels), components
        )
    return {
        'rated_loads': {c: float(v) for c, v in zip(components, capacity)},
        'rated_load_units': {c: load_unit(c) for c in components},
        'rated_outputs_mv': {
            v: float(x) for v, x in zip(config.bridge_outputs, config.rated_output_mv)
        },
        'rated_outputs_microstrain': {k: float(v) for k, v in strain.items()},
        'excitation': excitation,
        'temperature_c': (
            {
                'min': round(float(finite.min()), 3),
                'max': round(float(finite.max()), 3),
                'mean': round(float(finite.mean()), 3),
                'points_with_temperature': int(finite.size),
            }
            if finite.size
            else None
        ),
        'campaign': campaign,
        'load_points': {
            'total': int(len(labels)),
            'zero_points': int(zero.sum()),
            'loaded': int((~zero).sum()),
            'table2': breakdown,
            'by_loaded_components': by_count,
        },
        'body_by_orientation': orientation_rows,
        'residuals': residuals,
        'conditioning': {
            order: {
                'condition_number': float(f'{f.fit.condition_number:.4g}'),
                'rank': int(f.fit.rank),
                'terms_per_component': len(f.fit.model.terms),
                'degrees_of_freedom': int(f.fit.degrees_of_freedom),
            }
            for order, f in fits.items()
        },
    }


def _duration(seconds: float) -> str:
    return f'{seconds / 3600:.2f} h' if seconds >= 3600 else f'{seconds / 60:.1f} min'


def _iso(seconds: float) -> str:
    return _dt.datetime.fromtimestamp(seconds, _dt.timezone.utc).isoformat(timespec='seconds')


def _md_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    return ['| ' + ' | '.join(header) + ' |', '|' + '|'.join('---' for _ in header) + '|'] + [
        '| ' + ' | '.join(str(c) for c in row) + ' |' for row in rows
    ]


def _g(value: float, digits: int = 4) -> str:
    return f'{value:.{digits}g}'


def record_markdown(report: Mapping) -> list[str]:
    """Balance and campaign, Table 2 breakdown, calibration body per orientation."""
    record = report.get('record')
    if not record:
        return []
    components = list(record['rated_loads'])
    outputs = list(record['rated_outputs_mv'])
    strain = record.get('rated_outputs_microstrain') or {}
    lines = [
        '## Balance and campaign',
        '',
        'Full scale (FS) of every "% FS" in this report is the rated load of that component '
        '(TM-663 Tables 3 and 6):',
        '',
    ]
    rows = []
    for c, v in zip(components, outputs):
        rows.append(
            [
                c,
                f'{record["rated_loads"][c]:g} {record["rated_load_units"][c]}',
                v,
                f'{record["rated_outputs_mv"][v]:g}',
                f'{strain[v]:g}' if v in strain else '—',
            ]
        )
    lines += _md_table(
        ['component', 'rated load (FS)', 'bridge', 'rated output (mV)', 'rated output (µst)'], rows
    )
    excitation = record['excitation']
    volts = f'{excitation["volts"]:g} V' if excitation.get('volts') else 'unknown'
    temperature = record.get('temperature_c')
    campaign = record['campaign']
    span = (
        f'{campaign["first_point_utc"]} to {campaign["last_point_utc"]} UTC'
        if 'first_point_utc' in campaign
        else 'simulated clock (no wall-clock date)'
    )
    if campaign.get('clock'):  # a simulated bag says so (simulation/campaign_bag.py)
        span += f' — {campaign["clock"]}'
    temperature_text = (
        f'{temperature["min"]:.2f} to {temperature["max"]:.2f} °C '
        f'(mean {temperature["mean"]:.2f} °C, {temperature["points_with_temperature"]} points)'
        if temperature
        else 'not recorded (no /balance/temperature)'
    )
    sources = ', '.join(f'`{s}`' for s in report.get('sources', [])) or 'simulation (no bag)'
    lines += [
        '',
        f'- Excitation: {volts} ({excitation["source"]}).',
        f'- Balance temperature: {temperature_text}.',
        f'- Campaign: {span}, {_duration(campaign["last_point_s"] - campaign["first_point_s"])} '
        'from first to last point.',
        f'- Fitted: {report.get("fitted_at", "")}.',
        f'- Source files: {sources}.',
        '',
    ]
    points = record['load_points']
    lines += [
        '## Load points (TM-663 Table 2)',
        '',
        f'{points["total"]} points: {points["loaded"]} loaded, {points["zero_points"]} zero '
        'points (§5(4): every block bracketed by zero points in the same orientation).',
        '',
    ]
    if points['table2']:
        lines += _md_table(
            ['loading', 'point numbers (Table 2)', 'points here', 'loaded', 'zero points'],
            [
                [
                    b['title'],
                    f'{b["points_table2"][0]}–{b["points_table2"][1]}',
                    b['points'],
                    b['loaded'],
                    b['zero_points'],
                ]
                for b in points['table2']
            ],
        )
        lines.append('')
    by_count = points['by_loaded_components']
    lines += [
        'Loaded points by number of components carrying an applied load (loading hardware '
        'by-products included): '
        + ', '.join(f'{n}-component {k}' for n, k in by_count.items())
        + '.',
        '',
    ]
    body = report['calibration_body']
    lines += [
        '## Calibration body loads per orientation (TM-663 Tables 9, 13)',
        '',
        f'Body {body["weight_N"]:.2f} N, CG x = {body["cg_x_m"]:.4f} m '
        f'({body["source"]}); loads it puts on the balance in each orientation I_g '
        '(balance axes), added to the applied loads (§7.1):',
        '',
    ]
    rows = [
        [o['orientation'], '(' + ', '.join(f'{g:+.3f}' for g in o['gravity']) + ')', o['points']]
        + [f'{o["body_loads"][c]:.3f}' for c in components]
        for o in record['body_by_orientation']
    ]
    lines += _md_table(
        ['I_g', 'gravity (balance axes)', 'points']
        + [f'{c} ({record["rated_load_units"][c]})' for c in components],
        rows,
    )
    return lines + ['']


def residual_markdown(report: Mapping) -> list[str]:
    """σ, 2σ and the largest residual per model and component (% FS)."""
    record = report.get('record')
    if not record:
        return []
    components = list(record['rated_loads'])
    lines = [
        '## Residuals per component: σ, 2σ and the largest (% FS)',
        '',
        'σ by eqs. (44)-(49); about 95 % of the points lie within 2σ if the residuals are '
        f'normal; "beyond ±{PLOT_RANGE_PCT_FS:g} %" counts the points the residual plots draw '
        'on their edge.',
        '',
    ]
    rows = []
    for model, stats in record['residuals'].items():
        for c in components:
            s = stats[c]
            rows.append(
                [
                    model,
                    c,
                    f'{s["sigma_pct_fs"]:.3f}',
                    f'{s["two_sigma_pct_fs"]:.3f}',
                    f'{s["max_signed_pct_fs"]:+.3f}',
                    s['max_at_point'],
                    s['beyond_plot_range'],
                ]
            )
    lines += _md_table(
        [
            'model',
            'component',
            'σ',
            '2σ',
            'largest residual',
            'at point',
            f'beyond ±{PLOT_RANGE_PCT_FS:g} %',
        ],
        rows,
    )
    return lines + ['']


def coefficient_quality_markdown(report: Mapping, result) -> list[str]:
    """Condition number and rank per fit; standard errors in the coefficient layout."""
    from ..accuracy.tables import format_coefficient_tables

    record = report.get('record') or {}
    lines = [
        '### Conditioning and standard errors',
        '',
        'Condition number of the column-scaled design matrix (terms scaled by their size at rated '
        "outputs); a standard error is the coefficient's 1σ uncertainty from the residual scatter "
        '(same units as the coefficient).',
        '',
    ]
    conditioning = record.get('conditioning', {})
    if conditioning:
        lines += _md_table(
            ['model', 'terms per component', 'rank', 'condition number', 'degrees of freedom'],
            [
                [
                    m,
                    c['terms_per_component'],
                    c['rank'],
                    _g(c['condition_number']),
                    c['degrees_of_freedom'],
                ]
                for m, c in conditioning.items()
            ],
        )
        lines.append('')
    if result is not None:
        for order, fit in result.fits.items():
            errors = np.nan_to_num(np.asarray(fit.fit.standard_errors, dtype=float), nan=0.0)
            model = fit.fit.model.with_coefficients(errors, name=f'{order} standard errors')
            lines += [
                f'#### {order}: standard errors',
                '',
                '```',
                format_coefficient_tables(model),
                '```',
                '',
            ]
    return lines


def lab_units_markdown(report: Mapping, system: str) -> list[str]:
    """Rated loads, body, σ, 2σ and largest residual in the lab's units (e.g. lbf and in-lbf)."""
    record = report.get('record')
    if not record or system.lower() == 'si':
        return []
    force, moment, _, _ = LOAD_UNIT_SYSTEMS[system.lower()]
    components = list(record['rated_loads'])
    capacity = np.array([record['rated_loads'][c] for c in components])
    shown = loads_to_display(capacity, components, system)
    units = [load_unit(c, system) for c in components]
    lines = [
        f'## Loads in lab units ({force}, {moment})',
        '',
        'The same numbers as above converted for display (1 lbf = 4.4482216 N, 1 in-lbf = '
        '0.11298483 N·m, 1 kgf = 9.80665 N); the calibration itself stays in N, N·m and mV.',
        '',
    ]
    lines += _md_table(
        ['component', 'rated load', 'unit'],
        [[c, f'{v:.4g}', u] for c, v, u in zip(components, shown, units)],
    )
    lines.append('')
    rows = []
    for model, stats in record['residuals'].items():
        sigma = np.array([stats[c]['sigma_pct_fs'] for c in components]) / 100.0 * capacity
        largest = np.array([stats[c]['max_signed_pct_fs'] for c in components]) / 100.0 * capacity
        sigma, largest = (
            loads_to_display(sigma, components, system),
            loads_to_display(largest, components, system),
        )
        for k, c in enumerate(components):
            rows.append(
                [
                    model,
                    c,
                    units[k],
                    f'{sigma[k]:.4g}',
                    f'{2 * sigma[k]:.4g}',
                    f'{largest[k]:+.4g}',
                ]
            )
    lines += _md_table(['model', 'component', 'unit', 'σ', '2σ', 'largest residual'], rows)
    body = report.get('calibration_body', {})
    if 'weight_N' in body:
        weight = loads_to_display([body['weight_N']], ['FZ'], system)[0]
        lines += ['', f'Calibration body weight: {weight:.4g} {force}.']
    return lines + ['']


def add_lab_units_to_report(markdown_path, report: Mapping, system: str) -> None:
    """Insert the lab-units section into a written report.md (before the effects), atomically."""
    from pathlib import Path

    path = Path(markdown_path)
    section = lab_units_markdown(report, system)
    if not section:
        return
    text = path.read_text()
    anchor = '## Effects found in the residuals'
    block = '\n'.join(section) + '\n'
    text = text.replace(anchor, block + anchor, 1) if anchor in text else text + '\n' + block
    staging = path.with_name(f'.{path.name}.tmp')
    staging.write_text(text)
    staging.replace(path)
