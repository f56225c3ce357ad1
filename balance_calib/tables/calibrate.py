"""Table -> calibration: both model forms with series tares, method choice, validation,
uncertainty.

Pure (writes nothing): `calibrate_table` returns the Calibration (loadable by balance_calibrator),
the report dict (interfaces.md keys) and per-point rows; calibrate/path.calibrate runs it for a
table's points and calibrate/write_record.py writes them.
"""

from __future__ import annotations

from dataclasses import dataclass
import re
from typing import cast, Mapping

import numpy as np
import scipy.stats

from ..calibration_file import now_iso
from ..fit.series_tares import SeriesTareFit
from ..gates.fit_quality import condition_gate, overfit_gate
from ..gates.gate import first_failure, gates_report, TABLE_PRIORITY
from ..gates.outlier_gates import table_outlier_gate
from ..gates.outputs import channel_gate
from ..gates.sensitivity import table_sensitivity_gate
from ..model.calibration import Calibration
from .balfit_reader import CalibrationTable
from .closing import (
    channel_keys,
    close_the_loop,
    live_model,
    report_closing,
    temperature_reference_c,
)
from .errors import TableCalibrationError
from .model_selection import (
    AUTO_TERM_SETS,
    choose_form,
    choose_within_form,
    compared_entry,
    FIT_ERRORS,
    fit_form,
    select_terms,
    terms_dropped,
    with_statistics,
)
from .outlying_components import outlying_components
from .table_report import (
    build_report,
    FormChoice,
    in_file_units,
    point_rows,
    sigma_pct,
    signing_sections,
)
from .term_screen import linear_response
from .validation import coverage_warning, FormValidation, range_warnings, validate_form

_choose = choose_form  # the rule between the forms (tests reach it under its old name)

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


def rename_axes(table: CalibrationTable, axes: str) -> CalibrationTable:
    """The table with its loads named as TM-663 components (comma-separated, column order) and its
    bridge outputs as the matching bridges (FX -> FXV); other channels keep their symbols, and so
    do the bridges of a table with more bridges than loads.
    """
    from dataclasses import replace

    from ..units import BRIDGE_OUTPUTS, COMPONENTS

    names = tuple(a.strip() for a in axes.split(','))
    if (
        len(names) != table.n_loads
        or len(set(names)) != len(names)
        or not set(names) <= set(COMPONENTS)
    ):
        raise TableCalibrationError(
            f'--axes {axes!r}: give {table.n_loads} distinct names from '
            f'{", ".join(COMPONENTS)}, one per load of {table.source} '
            f'({", ".join(table.load_symbols)})'
        )
    if len(table.bridge_columns) < len(names):
        raise TableCalibrationError(
            f'--axes: {table.source} has {len(table.bridge_columns)} '
            f'bridge outputs for {len(names)} loads'
        )
    if len(table.bridge_columns) > len(names):
        # more bridges than loads (an 8-channel sensor): no bridge is one component's, so only
        # the loads are named; the outputs keep the table's symbols
        return replace(table, load_symbols=names)
    outputs = list(table.output_symbols)
    for column, name in zip(table.bridge_columns, names):
        outputs[column] = BRIDGE_OUTPUTS[COMPONENTS.index(name)]
    return replace(table, load_symbols=names, output_symbols=tuple(outputs))


def _check_names(table: CalibrationTable) -> None:
    for symbol in table.load_symbols + table.bridge_symbols:
        if not _NAME_RE.match(symbol):
            raise TableCalibrationError(
                f'{table.source}: symbol {symbol!r} cannot name a model '
                f'variable (letters, digits and _ only, not starting with '
                f'a digit)'
            )


def _outputs(table: CalibrationTable, excitation_v: float | None) -> np.ndarray:
    outputs = table.bridge_outputs
    if excitation_v is None:
        return outputs
    unit = table.output_internal_unit
    if unit != 'mV/V':
        written = ', '.join(sorted({table.output_units[i] for i in table.bridge_columns}))
        raise TableCalibrationError(
            f'{table.source}: --excitation-v {excitation_v:g} turns outputs that are ratios to '
            'the '
            "excitation (mV/V, microV/V) into mV; this table's bridge outputs are in "
            f"{written}, "
            f'which it cannot change: leave --excitation-v out'
        )
    return outputs * excitation_v


def calibrate_table(
    table: CalibrationTable,
    *,
    method: str = 'auto',
    terms: str = 'auto',
    validation: CalibrationTable | None = None,
    excitation_v: float | None = None,
    statistics: bool = True,
    select: bool = False,
    force: bool = False,
) -> TableCalibration:
    if method not in ('auto',) + METHODS:
        raise TableCalibrationError(f'--method {method!r}: expected auto, direct or iterative')
    _check_names(table)
    loads_si = table.applied_loads_si
    outputs = _outputs(table, excitation_v)
    capacity = table.load_capacity_si
    loads, inputs = table.load_symbols, table.bridge_symbols
    if validation is not None:
        if (
            validation.load_symbols != loads
            or validation.bridge_symbols != inputs
            or validation.load_units != table.load_units
            or validation.output_units != table.output_units
        ):
            raise TableCalibrationError(
                f'{validation.source}: symbols or units differ from the '
                f'calibration table {table.source}'
            )
    channels = channel_gate(table, outputs)
    if not channels.passed and not force:
        raise TableCalibrationError(_refusal(table, channels))
    methods = METHODS if (method == 'auto' or validation is not None) else (method,)
    if len(inputs) != len(loads) and 'iterative' in methods:
        if method == 'iterative':
            raise TableCalibrationError(
                f'{table.source}: the iterative method needs as many '
                f'bridge outputs as loads ({len(inputs)} outputs, '
                f'{len(loads)} loads)'
            )
        methods = ('direct',)
    specs = AUTO_TERM_SETS if terms == 'auto' else (terms,)
    choices = {m: choose_within_form(m, specs, table, outputs, prune=not select) for m in methods}
    term_sets = {m: c.candidate.terms for m, c in choices.items()}
    selections = {}
    try:
        # fitted ones
        chosen_fits = {m: cast(SeriesTareFit, c.candidate.fit) for m, c in choices.items()}
        fits: dict[str, SeriesTareFit] = {
            m: with_statistics(m, chosen_fits[m], term_sets[m], table, outputs)
            if statistics
            else chosen_fits[m]
            for m in choices
        }
        if select:
            for m in list(fits):
                term_sets[m], selections[m] = select_terms(
                    m, term_sets[m], fits[m], table, outputs, loads_si
                )
                if selections[m].removed:
                    fits[m] = fit_form(m, term_sets[m], table, outputs, statistics=statistics)
    except FIT_ERRORS as err:
        raise TableCalibrationError(f'{table.source}: {err}') from None

    if method == 'auto' and len(fits) == 2:
        chosen, why = choose_form(fits, capacity, loads)
    else:
        chosen = method if method != 'auto' else next(iter(fits))
        why = (
            f'{chosen}: asked for with --method {method}'
            if method != 'auto'
            else f'{chosen}: the only form the table allows (outputs and loads differ in number)'
        )
    why += f'; terms: {choices[chosen].why}'
    fit = fits[chosen]

    # validation: the calibration's tares for its series, own tares (model fixed) for the others
    validations: dict[str, FormValidation] = {}
    validation_sigma, validation_u = {}, {}
    if validation is not None:
        val_outputs = _outputs(validation, excitation_v)
        for m, f in fits.items():
            validations[m] = validate_form(m, f, validation, val_outputs)
            residual = validations[m].residuals
            validation_sigma[m] = (sigma_pct(residual, capacity, loads), residual)
            validation_u[m] = validations[m].uncertainty

    t95 = float(scipy.stats.t.ppf(0.975, fit.dof))
    report = build_report(
        table,
        validation,
        fits,
        FormChoice(chosen, why, term_sets, {m: c.candidate.term_set for m, c in choices.items()}),
        validation_sigma,
        validation_u,
        t95,
    )
    report['terms_dropped'] = {m: terms_dropped(c) for m, c in choices.items()}
    # the loop closed on the table: effects found in its points and adopted beyond chance
    closing = close_the_loop(table, outputs, fits, chosen, term_sets)
    base_fit = fit
    form, label = chosen, f'{chosen} model'  # the adopted fit's form, the gates' name for it
    if closing.adopted:
        fit = cast(SeriesTareFit, closing.fit)
        form, label = 'direct', f'{closing.model_name} model'
        report['method'] = form
        if chosen != form:
            report['method_choice'] += '; then ' + '; '.join(closing.notes)
    report_closing(report, table, closing)
    if closing.adopted and validation is not None:
        report['warnings'].append(
            "validation σ and methods_compared are the base model's: the adopted effects' "
            'terms are not evaluated on the validation table'
        )
    if validation is not None:
        own = validations[chosen]
        report['validation_series_tares'] = {
            str(k): {sym: float(f'{v:.6g}') for sym, v in zip(loads, in_file_units(t, table))}
            for k, t in own.own_tares.items()
        }
        report['validation_series_tares_sigma'] = {
            str(k): {sym: float(f'{v:.4g}') for sym, v in zip(loads, in_file_units(t, table))}
            for k, t in own.own_tare_sigma.items()
        }
        if own.own_tares:
            report['warnings'].append(
                f'validation series {", ".join(map(str, own.own_tares))} are not in the '
                'calibration (other setups): their tares were estimated from their own points '
                'with the model held fixed (validation_series_tares); their σ cannot show a '
                'wrong tare'
            )
        report['warnings'] += range_warnings(table, validation) + coverage_warning(
            own.coverage, chosen
        )
    sets = {'calibration': (table, fit.load_residuals)}
    if validation is not None:
        sets['validation'] = (validation, validations[chosen].residuals)
    report.update(signing_sections(table, fit, form, outputs, sets))
    effects, odd = outlying_components(chosen, base_fit, term_sets[chosen], table, outputs)
    report['effects'] = report['effects'] + effects
    report['unexplained'] = report['unexplained'] + odd
    report['model_selection'] = {
        'candidates': [compared_entry(k, loads) for c in choices.values() for k in c.compared],
        'adopted': {
            m: {'term_set': c.candidate.term_set, 'terms': len(c.candidate.terms), 'why': c.why}
            for m, c in choices.items()
        },
    }
    for m, c in choices.items():
        report['methods_compared'][m]['term_set'] = c.candidate.term_set
    if select:
        report['term_selection'] = {
            m: {'kept': len(sel.kept), 'removed': list(sel.removed), 'why': list(sel.reasons)}
            for m, sel in selections.items()
        }
    rows = point_rows(table, fit, t95, 'calibration', fit.load_residuals, fit.point_uncertainty)
    if validation is not None:
        rows += point_rows(
            validation, fit, t95, 'validation', validation_sigma[chosen][1], validation_u[chosen]
        )
    rated = (
        table.output_capacity[list(table.bridge_columns)]
        * table.output_factor[list(table.bridge_columns)]
    )
    if excitation_v is not None and table.output_internal_unit == 'mV/V':
        rated = rated * excitation_v
    gates = [
        channels,
        table_sensitivity_gate(table, rated, lambda: linear_response(table, outputs)[2]),
        table_outlier_gate(
            table.point_id,
            loads,
            fit.load_residuals,
            fit.press_load_residuals,
            capacity,
            label,
            applied=table.applied_loads_si,
        ),
        overfit_gate(
            report['sigma_pct_capacity']['calibration'],
            report['sigma_pct_fs_crossval']['after'],
            table.points,
            len(fit.model.terms if closing.adopted else term_sets[chosen])
            + len(fit.series_labels),
            label,
        ),
        condition_gate(fit.condition_number, label),
    ]
    acceptance = gates_report(gates, forced=force)
    report['gates'], report['forced'] = acceptance['gates'], acceptance['forced']
    refused = first_failure(gates, TABLE_PRIORITY)
    if refused is not None and not force:
        raise TableCalibrationError(_refusal(table, refused))
    rated = np.where(np.isfinite(rated) & (rated > 0), rated, np.max(np.abs(outputs), axis=0))
    models = {m: f.model for m, f in fits.items()}
    if closing.adopted and closing.diagnosis is not None:
        models[closing.model_name] = live_model(fit.model, closing.diagnosis)
    output_unit = (
        'mV'
        if excitation_v is not None or table.output_internal_unit == 'mV'
        else table.output_internal_unit
    )
    calibration = Calibration(
        table.balance_name or 'balance',
        models,
        closing.model_name,
        chosen,
        capacity,
        rated,
        tuple(loads),
        tuple(inputs),
        report['sigma_pct_fs']['after'],
        now_iso(),
        temperature_reference_c(closing),
        {
            'format': 'balfit',
            'source': table.source,
            'method_choice': why,
            'output_unit': output_unit,
            'load_units_si': list(table.load_si_units),
            'series_tares_si': {
                str(s): [float(x) for x in row] for s, row in zip(fit.series_labels, fit.tares)
            },
            'series_tares_sigma_si': {
                str(s): [float(x) for x in row]
                for s, row in zip(fit.series_labels, fit.tare_sigma)
            },
            'points': table.points,
            **channel_keys(closing),
        },
    )
    return TableCalibration(table, validation, fits, chosen, calibration, report, rows)


def _refusal(table: CalibrationTable, gate) -> str:
    return (
        f'{table.source}: refused by acceptance gate {gate.name}: {gate.reason}; nothing '
        f'written (--force writes it anyway)'
    )
