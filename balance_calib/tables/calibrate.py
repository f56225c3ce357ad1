"""Table -> calibration: both model forms with series tares, method choice, validation, uncertainty.

Pure (writes nothing): `calibrate_table` returns the Calibration (loadable by balance_calibrator),
the report dict (interfaces.md keys) and per-point rows; `commands/fit.py` writes them.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Mapping

import numpy as np
import scipy.stats

from ..calibration_file import Calibration, now_iso
from ..fit.iterative import IterationDidNotConverge, fit_iterative, iterative_point_uncertainty
from ..fit.least_squares import TooFewPointsError, UnexcitedTermsError
from ..fit.series_tares import SeriesTareFit, direct_point_uncertainty, fit_direct
from ..model.inverse import InverseDidNotConverge
from ..model.r091 import term_set
from ..refit.gates import gates_report
from .balfit_reader import CalibrationTable
from .errors import TableCalibrationError
from .gates import (channel_gate, condition_gate, first_failure, outlier_gate, overfit_gate,
                    sensitivity_gate)
from .term_screen import screen_for_table

METHODS = ('direct', 'iterative')
_NAME_RE = re.compile(r'^[A-Za-z_][A-Za-z0-9_]*$')


@dataclass(frozen=True)
class TableCalibration:
    table: CalibrationTable
    validation: CalibrationTable | None
    fits: Mapping[str, SeriesTareFit]
    method: str
    calibration: Calibration
    report: dict
    point_rows: list[dict]


def _sigma_pct(residuals, capacity, symbols) -> dict[str, float]:
    """Sample standard deviation of (applied - predicted) x 100 / capacity (interfaces.md)."""
    sigma = np.std(residuals, axis=0, ddof=1) / capacity * 100.0
    return {s: round(float(v), 5) for s, v in zip(symbols, sigma)}


def rename_axes(table: CalibrationTable, axes: str) -> CalibrationTable:
    """The table with its loads named as TM-663 components (comma-separated, column order) and its
    bridge outputs as the matching bridges (FX -> FXV); other channels keep their symbols."""
    from dataclasses import replace
    from ..units import BRIDGE_OUTPUTS, COMPONENTS
    names = tuple(a.strip() for a in axes.split(','))
    if len(names) != table.n_loads or len(set(names)) != len(names) or not set(names) <= set(COMPONENTS):
        raise TableCalibrationError(f'--axes {axes!r}: give {table.n_loads} distinct names from '
                                    f'{", ".join(COMPONENTS)}, one per load of {table.source} '
                                    f'({", ".join(table.load_symbols)})')
    if len(table.bridge_columns) != len(names):
        raise TableCalibrationError(f'--axes: {table.source} has {len(table.bridge_columns)} bridge outputs '
                                    f'for {len(names)} loads')
    outputs = list(table.output_symbols)
    for column, name in zip(table.bridge_columns, names):
        outputs[column] = BRIDGE_OUTPUTS[COMPONENTS.index(name)]
    return replace(table, load_symbols=names, output_symbols=tuple(outputs))


def _check_names(table: CalibrationTable) -> None:
    for symbol in table.load_symbols + table.bridge_symbols:
        if not _NAME_RE.match(symbol):
            raise TableCalibrationError(f'{table.source}: symbol {symbol!r} cannot name a model variable '
                                        f'(letters, digits and _ only, not starting with a digit)')


def _outputs(table: CalibrationTable, excitation_v: float | None) -> np.ndarray:
    outputs = table.bridge_outputs
    if excitation_v is not None and table.output_internal_unit == 'mV/V':
        outputs = outputs * excitation_v
    return outputs


def _normality(residuals, symbols) -> dict[str, float]:
    """p-value of D'Agostino-Pearson's normality test per load (small: structured residual)."""
    result = {}
    for k, symbol in enumerate(symbols):
        column = residuals[:, k]
        result[symbol] = float(f'{scipy.stats.normaltest(column).pvalue:.3g}') if len(column) >= 20 else 1.0
    return result


def _choose(fits: Mapping[str, SeriesTareFit], capacity, symbols) -> tuple[str, str]:
    """Adopt the form with the lower mean cross-validated σ (% capacity); say why, with the residual structure."""
    cv = {m: np.sqrt(np.mean(f.press_load_residuals ** 2, axis=0)) / capacity * 100 for m, f in fits.items()}
    score = {m: float(np.mean(v)) for m, v in cv.items()}
    structure, odd_count = [], {}
    for method, fit in fits.items():
        normal = _normality(fit.load_residuals, symbols)
        odd = [f'{s} (p={p:.2g})' for s, p in normal.items() if p < 1e-3]
        odd_count[method] = len(odd)
        if odd:
            structure.append(f'{method} residuals non-normal on {", ".join(odd)}')
    chosen = min(score, key=score.get)
    other = [m for m in fits if m != chosen][0]
    tie_break = ''
    # within 2 % on σ the residual structure decides: a form that leaves non-normal (structured)
    # residuals misses something the other captures
    if score[other] <= 1.02 * score[chosen] and odd_count[chosen] > odd_count[other]:
        chosen, other = other, chosen
        tie_break = (f'; σ within 2 %, so the form with fewer non-normal residual components '
                     f'({odd_count[chosen]} against {odd_count[other]}) is adopted')
    better = [s for s, a, b in zip(symbols, cv[chosen], cv[other]) if a < b]
    why = (f'{chosen}: cross-validated σ {score[chosen]:.4f} % capacity (mean over loads) against '
           f'{score[other]:.4f} % for {other}, lower on {len(better)} of {len(symbols)} loads '
           f'({", ".join(better) or "none"}){tie_break}')
    if structure:
        why += '; ' + '; '.join(structure)
    return chosen, why


def _select(method: str, terms, fit: SeriesTareFit, table: CalibrationTable, outputs, loads_si):
    """Backward elimination by PRESS on the linear problem of a fitted form (its tares held)."""
    from ..fit.series_tares import series_indicator
    from ..fit.term_selection import backward_elimination
    from ..model.r091 import TermEvaluator
    _, index, onehot = series_indicator(table.series)
    names = [t.name for t in terms]
    linear = [t.name for t in terms if t.degree == 1 and not t.factors[0].absolute]
    if method == 'direct':
        design = np.hstack([TermEvaluator(terms, table.bridge_symbols).design(outputs), -onehot])
        targets, target_names = loads_si, table.load_symbols
    else:
        totals = loads_si + fit.tares[index]
        design = np.hstack([TermEvaluator(terms, table.load_symbols).design(totals), onehot])
        targets, target_names = outputs, table.bridge_symbols
    selection = backward_elimination(design, targets, len(terms), names, target_names, keep=linear)
    return tuple(t for t in terms if t.name in selection.kept), selection


def calibrate_table(table: CalibrationTable, *, method: str = 'auto', terms: str = 'auto',
                    validation: CalibrationTable | None = None, excitation_v: float | None = None,
                    statistics: bool = True, select: bool = False,
                    force: bool = False) -> TableCalibration:
    if method not in ('auto',) + METHODS:
        raise TableCalibrationError(f'--method {method!r}: expected auto, direct or iterative')
    _check_names(table)
    loads_si = table.applied_loads_si
    outputs = _outputs(table, excitation_v)
    capacity = table.load_capacity_si
    loads, inputs = table.load_symbols, table.bridge_symbols
    if validation is not None:
        if validation.load_symbols != loads or validation.bridge_symbols != inputs or \
                validation.load_units != table.load_units or validation.output_units != table.output_units:
            raise TableCalibrationError(f'{validation.source}: symbols or units differ from the calibration '
                                        f'table {table.source}')
    channels = channel_gate(table, outputs)
    if not channels.passed and not force:
        raise TableCalibrationError(_refusal(table, channels))
    methods = METHODS if (method == 'auto' or validation is not None) else (method,)
    if len(inputs) != len(loads) and 'iterative' in methods:
        if method == 'iterative':
            raise TableCalibrationError(f'{table.source}: the iterative method needs as many bridge outputs as '
                                        f'loads ({len(inputs)} outputs, {len(loads)} loads)')
        methods = ('direct',)
    try:
        term_sets = {
            'direct': term_set('tm663-cubic' if terms == 'auto' else terms, inputs, loads),
            'iterative': term_set('r091-96' if terms == 'auto' else terms, loads, inputs)}
    except ValueError as err:
        raise TableCalibrationError(str(err)) from None
    screens = {m: screen_for_table(m, term_sets[m], table, outputs) for m in methods}
    term_sets = {m: screens[m].kept for m in methods}
    fits: dict[str, SeriesTareFit] = {}
    selections = {}
    try:
        for m in methods:
            if m == 'direct':
                fits[m] = fit_direct(term_sets[m], outputs, loads_si, table.series, components=loads,
                                     inputs=inputs, name='direct', statistics=statistics)
            else:
                fits[m] = fit_iterative(term_sets[m], loads_si, outputs, table.series, components=loads,
                                        inputs=inputs, capacity=capacity, name='iterative', statistics=statistics)
        if select:
            for m in list(fits):
                term_sets[m], selections[m] = _select(m, term_sets[m], fits[m], table, outputs, loads_si)
                if selections[m].removed:
                    fits[m] = (fit_direct(term_sets[m], outputs, loads_si, table.series, components=loads,
                                          inputs=inputs, name='direct', statistics=statistics) if m == 'direct' else
                               fit_iterative(term_sets[m], loads_si, outputs, table.series, components=loads,
                                             inputs=inputs, capacity=capacity, name='iterative',
                                             statistics=statistics))
    except (UnexcitedTermsError, TooFewPointsError, IterationDidNotConverge, InverseDidNotConverge) as err:
        raise TableCalibrationError(f'{table.source}: {err}') from None

    if method == 'auto' and len(fits) == 2:
        chosen, why = _choose(fits, capacity, loads)
    else:
        chosen = method if method != 'auto' else next(iter(fits))
        why = f'{chosen}: asked for with --method {method}' if method != 'auto' else \
            f'{chosen}: the only form the table allows (outputs and loads differ in number)'
    fit = fits[chosen]

    # validation with the calibration's tares (never re-estimated)
    validation_sigma, validation_u, val_outputs = {}, {}, None
    if validation is not None:
        val_outputs = _outputs(validation, excitation_v)
        for m, f in fits.items():
            try:
                predicted = f.predict_applied(val_outputs, validation.series)
            except KeyError as err:
                raise TableCalibrationError(f'{validation.source}: {err.args[0]}') from None
            except InverseDidNotConverge as err:
                raise TableCalibrationError(f'{validation.source}: {err}') from None
            residual = validation.applied_loads_si - predicted
            validation_sigma[m] = (_sigma_pct(residual, capacity, loads), residual)
            validation_u[m] = (direct_point_uncertainty if m == 'direct' else iterative_point_uncertainty)(
                f, val_outputs, validation.series)

    t95 = float(scipy.stats.t.ppf(0.975, fit.dof))
    report = _report(table, validation, fits, chosen, why, term_sets, validation_sigma, validation_u, t95, terms)
    report['terms_dropped'] = {m: [{'term': t, 'why': w} for t, w in screens[m].dropped] for m in fits}
    if select:
        report['term_selection'] = {m: {'kept': len(sel.kept), 'removed': list(sel.removed), 'why': list(sel.reasons)}
                                    for m, sel in selections.items()}
    point_rows = _point_rows(table, fit, t95, 'calibration', fit.load_residuals, fit.point_uncertainty)
    if validation is not None:
        point_rows += _point_rows(validation, fit, t95, 'validation', validation_sigma[chosen][1],
                                  validation_u[chosen])
    rated = table.output_capacity[list(table.bridge_columns)] * table.output_factor[list(table.bridge_columns)]
    if excitation_v is not None and table.output_internal_unit == 'mV/V':
        rated = rated * excitation_v
    gates = [channels, sensitivity_gate(table, outputs, rated),
             outlier_gate(table.point_id, loads, fit.load_residuals, fit.press_load_residuals, capacity,
                          f'{chosen} model'),
             overfit_gate(report['sigma_pct_capacity']['calibration'], report['sigma_pct_fs_crossval']['after'],
                          table.points, len(term_sets[chosen]) + len(fit.series_labels), f'{chosen} model'),
             condition_gate(fit.condition_number, f'{chosen} model')]
    acceptance = gates_report(gates, forced=force)
    report['gates'], report['forced'] = acceptance['gates'], acceptance['forced']
    refused = first_failure(gates)
    if refused is not None and not force:
        raise TableCalibrationError(_refusal(table, refused))
    rated = np.where(np.isfinite(rated) & (rated > 0), rated, np.max(np.abs(outputs), axis=0))
    models = {m: f.model for m, f in fits.items()}
    output_unit = 'mV' if excitation_v is not None or table.output_internal_unit == 'mV' else table.output_internal_unit
    calibration = Calibration(
        table.balance_name or 'balance', models, chosen, chosen, capacity, rated, tuple(loads), tuple(inputs),
        report['sigma_pct_fs']['after'], now_iso(), None,
        {'format': 'balfit', 'source': table.source, 'method_choice': why, 'output_unit': output_unit,
         'load_units_si': list(table.load_si_units),
         'series_tares_si': {str(s): [float(x) for x in row] for s, row in zip(fit.series_labels, fit.tares)},
         'series_tares_sigma_si': {str(s): [float(x) for x in row] for s, row in zip(fit.series_labels, fit.tare_sigma)},
         'points': table.points})
    return TableCalibration(table, validation, fits, chosen, calibration, report, point_rows)


def _refusal(table: CalibrationTable, gate) -> str:
    return (f'{table.source}: refused by acceptance gate {gate.name}: {gate.reason}; nothing written '
            f'(--force writes it anyway)')


def _point_rows(table, fit, t95, kind, residuals, uncertainty) -> list[dict]:
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


def _in_file_units(values_si, table) -> np.ndarray:
    return np.asarray(values_si) / table.load_factor


def _report(table, validation, fits, chosen, why, term_sets, validation_sigma, validation_u, t95, terms_spec) -> dict:
    fit = fits[chosen]
    loads = table.load_symbols
    capacity = table.load_capacity_si
    sigma_cal = _sigma_pct(fit.load_residuals, capacity, loads)
    sigma_cv = {s: round(float(v), 5) for s, v in
                zip(loads, np.sqrt(np.mean(fit.press_load_residuals ** 2, axis=0)) / capacity * 100)}
    pi = np.sqrt(np.mean(fit.point_uncertainty ** 2, axis=0)) * t95 / capacity * 100
    tares = _in_file_units(fit.tares, table)
    tare_sigma = _in_file_units(fit.tare_sigma, table)
    compared = {}
    for m, f in fits.items():
        entry = {'calibration': _sigma_pct(f.load_residuals, capacity, loads),
                 'crossval': {s: round(float(v), 5) for s, v in
                              zip(loads, np.sqrt(np.mean(f.press_load_residuals ** 2, axis=0)) / capacity * 100)},
                 'terms': len(term_sets[m]), 'iterations': f.iterations,
                 'condition_number': float(f'{f.condition_number:.4g}'),
                 'residual_normality_p': _normality(f.load_residuals, loads)}
        if m in validation_sigma:
            entry['validation'] = validation_sigma[m][0]
            u = validation_u[m]
            residual = validation_sigma[m][1]
            entry['validation_coverage_1.96u'] = round(float(np.mean(np.abs(residual) <= 1.96 * u)), 4)
        compared[m] = entry
    stats = {m: f.statistics.to_report() for m, f in fits.items() if f.statistics is not None}
    weak = {m: f.statistics.weak_terms() for m, f in fits.items() if f.statistics is not None}
    report = {
        'balance': table.balance_name or 'balance',
        'format': 'balfit',
        'method': chosen,
        'method_choice': why,
        'terms': [t.name for t in term_sets[chosen]],
        'term_set': terms_spec if terms_spec != 'auto' else ('tm663-cubic' if chosen == 'direct' else 'r091-96'),
        'load_symbols': list(loads),
        'load_units': list(table.load_units),
        'output_symbols': list(table.bridge_symbols),
        'output_units': [table.output_units[i] for i in table.bridge_columns],
        'capacities': {s: float(c) for s, c in zip(loads, table.load_capacity)},
        'points': {'calibration': table.points, 'validation': validation.points if validation is not None else 0},
        'disabled_points': {'calibration': table.disabled_points,
                            'validation': validation.disabled_points if validation is not None else 0},
        'base_model': chosen,
        'sigma_pct_capacity': {'calibration': sigma_cal,
                               **({'validation': validation_sigma[chosen][0]} if validation_sigma else {})},
        'sigma_pct_fs': {'before': sigma_cal, 'after': sigma_cal},
        'sigma_pct_fs_crossval': {'before': sigma_cv, 'after': sigma_cv},
        'series_tares': {str(s): {sym: float(f'{v:.6g}') for sym, v in zip(loads, row)}
                         for s, row in zip(fit.series_labels, tares)},
        'series_tares_sigma': {str(s): {sym: float(f'{v:.4g}') for sym, v in zip(loads, row)}
                               for s, row in zip(fit.series_labels, tare_sigma)},
        'prediction_interval_95_pct_capacity': {s: round(float(v), 5) for s, v in zip(loads, pi)},
        'uncertainty': {'k': 1, 't_95': round(t95, 4),
                        'how': 'u² = σ²(1 + z (ZᵀZ)⁻¹ zᵀ), z the point\'s design row with its series; '
                               'iterative: in output space, mapped by the inverse Jacobian; per point in '
                               'point_uncertainty.csv'},
        'methods_compared': compared,
        'term_statistics': stats,
        'weak_terms': weak,
        'effects': [],
        'adopted': False,
        'unexplained': [],
        'warnings': [],
        'natural_zeros': {label: [float(x) for x in zero] for label, zero in table.natural_zeros.items()},
        'fitted_at': now_iso(),
        'sources': [table.source] + ([validation.source] if validation is not None else []),
    }
    if not table.natural_zeros:
        report['warnings'].append(f'{table.source} has no natural zeros: outputs used as written')
    extra = [table.output_symbols[i] for i in range(len(table.output_symbols)) if i not in table.bridge_columns]
    if extra:
        report['warnings'].append(f'channels {", ".join(extra)} are not bridge outputs: not used by the fit')
    from ..units import BRIDGE_OUTPUTS, COMPONENTS
    if not (set(loads) <= set(COMPONENTS) and set(table.bridge_symbols) <= set(BRIDGE_OUTPUTS)):
        report['warnings'].append(f'loads {", ".join(loads)} / outputs {", ".join(table.bridge_symbols)} are not '
                                  f'TM-663 names: balance_calibrator cannot run this calibration; refit with '
                                  f'--axes FX,FY,FZ,MX,MY,MZ (in the table\'s column order) if that is what they are')
    from .diagnose_table import residual_structure
    structure = residual_structure(table, fit)
    report['unexplained'] = structure['unexplained']
    report['diagnosis'] = {'examined': structure['examined'], 'skipped': structure['skipped']}
    report['warnings'].append('the refit\'s diagnosis of effects needs sample times, temperatures and gravity '
                              'directions a table lacks: residuals examined against point order, load '
                              'direction and extra channels only (report.json diagnosis.skipped)')
    return report
