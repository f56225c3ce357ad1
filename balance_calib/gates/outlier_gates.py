"""The `outliers` gate of a refit and of a table calibration: the one rule (outliers.py) in the
words and report keys each has (interfaces.md, report.json `acceptance.gates` of a refit, `gates`
of `fit`): a refit names points by label and I_g in % FS, a table by point id in % capacity.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from .gate import Gate, ModelResiduals
from .limits import AcceptanceLimits, DEFAULT_OUTLIER_ROBUST_SIGMAS
from .outliers import judge_outliers, JudgedResiduals, OutlierRule


def bag_outlier_gate(
    config,
    points,
    model: ModelResiduals,
    limits: AcceptanceLimits,
    unexplained: Mapping[str, str] | None = None,
    structure=None,
) -> Gate:
    """A refit's outliers: points LoadPoints; unexplained: component -> what the diagnosis's
    unexplained structure there tracks (named as a cause besides a weight or marker error);
    structure: diagnosis.coherence.CampaignStructure or None (what may explain a flagged point).
    """
    what = model.what
    data = JudgedResiduals(
        config.components, model.residuals, model.press, config.capacity, ~points.is_zero_point
    )
    rule = OutlierRule(limits.outlier_robust_sigmas, limits.outlier_floor_pct_fs)
    verdict = judge_outliers(data, rule, structure)
    standardized, robust, rows = verdict.standardized, verdict.robust, verdict.rows
    entries = []
    for i, k in zip(rows[:20], verdict.worst[:20]):
        entries.append(
            {
                'point': int(points.label[i]),
                'orientation': int(points.orientation[i]),
                'component': config.components[k],
                'residual_pct_fs': float(verdict.press_pct[i, k]),
                'robust_sigmas': float(abs(standardized[i, k]) / max(robust[k], 1e-12)),
                'applied_load': [float(x) for x in points.applied_loads[i]],
            }
        )
    with np.errstate(divide='ignore', invalid='ignore'):
        largest = float(np.nanmax(np.abs(standardized) / np.maximum(robust, 1e-12)))
    details = {
        'threshold_pct_fs': dict(zip(config.components, verdict.threshold)),
        'points': entries,
        'count': int(len(rows)),
        'largest_robust_sigmas': largest,
        'model': what,
    }
    coherent = _explained_text(config, points, verdict.explained, structure)
    if coherent:
        details['explained_by_structure'] = coherent[1]
    if not len(rows):
        if coherent:
            return Gate('outliers', True, f'no point wrong on its own: {coherent[0]}', details)
        return Gate(
            'outliers',
            True,
            f'no point beyond {limits.outlier_robust_sigmas:g} robust σ '
            f'(largest {largest:.1f}; leave-one-out residuals of the {what})',
            details,
        )
    first = entries[0]
    more = (
        f' and {len(rows) - 1} more (points {", ".join(str(e["point"]) for e in entries[1:6])}'
        f'{"…" if len(rows) > 6 else ""})'
        if len(rows) > 1
        else ''
    )
    cause = 'a weight, unit or marker error?'
    tracks = (unexplained or {}).get(first['component'])
    if tracks is not None:  # structure the diagnosis could not name, on the same component
        cause = (
            f'a weight, unit or marker error, or the structure the diagnosis left unexplained on '
            f'{first["component"]} (it tracks {tracks}): an effect the model lacks?'
        )
        details['unexplained_tracks'] = tracks
    besides = f'; besides, {coherent[0]}' if coherent else ''
    return Gate(
        'outliers',
        False,
        f'point {first["point"]} (I_g {first["orientation"]}): its {first["component"]} load '
        f'disagrees with its outputs by {first["residual_pct_fs"]:+.3g} % FS '
        f'({first["robust_sigmas"]:.0f} robust σ; {cause}){more}{besides}',
        details,
    )


def _explained_text(config, points, explained, structure):
    """(one line, details) on the flagged points a structure explains, or None."""
    if structure is None or not np.any(explained):
        return None
    parts, details = [], {}
    for k, component in enumerate(config.components):
        rows = np.flatnonzero(explained[:, k])
        if len(rows):
            labels = [int(points.label[i]) for i in rows]
            details[component] = {'points': labels, 'structure': structure.covered[component]}
            listed = ', '.join(str(x) for x in labels[:5]) + ('…' if len(labels) > 5 else '')
            named = structure.named.get(component)
            if named:
                details[component]['named'] = named
            parts.append(
                f'{len(rows)} point(s) beyond the threshold on {component} '
                f'(points {listed}) follow {structure.covered[component]}, which the '
                f'other points share' + (f' and {named} fitted in part' if named else '')
            )
    return '; '.join(parts) + ' (an effect the model lacks, not a weight or marker error)', details


def table_outlier_gate(
    point_ids: Sequence[str],
    symbols: Sequence[str],
    residuals: np.ndarray,
    press: np.ndarray,
    capacity: np.ndarray,
    what: str,
    applied: np.ndarray | None = None,
) -> Gate:
    """A table's outliers: leave-one-out residuals (N, k) of the loads, capacity (k,).

    The robust σ comes from the loaded points (any applied load (N, k) not zero), as a refit's:
    a table's zero points (all loads zero, e.g. TM-663's §5(4) brackets in an exported campaign)
    fit their series tare almost exactly and would shrink the scale until the ordinary scatter
    of loaded points looked like typing errors. The rule's `tail_quantile` and `alike` are on
    (outliers.py): many points of a load beyond the limit alike are structure, named by
    outlying_components.py, not refused here.
    """
    loaded = (
        np.ones(len(residuals), bool)
        if applied is None
        else np.any(np.abs(applied) > 1e-9 * np.abs(capacity), axis=1)
    )
    data = JudgedResiduals(symbols, residuals, press, capacity, loaded)
    verdict = judge_outliers(data, OutlierRule(tail_quantile=True, alike=True))
    rows, robust = verdict.rows, verdict.robust
    entries = []
    for i, k in zip(rows[:20], verdict.worst[:20]):
        entries.append(
            {
                'point_id': point_ids[i],
                'component': symbols[k],
                'residual_pct_capacity': float(verdict.press_pct[i, k]),
                'robust_sigmas': float(abs(verdict.standardized[i, k]) / max(robust[k], 1e-12)),
            }
        )
    structure = {s: [point_ids[int(i)] for i in r] for s, r in verdict.alike.items()}
    details = {
        'points': entries,
        'count': int(len(rows)),
        'structure': structure,
        'threshold_pct_capacity': dict(zip(symbols, verdict.threshold.tolist())),
    }
    alike = ''.join(
        f'; {s}: {len(p)} points beyond it alike, structure not outliers (named in '
        f'effects/unexplained)'
        for s, p in structure.items()
        if p
    )
    if not len(rows):
        return Gate(
            'outliers',
            True,
            f'no point beyond {DEFAULT_OUTLIER_ROBUST_SIGMAS:g} '
            f'robust σ (leave-one-out residuals of the {what})'
            f'{alike}',
            details,
        )
    first = entries[0]
    more = (
        (
            f' and {len(rows) - 1} more ({", ".join(e["point_id"] for e in entries[1:6])}'
            f'{"…" if len(rows) > 6 else ""})'
        )
        if len(rows) > 1
        else ''
    )
    return Gate(
        'outliers',
        False,
        f'point {first["point_id"]}: its {first["component"]} load disagrees with its '
        f'outputs by {first["residual_pct_capacity"]:+.3g} % capacity '
        f'({first["robust_sigmas"]:.0f} robust σ; a weight, unit or typing error?){more}',
        details,
    )
