"""report.json and the per-point rows of a table calibration (interfaces.md, "Calibration data
tables"): σ in % of capacity, the forms compared, tares in the file's units, warnings.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
import scipy.stats

from ..accuracy.sigma import sample_std_pct_fs, sigma_pct_fs
from ..calibration_file import now_iso


def sigma_pct(residuals, capacity, symbols) -> dict[str, float]:
    """Sample standard deviation of (applied - predicted) x 100 / capacity (interfaces.md)."""
    return {s: round(float(v), 5) for s, v in zip(symbols, sample_std_pct_fs(residuals, capacity))}


def _rms_pct(residuals, capacity, symbols) -> dict[str, float]:
    """TM-663 eq. (44)'s σ (root mean square) of residuals such as PRESS's, % of capacity."""
    return {
        s: round(float(v), 5)
        for s, v in zip(symbols, np.atleast_1d(sigma_pct_fs(residuals, capacity)))
    }


def normality(residuals, symbols) -> dict[str, float]:
    """p-value of D'Agostino-Pearson's normality test per load (small: structured residual)."""
    result = {}
    for k, symbol in enumerate(symbols):
        column = residuals[:, k]
        result[symbol] = (
            float(f'{scipy.stats.normaltest(column).pvalue:.3g}') if len(column) >= 20 else 1.0
        )
    return result


def point_rows(table, fit, t95, kind, residuals, uncertainty) -> list[dict]:
    capacity = table.load_capacity_si
    rows = []
    for i in range(table.points):
        row = {'set': kind, 'point_id': table.point_id[i], 'series': int(table.series[i])}
        for k, symbol in enumerate(table.load_symbols):
            row[f'{symbol}_residual_pct'] = residuals[i, k] / capacity[k] * 100
            row[f'{symbol}_u_pct'] = uncertainty[i, k] / capacity[k] * 100
            row[f'{symbol}_pi95_pct'] = t95 * uncertainty[i, k] / capacity[k] * 100
        rows.append(row)
    return rows


def in_file_units(values_si, table) -> np.ndarray:
    return np.asarray(values_si) / table.load_factor


@dataclass(frozen=True)
class FormChoice:
    """The form adopted and why, with each form's terms (term_sets) and their set's name."""

    chosen: str
    why: str
    term_sets: Mapping
    term_set_names: Mapping[str, str]


def build_report(
    table,
    validation,
    fits,
    choice: FormChoice,
    validation_sigma,
    validation_u,
    t95,
) -> dict:
    """report.json of a table calibration (interfaces.md keys); fits, validation_sigma
    ((σ, residuals) by form) and validation_u (uncertainty by form) by form.
    """
    chosen, why = choice.chosen, choice.why
    term_sets, term_set_names = choice.term_sets, choice.term_set_names
    fit = fits[chosen]
    loads = table.load_symbols
    capacity = table.load_capacity_si
    sigma_cal = sigma_pct(fit.load_residuals, capacity, loads)
    sigma_cv = _rms_pct(fit.press_load_residuals, capacity, loads)
    pi = np.sqrt(np.mean(fit.point_uncertainty**2, axis=0)) * t95 / capacity * 100
    tares = in_file_units(fit.tares, table)
    tare_sigma = in_file_units(fit.tare_sigma, table)
    compared = {}
    for m, f in fits.items():
        entry = {
            'calibration': sigma_pct(f.load_residuals, capacity, loads),
            'crossval': _rms_pct(f.press_load_residuals, capacity, loads),
            'terms': len(term_sets[m]),
            'iterations': f.iterations,
            'condition_number': float(f'{f.condition_number:.4g}'),
            'residual_normality_p': normality(f.load_residuals, loads),
        }
        if m in validation_sigma:
            entry['validation'] = validation_sigma[m][0]
            u = validation_u[m]
            residual = validation_sigma[m][1]
            entry['validation_coverage_1.96u'] = round(
                float(np.mean(np.abs(residual) <= 1.96 * u)), 4
            )
        compared[m] = entry
    stats = {m: f.statistics.to_report() for m, f in fits.items() if f.statistics is not None}
    weak = {m: f.statistics.weak_terms() for m, f in fits.items() if f.statistics is not None}
    report: dict[str, Any] = {
        'balance': table.balance_name or 'balance',
        'format': 'balfit',
        'method': chosen,
        'method_choice': why,
        'terms': [t.name for t in term_sets[chosen]],
        'term_set': term_set_names[chosen],
        'load_symbols': list(loads),
        'load_units': list(table.load_units),
        'output_symbols': list(table.bridge_symbols),
        'output_units': [table.output_units[i] for i in table.bridge_columns],
        'capacities': {s: float(c) for s, c in zip(loads, table.load_capacity)},
        'points': {
            'calibration': table.points,
            'validation': validation.points if validation is not None else 0,
        },
        'disabled_points': {
            'calibration': table.disabled_points,
            'validation': validation.disabled_points if validation is not None else 0,
        },
        'base_model': chosen,
        'sigma_pct_capacity': {
            'calibration': sigma_cal,
            'crossval': sigma_cv,
            **({'validation': validation_sigma[chosen][0]} if validation_sigma else {}),
        },
        'sigma_pct_fs': {'before': sigma_cal, 'after': sigma_cal},
        'sigma_pct_fs_crossval': {'before': sigma_cv, 'after': sigma_cv},
        'series_tares': {
            str(s): {sym: float(f'{v:.6g}') for sym, v in zip(loads, row)}
            for s, row in zip(fit.series_labels, tares)
        },
        'series_tares_sigma': {
            str(s): {sym: float(f'{v:.4g}') for sym, v in zip(loads, row)}
            for s, row in zip(fit.series_labels, tare_sigma)
        },
        'prediction_interval_95_pct_capacity': {s: round(float(v), 5) for s, v in zip(loads, pi)},
        'uncertainty': {
            'k': 1,
            't_95': round(t95, 4),
            'how': "u² = σ²(1 + z (ZᵀZ)⁻¹ zᵀ), z the point's design row with its series; "
            'iterative: in output space, mapped by the inverse Jacobian; per '
            'point in point_uncertainty.csv',
        },
        'methods_compared': compared,
        'term_statistics': stats,
        'weak_terms': weak,
        'effects': [],
        'adopted': False,
        'unexplained': [],
        'warnings': [],
        'natural_zeros': {
            label: [float(x) for x in zero] for label, zero in table.natural_zeros.items()
        },
        'fitted_at': now_iso(),
        'sources': [table.source] + ([validation.source] if validation is not None else []),
    }
    if not table.natural_zeros:
        report['warnings'].append(f'{table.source} has no natural zeros: outputs used as written')
    extra = [
        table.output_symbols[i]
        for i in range(len(table.output_symbols))
        if i not in table.bridge_columns
    ]
    if extra:
        report['warnings'].append(
            f'channels {", ".join(extra)} are not bridge outputs: examined as extra channels, '
            'in the model only where an effect of theirs is adopted (effects, requires)'
        )
    from ..units import BRIDGE_OUTPUTS, COMPONENTS

    if not (set(loads) <= set(COMPONENTS) and set(table.bridge_symbols) <= set(BRIDGE_OUTPUTS)):
        report['warnings'].append(
            f'loads {", ".join(loads)} / outputs {", ".join(table.bridge_symbols)} are not '
            f'TM-663 names: balance_calibrator cannot run this calibration; '
            f'refit with --axes FX,FY,FZ,MX,MY,MZ (in the '
            f"table's column order) if that is what they are"
        )
    from .diagnose_table import residual_structure

    structure = residual_structure(table, fit)
    report['unexplained'] = structure['unexplained']
    report['diagnosis'] = {'examined': structure['examined'], 'skipped': structure['skipped']}
    report['warnings'].append(
        'a table has no sample times, zero points or gravity directions: creep, excitation '
        'and the calibration-body tare are not examined; effects are sought in the load '
        'direction, point order, load sign and extra channels (report.json diagnosis)'
    )
    return report


def signing_sections(table, fit, method: str, outputs: np.ndarray, residuals_sets: dict) -> dict:
    """What a laboratory signs beside the σ: identification, rated loads,
    the largest residual of each load with its point id (per set), the adopted model's coefficients
    with standard errors, and the sensitivities (output change from zero to capacity of each load).

    residuals_sets: {'calibration': (table, (N, n_loads) SI), 'validation': ...}.
    """
    from .. import __version__
    from .term_screen import linear_response

    capacity = table.load_capacity_si
    largest: dict[str, dict] = {}
    for name, (source, residuals) in residuals_sets.items():
        pct = residuals / capacity * 100.0
        largest[name] = {}
        for k, symbol in enumerate(table.load_symbols):
            i = int(np.argmax(np.abs(pct[:, k])))
            largest[name][symbol] = {
                'point_id': source.point_id[i],
                'series': int(source.series[i]),
                'residual_pct_capacity': round(float(pct[i, k]), 5),
            }
    model = fit.model
    p = len(model.terms)
    variance = np.diag(fit.full_covariance_unscaled)[:p]
    coefficients = np.atleast_2d(np.asarray(model.coefficients, float))  # (targets, p)
    standard_errors = np.sqrt(np.outer(fit.residual_sigma**2, variance))
    targets = list(table.load_symbols if method == 'direct' else table.bridge_symbols)
    _, _, response = linear_response(table, outputs)
    return {
        'identification': {
            'balance_name': table.balance_name,
            'description': table.description,
            'source': table.source,
            'package': 'balance_calib',
            'package_version': __version__,
        },
        'rated_loads': {
            s: {'capacity': float(c), 'unit': u}
            for s, c, u in zip(table.load_symbols, table.load_capacity, table.load_units)
        },
        'largest_residual': largest,
        'coefficients': {
            'form': method,
            'terms': [t.name for t in model.terms],
            'targets': targets,
            'units': "SI: N and N·m, outputs in the calibration's output unit",
            'values': {
                t: [float(f'{v:.8g}') for v in row] for t, row in zip(targets, coefficients)
            },
            'standard_errors': {
                t: [float(f'{v:.4g}') for v in row] for t, row in zip(targets, standard_errors)
            },
        },
        'sensitivities': {
            'what': 'output change from zero to capacity of each load (linear least squares with '
            "the series), in the calibration's output unit",
            'outputs': list(table.bridge_symbols),
            'per_load': {
                s: [float(f'{v:.6g}') for v in row] for s, row in zip(table.load_symbols, response)
            },
        },
    }
