"""Table -> calibration: both model forms with series tares, method choice, validation,
uncertainty.

Pure (writes nothing): `calibrate_table` returns the Calibration (loadable by balance_calibrator),
the report dict (interfaces.md keys) and per-point rows; calibrate/path.calibrate runs it for a
table's points and calibrate/write_record.py writes them.
"""

from __future__ import annotations

from dataclasses import dataclass
import re
from typing import cast, Mapping, Sequence

import numpy as np
import scipy.stats

from ..calibration_file import now_iso
from ..calibration_settings import TableOptions
from ..calibration_stages import run_stages
from ..fit.series_tares import SeriesTareFit
from ..gates.fit_quality import condition_gate, overfit_gate
from ..gates.gate import Gate, gates_report, TABLE_PRIORITY
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
    """The calibration of `table`, pure (writes nothing): TableStages run in the path's one order
    (calibration_stages.run_stages). A failed gate is a TableCalibrationError unless `force`.
    """
    options = TableOptions(method, terms, validation, excitation_v, select)
    return run_stages(TableStages(table, options, statistics), force)


class TableStages:
    """The stages (calibration_stages.py) of a table's points: both model forms with series
    tares, term sets, method choice and validation; the loop closed on what the table carries
    (closing.py) and its outlying components; the table's gates.
    """

    priority = TABLE_PRIORITY
    names_others = False

    def __init__(self, table: CalibrationTable, options: TableOptions, statistics: bool) -> None:
        method, validation = options.method, options.validation
        if method not in ('auto',) + METHODS:
            raise TableCalibrationError(f'--method {method!r}: expected auto, direct or iterative')
        _check_names(table)
        self.table, self.options, self.statistics = table, options, statistics
        self.where = table.source
        self.outputs = _outputs(table, options.excitation_v)
        self.capacity = table.load_capacity_si
        self.loads, self.inputs = table.load_symbols, table.bridge_symbols
        if validation is not None and (
            validation.load_symbols != self.loads
            or validation.bridge_symbols != self.inputs
            or validation.load_units != table.load_units
            or validation.output_units != table.output_units
        ):
            raise TableCalibrationError(
                f'{validation.source}: symbols or units differ from the '
                f'calibration table {table.source}'
            )

    def refused(self, message: str) -> Exception:
        return TableCalibrationError(message)

    def screen(self) -> list[Gate]:
        """The channels, before any fit."""
        return [channel_gate(self.table, self.outputs)]

    def fit(self) -> None:
        """Term sets within each form, the form chosen, and the validation of every form."""
        table, outputs, loads = self.table, self.outputs, self.loads
        method, select = self.options.method, self.options.select
        validation = self.options.validation
        methods = METHODS if (method == 'auto' or validation is not None) else (method,)
        if len(self.inputs) != len(loads) and 'iterative' in methods:
            if method == 'iterative':
                raise TableCalibrationError(
                    f'{table.source}: the iterative method needs as many '
                    f'bridge outputs as loads ({len(self.inputs)} outputs, '
                    f'{len(loads)} loads)'
                )
            methods = ('direct',)
        specs = AUTO_TERM_SETS if self.options.terms == 'auto' else (self.options.terms,)
        choices = {
            m: choose_within_form(m, specs, table, outputs, prune=not select) for m in methods
        }
        term_sets = {m: c.candidate.terms for m, c in choices.items()}
        selections = {}
        try:
            # fitted ones
            chosen_fits = {m: cast(SeriesTareFit, c.candidate.fit) for m, c in choices.items()}
            fits: dict[str, SeriesTareFit] = {
                m: with_statistics(m, chosen_fits[m], term_sets[m], table, outputs)
                if self.statistics
                else chosen_fits[m]
                for m in choices
            }
            if select:
                for m in list(fits):
                    term_sets[m], selections[m] = select_terms(
                        m, term_sets[m], fits[m], table, outputs, table.applied_loads_si
                    )
                    if selections[m].removed:
                        fits[m] = fit_form(
                            m, term_sets[m], table, outputs, statistics=self.statistics
                        )
        except FIT_ERRORS as err:
            raise TableCalibrationError(f'{table.source}: {err}') from None

        if method == 'auto' and len(fits) == 2:
            chosen, why = choose_form(fits, self.capacity, loads)
        else:
            chosen = method if method != 'auto' else next(iter(fits))
            why = (
                f'{chosen}: asked for with --method {method}'
                if method != 'auto'
                else f'{chosen}: the only form the table allows (outputs and loads differ in '
                'number)'
            )
        why += f'; terms: {choices[chosen].why}'
        self.choices, self.term_sets, self.selections = choices, term_sets, selections
        self.fits, self.chosen, self.why = fits, chosen, why
        self.fit_adopted = fits[chosen]

        # validation: the calibration's tares for its series, own tares (model fixed) for the
        # others
        self.validations: dict[str, FormValidation] = {}
        self.validation_sigma: dict = {}
        self.validation_u: dict = {}
        if validation is not None:
            val_outputs = _outputs(validation, self.options.excitation_v)
            for m, f in fits.items():
                self.validations[m] = validate_form(m, f, validation, val_outputs)
                residual = self.validations[m].residuals
                self.validation_sigma[m] = (sigma_pct(residual, self.capacity, loads), residual)
                self.validation_u[m] = self.validations[m].uncertainty

    def data_gates(self) -> list[Gate]:
        """The sensitivities against the table's rated outputs."""
        table, outputs = self.table, self.outputs
        rated = (
            table.output_capacity[list(table.bridge_columns)]
            * table.output_factor[list(table.bridge_columns)]
        )
        if self.options.excitation_v is not None and table.output_internal_unit == 'mV/V':
            rated = rated * self.options.excitation_v
        self.rated = rated
        return [table_sensitivity_gate(table, rated, lambda: linear_response(table, outputs)[2])]

    def diagnose(self) -> None:
        """The report of the fits, the loop closed on the table (effects adopted beyond chance)
        and the outlying components.
        """
        table, outputs, loads = self.table, self.outputs, self.loads
        validation, choices, chosen = self.options.validation, self.choices, self.chosen
        fits, term_sets, fit = self.fits, self.term_sets, self.fit_adopted
        self.t95 = t95 = float(scipy.stats.t.ppf(0.975, fit.dof))
        report = build_report(
            table,
            validation,
            fits,
            FormChoice(
                chosen, self.why, term_sets, {m: c.candidate.term_set for m, c in choices.items()}
            ),
            self.validation_sigma,
            self.validation_u,
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
            own = self.validations[chosen]
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
                    'calibration (other setups): their tares were estimated from their own '
                    'points with the model held fixed (validation_series_tares); their σ cannot '
                    'show a wrong tare'
                )
            report['warnings'] += range_warnings(table, validation) + coverage_warning(
                own.coverage, chosen
            )
        sets = {'calibration': (table, fit.load_residuals)}
        if validation is not None:
            sets['validation'] = (validation, self.validations[chosen].residuals)
        report.update(signing_sections(table, fit, form, outputs, sets))
        effects, odd = outlying_components(chosen, base_fit, term_sets[chosen], table, outputs)
        report['effects'] = report['effects'] + effects
        report['unexplained'] = report['unexplained'] + odd
        report['model_selection'] = {
            'candidates': [compared_entry(k, loads) for c in choices.values() for k in c.compared],
            'adopted': {
                m: {
                    'term_set': c.candidate.term_set,
                    'terms': len(c.candidate.terms),
                    'why': c.why,
                }
                for m, c in choices.items()
            },
        }
        for m, c in choices.items():
            report['methods_compared'][m]['term_set'] = c.candidate.term_set
        if self.options.select:
            report['term_selection'] = {
                m: {'kept': len(sel.kept), 'removed': list(sel.removed), 'why': list(sel.reasons)}
                for m, sel in self.selections.items()
            }
        rows = point_rows(
            table, fit, t95, 'calibration', fit.load_residuals, fit.point_uncertainty
        )
        if validation is not None:
            rows += point_rows(
                validation,
                fit,
                t95,
                'validation',
                self.validation_sigma[chosen][1],
                self.validation_u[chosen],
            )
        self.report, self.rows, self.closing = report, rows, closing
        self.fit_adopted, self.label = fit, label

    def fit_gates(self) -> list[Gate]:
        """Outliers, overfit and condition of the model adopted (effects found included)."""
        fit, label, closing = self.fit_adopted, self.label, self.closing
        return [
            table_outlier_gate(
                self.table.point_id,
                self.loads,
                fit.load_residuals,
                fit.press_load_residuals,
                self.capacity,
                label,
                applied=self.table.applied_loads_si,
            ),
            overfit_gate(
                self.report['sigma_pct_capacity']['calibration'],
                self.report['sigma_pct_fs_crossval']['after'],
                self.table.points,
                len(fit.model.terms if closing.adopted else self.term_sets[self.chosen])
                + len(fit.series_labels),
                label,
            ),
            condition_gate(fit.condition_number, label),
        ]

    def result(self, gates: Sequence[Gate], forced: bool) -> TableCalibration:
        """The calibration (loadable by balance_calibrator), its report and per-point rows."""
        table, report, closing, fit = self.table, self.report, self.closing, self.fit_adopted
        acceptance = gates_report(gates, forced=forced)
        report['gates'], report['forced'] = acceptance['gates'], acceptance['forced']
        rated = np.where(
            np.isfinite(self.rated) & (self.rated > 0),
            self.rated,
            np.max(np.abs(self.outputs), axis=0),
        )
        models = {m: f.model for m, f in self.fits.items()}
        if closing.adopted and closing.diagnosis is not None:
            models[closing.model_name] = live_model(fit.model, closing.diagnosis)
        output_unit = (
            'mV'
            if self.options.excitation_v is not None or table.output_internal_unit == 'mV'
            else table.output_internal_unit
        )
        calibration = Calibration(
            table.balance_name or 'balance',
            models,
            closing.model_name,
            self.chosen,
            self.capacity,
            rated,
            tuple(self.loads),
            tuple(self.inputs),
            report['sigma_pct_fs']['after'],
            now_iso(),
            temperature_reference_c(closing),
            {
                'format': 'balfit',
                'source': table.source,
                'method_choice': self.why,
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
        return TableCalibration(
            table,
            self.options.validation,
            self.fits,
            self.chosen,
            calibration,
            report,
            self.rows,
        )
