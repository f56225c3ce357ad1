"""Acceptance gates of a table calibration, as `refit` has (refit/gates.py: the same Gate, the same
outlier rule and limits): a calibration is written only when its data and its result look like one.

    channels      as many bridge outputs as loads, none constant (a deleted or dead bridge column)
    sensitivity   each load's response at capacity on the output that follows it, against that
                  output's rated output (the table's output capacities) where the table gives them:
                  a unit mix-up (mV/V as µV/V, kgf as N) is a factor far from 1
    overfit       cross-validated σ (PRESS) against the in-sample σ, per load: an honest model of q
                  coefficients on N points gives a ratio near N / (N - q) (equal leverages); beyond
                  OVERFIT_FACTOR times that the model fits the noise of its own points
    outliers      no point whose leave-one-out residual is beyond k robust σ (point ids named);
                  many points of a load beyond it alike are structure (odd_components.py)
    condition     condition number of the column-scaled design within CONDITION_LIMIT

A failed gate raises nothing here: `calibrate_table` refuses unless forced.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..refit.gates import (
    DEFAULT_OUTLIER_FLOOR_PCT_FS,
    DEFAULT_OUTLIER_ROBUST_SIGMAS,
    failed,
    Gate,
    robust_sigma,
    standardized_press,
    worst_first,
)

OVERFIT_FACTOR = 2.0
# a load predicted within this (% capacity) on left-out points passes whatever its ratio: a
# noise-free table's in-sample σ is round-off, the ratio of two round-offs means nothing
OVERFIT_FLOOR_PCT = 1e-3
RATED_OUTPUT_FACTOR = 2.0  # fitted response at capacity within [1/2, 2] x the rated output
CONDITION_LIMIT = 1e8  # of the unit-norm-column design (terms and tares)
CONSTANT_FRACTION = 1e-6  # a channel whose spread is below this of its size is constant
STRUCTURE_MIN_POINTS = 3  # more points of one load beyond the outlier limit than this,
DOMINANCE = 4.0  # and only those this far beyond the median of them are outliers
PRIORITY = ('channels', 'sensitivity', 'outliers', 'overfit', 'condition')


def channel_gate(table, outputs: np.ndarray) -> Gate:
    """Bridge outputs (N, n_out) in the calibration's unit: enough of them, none constant."""
    symbols = table.bridge_symbols
    spread = np.ptp(outputs, axis=0) if len(outputs) else np.zeros(len(symbols))
    size = (
        np.maximum(np.max(np.abs(outputs), axis=0), 1e-300)
        if len(outputs)
        else np.ones(len(symbols))
    )
    constant = [s for s, d, m in zip(symbols, spread, size) if not d > CONSTANT_FRACTION * m]
    details = {'outputs': list(symbols), 'constant': constant}
    if len(symbols) < table.n_loads:
        return Gate(
            'channels',
            False,
            f'{len(symbols)} bridge outputs ({", ".join(symbols)}) for '
            f'{table.n_loads} loads ({", ".join(table.load_symbols)}): a bridge column '
            f'is missing',
            details,
        )
    if constant:
        return Gate(
            'channels',
            False,
            f'bridge output(s) {", ".join(constant)} constant over all {table.points} '
            f'points: a dead or disconnected bridge',
            details,
        )
    return Gate(
        'channels',
        True,
        f'{len(symbols)} bridge outputs for {table.n_loads} loads, all varying',
        details,
    )


def sensitivity_gate(table, outputs: np.ndarray, rated: np.ndarray | None) -> Gate:
    """Each load's fitted response at capacity (linear fit of the outputs on the applied loads and
    the series) on the output it drives most, against that output's rated output (NaN: unknown).
    """
    from .term_screen import linear_response

    if rated is None or not np.any(np.isfinite(rated) & (np.asarray(rated) > 0)):
        return Gate(
            'sensitivity',
            True,
            'the table gives no rated outputs (output capacities): not checked',
            {},
        )
    _, _, response = linear_response(table, outputs)
    ratios, bad = {}, []
    for v, load in enumerate(table.load_symbols):
        k = int(np.argmax(np.abs(response[v]) / np.maximum(np.abs(rated), 1e-300)))
        if not (np.isfinite(rated[k]) and rated[k] > 0):
            continue
        ratio = float(abs(response[v, k]) / rated[k])
        ratios[load] = {'output': table.bridge_symbols[k], 'ratio': ratio}
        if not (1.0 / RATED_OUTPUT_FACTOR <= ratio <= RATED_OUTPUT_FACTOR):
            bad.append(f'{load} on {table.bridge_symbols[k]} {ratio:.3g} x its rated output')
    details = {'response_at_capacity_over_rated': ratios, 'factor': RATED_OUTPUT_FACTOR}
    if bad:
        return Gate(
            'sensitivity',
            False,
            f'response at capacity against the rated outputs: '
            f'{"; ".join(bad)} (a unit or capacity error?)',
            details,
        )
    worst = max(ratios, key=lambda s: abs(np.log(ratios[s]['ratio'])), default=None)
    text = (
        f'closest to its limit: {worst} {ratios[worst]["ratio"]:.3g}'
        if worst
        else 'none comparable'
    )
    return Gate(
        'sensitivity',
        True,
        f'responses at capacity within {RATED_OUTPUT_FACTOR:g}x of the rated outputs ({text})',
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


def outlier_gate(
    point_ids: Sequence[str],
    symbols: Sequence[str],
    residuals: np.ndarray,
    press: np.ndarray,
    capacity: np.ndarray,
    what: str,
    applied: np.ndarray | None = None,
) -> Gate:
    """Leave-one-out residuals (N, k) standardised to equal variance, against k robust σ (MAD).

    The robust σ comes from the loaded points (any applied load (N, k) not zero), as refit's gate
    takes it: a table's zero points (all loads zero, e.g. TM-663's §5(4) brackets in an exported
    campaign) fit their series tare almost exactly and would shrink the scale until the ordinary
    scatter of loaded points looked like typing errors.

    When more than STRUCTURE_MIN_POINTS points of one load are beyond it, only those beyond
    DOMINANCE times the median of them are outliers: a typed weight stands out of the points it
    drags along with it; a shape the model lacks (a low-load knee on every series of the load,
    against a MAD set by the points that never load it) moves many points alike, and is
    structure, named by odd_components.py, not refused here.
    """
    press_pct, standardized = standardized_press(residuals, press, capacity)
    loaded = (
        np.ones(len(standardized), bool)
        if applied is None
        else np.any(np.abs(applied) > 1e-9 * np.abs(capacity), axis=1)
    )
    # σ from the median (MAD) and from the 90th percentile of |residual|, the larger: a table's
    # points mix load levels and zero brackets of unequal scatter, so its residuals have wider
    # tails than one Gaussian (the 90 % point at ~1.45 MAD-σ on simulated campaigns) and 7 MAD-σ
    # alone flags ordinary points; a typed weight is far beyond either and moves neither.
    robust = robust_sigma(standardized, loaded, tail_quantile=True)
    threshold = np.maximum(DEFAULT_OUTLIER_ROBUST_SIGMAS * robust, DEFAULT_OUTLIER_FLOOR_PCT_FS)
    flagged = (np.abs(standardized) > threshold) | ~np.isfinite(standardized)
    structure = {}
    for k, symbol in enumerate(symbols):
        off = flagged[:, k] & np.isfinite(standardized[:, k])
        if np.count_nonzero(off) > STRUCTURE_MIN_POINTS:
            size = np.abs(standardized[:, k])
            alike = off & (size <= DOMINANCE * np.median(size[off]))
            structure[symbol] = [point_ids[int(i)] for i in np.flatnonzero(alike)]
            flagged[alike, k] = False
    rows, worst = worst_first(flagged, standardized, threshold)
    entries = []
    for i, k in zip(rows[:20], worst[:20]):
        entries.append(
            {
                'point_id': point_ids[i],
                'component': symbols[k],
                'residual_pct_capacity': float(press_pct[i, k]),
                'robust_sigmas': float(abs(standardized[i, k]) / max(robust[k], 1e-12)),
            }
        )
    details = {
        'points': entries,
        'count': int(len(rows)),
        'structure': structure,
        'threshold_pct_capacity': dict(zip(symbols, threshold.tolist())),
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


def first_failure(gates: Sequence[Gate]) -> Gate | None:
    bad = sorted(failed(gates), key=lambda g: PRIORITY.index(g.name) if g.name in PRIORITY else 99)
    return bad[0] if bad else None
