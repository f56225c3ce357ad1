"""The loop closed on a table (interfaces.md, "Effects found in table calibrations"): the
table's points (calibration_points.py) go through the diagnosis (diagnosis/table_effects.py) and
the effects it finds are fitted into the direct form with the series tares.

The diagnosis works in the direct form (TM-663's: loads from the outputs and the extra
variables). When the iterative form was chosen, the effects are adopted only if the direct form
with them cross-validates at least as well; otherwise they are listed, not adopted.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..calibration_points import CalibrationPoints
from ..diagnosis.table_effects import diagnose_points, TableDiagnosis
from ..fit.series_tares import fit_direct, SeriesTareFit
from ..model.balance_model import BalanceModel
from ..model.terms import Term
from .model_selection import crossval_pct, FIT_ERRORS
from .table_points import points_from_table


@dataclass(frozen=True)
class ClosedLoop:
    points: CalibrationPoints
    diagnosis: TableDiagnosis | None  # None: not examined (no direct form)
    fit: SeriesTareFit | None  # direct + effects, when adopted
    adopted: bool
    model_name: str
    notes: tuple[str, ...] = ()

    def requires(self) -> list[str]:
        """The extra channels the adopted model reads (calibration.yaml `requires`)."""
        if not self.adopted or self.diagnosis is None:
            return []
        return [c.symbol for c in self.diagnosis.channels]

    def channel_references(self) -> dict:
        """Per required channel: its kind, unit and the reference its d<SYMBOL> is taken from."""
        if not self.adopted or self.diagnosis is None:
            return {}
        return {
            c.symbol: {
                'kind': c.kind,
                'variable': c.variable,
                'unit': c.internal_unit,
                'unit_in_table': c.unit,
                'reference': float(f'{c.reference:.10g}'),
            }
            for c in self.diagnosis.channels
        }


def fit_with_effects(
    points: CalibrationPoints, base_terms, diagnosis: TableDiagnosis, name: str
) -> SeriesTareFit:
    """The direct form with the diagnosis' terms added, every load, series tares as columns."""
    extra = list(diagnosis.variables)
    values = np.column_stack(
        [points.outputs] + [np.asarray(diagnosis.variables[v], float)[:, None] for v in extra]
    )
    terms = tuple(base_terms) + tuple(Term.parse(t) for t in diagnosis.added_terms)
    fit = fit_direct(
        terms,
        values,
        points.applied_loads,
        points.series,
        components=points.load_symbols,
        inputs=tuple(points.output_symbols) + tuple(extra),
        name=name,
        statistics=False,
    )
    model = fit.model
    full = BalanceModel(
        name,
        model.terms,
        model.coefficients,
        model.components,
        tuple(points.output_symbols),
        model.metadata,
    )
    return replace(fit, model=full)


def live_model(model: BalanceModel, diagnosis: TableDiagnosis) -> BalanceModel:
    """The adopted model without the terms a calibrator cannot evaluate, as the bag diagnosis'
    live model (diagnose.py): the point order (zero_drift, a nuisance of the campaign) and the
    sign of the fitted load and the point's direction `dir` (it needs the series); kept:
    outputs, the extra channels (a temperature from /balance/temperature) and each load's
    signed direction dir_X (the live load history).
    """
    ok = set(model.inputs) | {c.variable for c in diagnosis.channels}
    ok |= {v for v in diagnosis.variables if v.startswith('dir_')}
    kept = [t.name for t in model.terms if set(t.variables) <= ok]
    return model.restricted_to(kept)


def close_the_loop(table, outputs, fits, chosen: str, term_sets) -> ClosedLoop:
    """Diagnose the table's points on the direct form and adopt what is found beyond chance."""
    points = points_from_table(table, outputs)
    if 'direct' not in fits:
        return ClosedLoop(
            points,
            None,
            None,
            False,
            chosen,
            ('effects are examined in the direct form, which this table or --method excludes',),
        )
    base_terms = tuple(term_sets['direct'])
    diagnosis = diagnose_points(points, [t.name for t in base_terms])
    if not diagnosis.effects:
        return ClosedLoop(points, diagnosis, None, False, chosen)
    name = 'direct+' + '+'.join(dict.fromkeys(e.name for e in diagnosis.effects))
    try:
        fit = fit_with_effects(points, base_terms, diagnosis, name)
    except FIT_ERRORS as err:
        return ClosedLoop(
            points, diagnosis, None, False, chosen, (f'the effects could not be fitted: {err}',)
        )
    capacity = table.load_capacity_si
    worse = _worse_loads(fit, fits['direct'], capacity, table.load_symbols)
    if worse:
        # the joint fit gives every load every added term: where that costs a load more than
        # the chance scatter of its cross-validated σ, the effects are listed, not adopted
        return ClosedLoop(
            points,
            diagnosis,
            fit,
            False,
            chosen,
            (
                'effects found, not adopted: fitted into every load they raise the '
                f'cross-validated σ of {worse}',
            ),
        )
    notes: tuple[str, ...] = ()
    if chosen != 'direct':
        mine = float(np.mean(crossval_pct(fit, capacity)))
        theirs = float(np.mean(crossval_pct(fits[chosen], capacity)))
        if mine > theirs:
            return ClosedLoop(
                points,
                diagnosis,
                fit,
                False,
                chosen,
                (
                    f'effects found in the direct form, not adopted: with them its mean '
                    f"cross-validated σ ({mine:.3g} %) stays above the {chosen} form's "
                    f'({theirs:.3g} %)',
                ),
            )
        notes = (
            f'the direct form with its effects cross-validates better ({mine:.3g} %) than the '
            f'{chosen} form ({theirs:.3g} %): it is adopted',
        )
    return ClosedLoop(points, diagnosis, fit, True, name, notes)


def _worse_loads(fit, base, capacity, symbols) -> str:
    """Loads whose cross-validated σ with the effects exceeds the base's by more than its
    chance scatter, 1/sqrt(2N) of it (model_selection.SELECTION_MARGIN's reasoning).
    """
    after, before = crossval_pct(fit, capacity), crossval_pct(base, capacity)
    margin = 1.0 + 2.0 / np.sqrt(2.0 * len(fit.load_residuals))
    return ', '.join(
        f'{s} ({b:.3g} → {a:.3g} %)' for s, a, b in zip(symbols, after, before) if a > margin * b
    )


def channel_keys(closing: ClosedLoop) -> dict:
    """The calibration's `requires` and channel references (Calibration.extra; calibration_file
    writes them at the top of calibration.yaml). Nothing when no channel was adopted.
    """
    required = closing.requires()
    if not required:
        return {}
    return {'requires': required, 'channels': closing.channel_references()}


def temperature_reference_c(closing: ClosedLoop) -> float | None:
    """The adopted temperature channel's reference (degC), what the live dT is taken from."""
    for symbol, entry in closing.channel_references().items():
        if entry['kind'] == 'temperature':
            return float(entry['reference'])
    return None


def report_closing(report: dict, table, closing: ClosedLoop) -> None:
    """report.json's effects, σ after, unexplained and diagnosis from the closed loop (in place;
    `before` stays the base model build_report wrote).
    """
    from .diagnose_table import residual_structure
    from .table_report import _rms_pct, sigma_pct

    diagnosis = closing.diagnosis
    report['warnings'] += list(closing.notes)
    if diagnosis is None:
        report['diagnosis']['families'] = []
        return
    report['diagnosis']['families'] = list(diagnosis.examined)
    report['diagnosis']['not_examined'] = dict(diagnosis.skipped)
    report['warnings'] += list(diagnosis.warnings)
    entries = [e.to_report() for e in diagnosis.effects]
    if not closing.adopted:
        for entry in entries:
            entry['adopted'] = False
    report['effects'] = entries
    report['adopted'] = closing.adopted
    if not closing.adopted or closing.fit is None:
        return
    fit = closing.fit
    loads, capacity = table.load_symbols, table.load_capacity_si
    report['adopted_model'] = closing.model_name
    # the adopted fit's terms (its coefficients in report.json), the base's kept beside them
    report['base_terms'] = report['terms']
    report['terms'] = [t.name for t in fit.model.terms]
    after = sigma_pct(fit.load_residuals, capacity, loads)
    crossval = _rms_pct(fit.press_load_residuals, capacity, loads)
    report['sigma_pct_fs']['after'] = after
    report['sigma_pct_fs_crossval']['after'] = crossval
    report['sigma_pct_capacity']['calibration'] = after
    report['sigma_pct_capacity']['crossval'] = crossval
    report['unexplained'] = residual_structure(table, fit)['unexplained']
    report.update(channel_keys(closing))
