"""Gates on the fitted model itself: its σ, how much better it fits its own points than left-out
ones, and whether its coefficients are determined.

    sigma       σ of the model per component (TM-663 eqs. (44)-(49)) within the `acceptance:`
                limit (interfaces.md; limits.py): a refit
    overfit     cross-validated σ (PRESS) against the in-sample σ, per load: an honest model of q
                coefficients on N points gives a ratio near N / (N - q) (equal leverages); beyond
                OVERFIT_FACTOR times that the model fits the noise of its own points: a table
    condition   condition number of the column-scaled design within CONDITION_LIMIT: a table
"""

from __future__ import annotations

import numpy as np

from .gate import Gate

OVERFIT_FACTOR = 2.0
# a load predicted within this (% capacity) on left-out points passes whatever its ratio: a
# noise-free table's in-sample σ is round-off, the ratio of two round-offs means nothing
OVERFIT_FLOOR_PCT = 1e-3
CONDITION_LIMIT = 1e8  # of the unit-norm-column design (terms and tares)


def sigma_gate(config, sigma, limits, what) -> Gate:
    over = [c for c in config.components if not (sigma[c] <= limits.sigma_limit_pct_fs[c])]
    details = {
        'sigma_pct_fs': dict(sigma),
        'limit_pct_fs': dict(limits.sigma_limit_pct_fs),
        'model': what,
    }
    if over:
        text = ', '.join(
            f'{c} {sigma[c]:.3g} % FS > {limits.sigma_limit_pct_fs[c]:.3g}' for c in over
        )
        return Gate('sigma', False, f'σ of the {what} beyond its limit: {text}', details)
    worst = max(config.components, key=lambda c: sigma[c] / limits.sigma_limit_pct_fs[c])
    return Gate(
        'sigma',
        True,
        f'σ of the {what} within limits (closest: {worst} {sigma[worst]:.3g} of '
        f'{limits.sigma_limit_pct_fs[worst]:.3g} % FS)',
        details,
    )


def overfit_gate(
    sigma_cal: dict, sigma_cv: dict, points: int, coefficients: int, what: str
) -> Gate:
    """Cross-validated against in-sample σ (% capacity) per load, with q coefficients per load."""
    expected = points / max(points - coefficients, 1)
    limit = OVERFIT_FACTOR * expected
    ratio = {s: (sigma_cv[s] / sigma_cal[s] if sigma_cal[s] > 0 else np.inf) for s in sigma_cal}
    details = {'ratio': ratio, 'limit': limit, 'points_per_coefficient': points / coefficients}
    over = [s for s in ratio if not ratio[s] <= limit and not sigma_cv[s] <= OVERFIT_FLOOR_PCT]
    if over:
        text = ', '.join(f'{s} {sigma_cv[s]:.3g} % against {sigma_cal[s]:.3g} %' for s in over)
        return Gate(
            'overfit',
            False,
            f'the {what} fits its own points far better than it predicts left-out ones: '
            f'cross-validated σ {text} in-sample (ratio > {limit:.3g}; {coefficients} '
            f'coefficients per load on {points} points): fit fewer terms',
            details,
        )
    worst = max(ratio, key=lambda s: ratio[s] if sigma_cv[s] > OVERFIT_FLOOR_PCT else 0.0)
    return Gate(
        'overfit',
        True,
        f'cross-validated σ within {limit:.3g}x the in-sample σ '
        f'(largest: {worst} {ratio[worst]:.3g}x)',
        details,
    )


def condition_gate(condition_number: float, what: str) -> Gate:
    details = {'condition_number': condition_number, 'limit': CONDITION_LIMIT}
    if not condition_number <= CONDITION_LIMIT:
        return Gate(
            'condition',
            False,
            f"condition number of the {what}'s scaled design "
            f'{condition_number:.3g} > {CONDITION_LIMIT:.0e}: its '
            f'coefficients are not determined; fit fewer '
            f'terms',
            details,
        )
    return Gate(
        'condition',
        True,
        f'condition number {condition_number:.3g} (limit {CONDITION_LIMIT:.0e})',
        details,
    )
