"""An adopted candidate as the EffectFound the report carries (diagnose.py)."""

from __future__ import annotations

from typing import cast

import numpy as np

from .candidates import (
    NUISANCE_EFFECTS,
)
from .result import EffectFound
from .search_state import _Candidate
from .tare_refit import BodyRefit


def _fmt_p(p: float) -> str:
    return f'{p:.1g}' if p >= 1e-99 else '< 1e-99'


def _effect_found(
    entry, final_fits, comp_terms, components, problem, points, times, live_terms=None
) -> EffectFound:
    candidate: _Candidate = entry['candidate']
    name = candidate.family
    per = {components[k]: s for k, s in candidate.components.items()}
    lines = {}
    for c, s in per.items():
        lines[c] = (
            f'{c} residual follows {s["label"]}: r = {s["r"]:.2f}, F = {s["f"]:.3g} (p = '
            f'{_fmt_p(s["p"])}), removes {s["removed"]:.3f} % FS (σ {s["sigma_before"]:.3f} → '
            f'{s["sigma_after"]:.3f}, PRESS σ {s["press_before"]:.3f} → {s["press_after"]:.3f})'
        )
    order = sorted(per, key=lambda c: -per[c]['removed'])
    evidence = lines[order[0]]
    if len(order) > 1:
        evidence += '; also ' + ', '.join(
            f'{c} (r = {per[c]["r"]:.2f}, removes {per[c]["removed"]:.3f} % FS)' for c in order[1:]
        )
    terms = []
    for c in order:
        terms += [t for t in per[c]['added'] if t not in terms]
    explaining_variable, explaining_values, contribution = {}, {}, {}
    for k, s in candidate.components.items():
        c = components[k]
        if name == 'tare':
            contribution[c] = entry['before'][k].ols.residuals - s['fit'].ols.residuals
            explaining_variable[c] = 'orientation I_g'
            explaining_values[c] = np.asarray(points.orientation, dtype=float)
            continue
        added = list(s['added'])
        index = [comp_terms[k].index(t) for t in added]
        contribution[c] = problem.columns(added) @ final_fits[k].ols.coefficients[index]
        if name == 'zero_drift':
            explaining_variable[c], explaining_values[c] = 'time (s)', times
        else:
            explaining_variable[c], explaining_values[c] = (
                added[0],
                problem.columns(added[:1])[:, 0],
            )
    parameters = {}
    if name == 'tare':
        body = cast(BodyRefit, candidate.body_refit).body
        parameters = {
            'weight_n': body.weight_n,
            'cg_x_m': body.cg_m[0],
            'cg_y_m': body.cg_m[1],
            'cg_z_m': body.cg_m[2],
        }
    return EffectFound(
        name=name,
        components=tuple(c for c in components if c in per),
        evidence=evidence,
        terms=tuple(terms),
        terms_by_component={c: tuple(per[c]['added']) for c in per},
        sigma_before_pct_fs={c: per[c]['sigma_before'] for c in per},
        sigma_after_pct_fs={c: per[c]['sigma_after'] for c in per},
        press_sigma_before_pct_fs={c: per[c]['press_before'] for c in per},
        press_sigma_after_pct_fs={c: per[c]['press_after'] for c in per},
        removed_pct_fs={c: per[c]['removed'] for c in per},
        f_value={c: per[c]['f'] for c in per},
        p_value={c: per[c]['p'] for c in per},
        correlation={c: per[c]['r'] for c in per},
        evidence_by_component=lines,
        score=float(candidate.score),
        # not applied live: a nuisance family, or none of its terms is one the live calibrator
        # evaluates
        nuisance=name in NUISANCE_EFFECTS
        or (live_terms is not None and bool(terms) and not set(terms) & live_terms),
        parameters=parameters,
        explaining_variable=explaining_variable,
        explaining_values=explaining_values,
        contribution=contribution,
    )
