"""report.json, report.md and calibration.yaml contents of a refit (keys per interfaces.md)."""

from __future__ import annotations

from typing import cast, Mapping, Sequence

from ..accuracy.sigma import format_sigma_table
from ..accuracy.tables import format_coefficient_tables, WEAK_NOTE
from ..calibration_file import now_iso
from ..model.calibration import Calibration
from ..record import identification_markdown, signature_markdown


def _round(values: Mapping[str, float], digits: int = 5) -> dict[str, float]:
    return {k: round(float(v), digits) for k, v in values.items()}


def _diagnosis_fields(diagnosis, fits, base_model):
    """(sigma before/after, crossval before/after, effects list, adopted model or None, ref T)."""
    base = fits[base_model]
    before, cv_before = base.sigma_pct_fs, base.sigma_crossval_pct_fs
    if diagnosis is None:
        return before, before, cv_before, cv_before, [], None, None
    sigma = diagnosis.sigma_pct_fs
    cv = diagnosis.sigma_crossval_pct_fs
    effects = [_effect_report(effect) for effect in diagnosis.effects]
    live = diagnosis.live_model if diagnosis.effects else None
    return (
        sigma['before'],
        sigma['after'],
        cv['before'],
        cv['after'],
        effects,
        live,
        getattr(diagnosis, 'reference_temperature_c', None),
    )


def _effect_report(effect) -> dict:
    """interfaces.md's keys, then the numbers behind the evidence line."""
    entry = effect.to_report()
    entry.update(
        {
            'p_value': {c: float(f'{v:.3g}') for c, v in effect.p_value.items()},
            'correlation': {c: round(float(v), 3) for c, v in effect.correlation.items()},
            'removed_pct_fs': {c: round(float(v), 4) for c, v in effect.removed_pct_fs.items()},
            'sigma_before_pct_fs': {
                c: round(float(v), 4) for c, v in effect.sigma_before_pct_fs.items()
            },
            'sigma_crossval_before_pct_fs': {
                c: round(float(v), 4) for c, v in effect.press_sigma_before_pct_fs.items()
            },
            'sigma_crossval_after_pct_fs': {
                c: round(float(v), 4) for c, v in effect.press_sigma_after_pct_fs.items()
            },
            'explaining_variable': dict(effect.explaining_variable),
            'applied_live': not effect.nuisance,
        }
    )
    if effect.parameters:
        entry['parameters'] = {k: float(v) for k, v in effect.parameters.items()}
    return entry


def _body(reduction, diagnosis):
    """The body the adopted fit used and its source in interfaces.md's words."""
    if diagnosis is None:
        return reduction.body, reduction.body_source, reduction.body_source
    detail = diagnosis.body_source
    return (
        diagnosis.calibration_body,
        ('declared' if detail == 'declared' else 'estimated'),
        detail,
    )


def _live_with_covariance(live, diagnosis):
    """The adopted live model with its coefficient covariance on the points the diagnosis fitted
    (one shared (XᵀX)⁻¹ over the union of terms: conservative for components that use fewer).
    """
    from ..fit.fitted_covariance import with_fitted_covariance

    try:
        return with_fitted_covariance(
            live,
            diagnosis.corrected.bridge_outputs_mv,
            diagnosis.residuals_after,
            diagnosis.extra_variables,
        )
    except (AttributeError, KeyError, ValueError):
        # no covariance: load_standard_uncertainty gives NaN for it, never a made-up number
        return live


def build_calibration(
    config, reduction, fits, base_model, diagnosis, sources: Sequence[str]
) -> Calibration:
    # covariance for /balance/wrench_uncertainty
    from ..fit.fitted_covariance import with_fitted_covariance

    models = {
        order: with_fitted_covariance(
            fit.fit.model, reduction.corrected.bridge_outputs_mv, fit.fit.residuals
        )
        for order, fit in fits.items()
    }
    before, after, _, _, effects, live, reference = _diagnosis_fields(diagnosis, fits, base_model)
    adopted = base_model
    if live is not None:
        adopted = live.name
        models[adopted] = _live_with_covariance(live, diagnosis)
    body, source, _ = _body(reduction, diagnosis)
    return Calibration(
        config.name,
        models,
        adopted,
        base_model,
        config.capacity,
        config.rated_output_mv,
        config.components,
        config.bridge_outputs,
        _round(after),
        now_iso(),
        reference,
        {
            'calibration_body': {
                'weight_n': round(body.weight_n, 4),
                'cg_m': [round(x, 6) for x in body.cg_m],
                'source': source,
            },
            'points': int(len(reduction.points.label)),
            'sources': list(sources),
            # where the schedule put loads, alone and in pairs: `coverage` tells a run outside it
            'support': _support(config, reduction, models[base_model]),
            'effects': [e['name'] for e in effects],
            'sigma_pct_fs_base': _round(before),
        },
    )


def _support(config, reduction, base) -> dict:
    """The schedule's support (coverage/support.py) in the base model's terms, for
    calibration.yaml.
    """
    from ..coverage.support import support_of_points
    from ..model.uncertainty import covariance_and_sigma

    covariance, _ = cast(tuple, covariance_and_sigma(base))  # a fitted model carries it
    corrected = reduction.corrected
    return support_of_points(
        corrected.loads,
        base.design(corrected.bridge_outputs_mv),
        covariance,
        config.capacity,
        config.components,
        base.name,
    ).to_dict()


def build_report(config, points, reduction, fits, base_model, diagnosis, cut, sources) -> dict:
    before, after, cv_before, cv_after, effects, live, reference = _diagnosis_fields(
        diagnosis, fits, base_model
    )
    body, source, detail = _body(reduction, diagnosis)
    report = {
        'balance': config.name,
        'points': int(len(points.label)),
        'base_model': base_model,
        'calibration_body': {
            'weight_N': round(body.weight_n, 3),
            'cg_x_m': round(body.cg_m[0], 5),
            'source': source,
        },
        'sigma_pct_fs': {'before': _round(before), 'after': _round(after)},
        'sigma_pct_fs_crossval': {'before': _round(cv_before), 'after': _round(cv_after)},
        'effects': effects,
        'adopted': live is not None,
        # what is left and what to check: empty / unknown without a diagnosis
        'unexplained': [u.to_report() for u in getattr(diagnosis, 'unexplained', ())],
        'repeatability_pct_fs': {
            c: v
            for c, v in _round(getattr(diagnosis, 'repeatability_pct_fs', {}) or {}, 4).items()
            if v == v
        },  # unknown (NaN): left out
        'warnings': list(getattr(diagnosis, 'warnings', ())),
        # beyond the promised keys
        'adopted_model': live.name if live is not None else base_model,
        'models': {
            order: {
                'sigma_pct_fs': _round(f.sigma_pct_fs),
                'sigma_pct_fs_crossval': _round(f.sigma_crossval_pct_fs),
                'terms_per_component': len(f.fit.model.terms),
                'rank': f.fit.rank,
                'condition_number': float(f'{f.fit.condition_number:.4g}'),
                'unexcited_terms': list(f.fit.unexcited_terms),
            }
            for order, f in fits.items()
        },
        'table17_memo': {k: dict(v) for k, v in config.table17_sigma_pct_fs.items()},
        'calibration_body_detail': {
            'weight_N': round(body.weight_n, 4),
            'cg_m': [round(x, 6) for x in body.cg_m],
            'declared_weight_N': config.calibration_body.weight_n,
            'declared_cg_m': list(config.calibration_body.cg_m),
            'how': detail,
            'opposite_pairs': reduction.body_estimate.pairs if reduction.body_estimate else 0,
        },
        'reference_temperature_c': reference,
        'sources': list(sources),
        'fitted_at': now_iso(),
    }
    from .report_sections import calibration_record

    report['record'] = calibration_record(config, points, reduction, fits, diagnosis, body)
    if cut is not None:
        report['samples'] = {
            'used': cut.samples_used,
            'rejected_outliers': cut.samples_rejected_outliers,
            'rejected_nan': cut.samples_rejected_nan,
            'empty_points': cut.empty_points,
        }
    return report


def report_markdown(report: Mapping, result=None, units: str = 'si') -> str:
    """report.md; `units` 'lbf' or 'kgf' adds the loads in those lab units (SI stays the
    record).
    """
    from .report_sections import (
        coefficient_quality_markdown,
        lab_units_markdown,
        record_markdown,
        residual_markdown,
    )

    components = list(report['sigma_pct_fs']['before'])
    lines = [f'# Calibration report: {report["balance"]}', '']
    lines += identification_markdown(report.get('record') or {'balance': report['balance']})
    lines += [
        f'{report["points"]} load points; base model **{report["base_model"]}** (TM-663 §2); '
        f'adopted model **{report.get("adopted_model", report["base_model"])}**.',
        '',
        f'Calibration body: {report["calibration_body"]["weight_N"]:.2f} N, CG '
        f'{report["calibration_body"]["cg_x_m"]:.4f} m forward '
        f'({report["calibration_body"]["source"]}; declared '
        f'{report["calibration_body_detail"]["declared_weight_N"]:.2f} N).',
        '',
    ]
    lines += acceptance_markdown(report)
    lines += record_markdown(report)
    lines += ['## σ in % of full scale (Table 17 style, eqs. (44)-(49))', '', '```']
    rows = {}
    memo = report.get('table17_memo', {})
    for order, values in report.get('models', {}).items():
        if order in memo:
            rows[f'TM-663 Table 17 / {order}'] = memo[order]
        rows[f'this fit / {order}'] = values['sigma_pct_fs']
        rows[f'this fit / {order} (cross-val.)'] = values['sigma_pct_fs_crossval']
    rows['before (base model)'] = report['sigma_pct_fs']['before']
    rows['after (adopted)'] = report['sigma_pct_fs']['after']
    rows['before, cross-validated'] = report['sigma_pct_fs_crossval']['before']
    rows['after, cross-validated'] = report['sigma_pct_fs_crossval']['after']
    lines += [format_sigma_table(rows, components), '```', '']
    lines += residual_markdown(report) + lab_units_markdown(report, units)
    from ..diagnosis.report_text import findings_markdown

    lines += findings_markdown(report)
    if report.get('plots'):
        lines += ['', '## Residual plots', ''] + [f'![{p}]({p})' for p in report['plots']]
    if result is not None:
        lines += ['', '## Coefficients (layout of Tables 10-16; N or N·m per mV^k)', '']
        lines += [WEAK_NOTE + '.', '']
        lines += coefficient_quality_markdown(report, result)
        for order, fit in result.fits.items():
            lines += [
                f'### {order}',
                '',
                '```',
                format_coefficient_tables(fit.fit.model, fit.fit.standard_errors),
                '```',
                '',
            ]
        adopted = result.calibration.model()
        if adopted.name not in result.fits:
            lines += [
                f'### {adopted.name} (adopted)',
                '',
                '```',
                format_coefficient_tables(adopted, _standard_errors(adopted)),
                '```',
                '',
            ]
    lines += [
        '',
        f'Fitted {report.get("fitted_at", "")} from: '
        f'{", ".join(report.get("sources", [])) or "simulation"}.',
    ]
    lines += signature_markdown('calibration')
    return '\n'.join(lines) + '\n'


def _standard_errors(model):
    """(n_components, n_terms) σ_k·√((XᵀX)⁻¹_jj) from the model's stored covariance, or None."""
    import numpy as np

    from ..model.uncertainty import covariance_and_sigma

    pieces = covariance_and_sigma(model)
    if pieces is None:
        return None
    covariance, sigma = pieces
    return np.outer(sigma, np.sqrt(np.clip(np.diag(covariance), 0.0, None)))


def acceptance_markdown(report: Mapping) -> list[str]:
    """The acceptance gates (gates/) as a table; a forced refit says so first."""
    acceptance = report.get('acceptance')
    if not acceptance:
        return []
    lines = ['## Acceptance gates', '']
    if acceptance.get('forced'):
        failed = [g['name'] for g in acceptance['gates'] if not g['passed']]
        lines += [
            f'**WRITTEN WITH --force: gate(s) {", ".join(failed)} FAILED. Do not use this '
            'calibration before the failures below are understood.**',
            '',
        ]
    lines += ['| gate | result | why |', '|---|---|---|']
    lines += [
        f'| {g["name"]} | {"pass" if g["passed"] else "**FAIL**"} | '
        f'{g["reason"].replace("|", "/")} |'
        for g in acceptance['gates']
    ]
    lost = (report.get('bag_integrity') or {}).get('lost') or []
    if lost:
        lines += ['', 'Salvaged from damaged bags (--salvage); lost:', ''] + [
            f'- {line}' for line in lost
        ]
    pauses = (report.get('sessions') or {}).get('pauses_s') or []
    if pauses:
        lines += [
            '',
            f'{len(pauses) + 1} sessions; pauses of {", ".join(f"{p:.0f}" for p in pauses)} s '
            f'between them shortened on the time axis of the points.',
        ]
    return lines + ['']
