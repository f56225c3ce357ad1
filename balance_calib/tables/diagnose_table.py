"""What the residuals of a table calibration still follow (the closing of the loop on table data).

A table carries no sample times, no gravity directions and usually no temperature, so most of the
refit's diagnosis (temperature, zero drift in time, creep, excitation, calibration-body tare)
cannot run. What it does carry, and what is examined here, per load:
- point order within each series (the order the rows were taken in, centred per series; a drift
  slower than a series is absorbed by the series tares): a drift of the zero or sensitivity;
- load direction within a series (magnitude of the series' dominant load rising or falling from the
  previous point): hysteresis;
- any extra channel the table has (a temperature column such as degF/degC): the residual against
it. A residual that follows one of these with p < 0.001 / (number of tests) (Bonferroni) is listed
in `unexplained` with interfaces.md's keys; nothing is adopted (the live node has none of these
inputs for a table calibration).
"""

from __future__ import annotations

import numpy as np
import scipy.stats

from ..accuracy.sigma import sample_std_pct_fs

ALPHA = 1e-3


def load_direction(applied: np.ndarray, series: np.ndarray, capacity: np.ndarray) -> np.ndarray:
    """(N,) +1 where the point's dominant load grew in magnitude since the previous point of its
    series, -1 where it shrank, 0 for a series' first point or no change.
    """
    direction = np.zeros(len(applied))
    last: dict[int, int] = {}
    relative = applied / capacity
    for i, s in enumerate(series):
        previous = last.get(int(s))
        if previous is not None:
            k = int(np.argmax(np.abs(relative[i])))
            change = abs(relative[i, k]) - abs(relative[previous, k])
            direction[i] = np.sign(change) if abs(change) > 1e-9 else 0.0
        last[int(s)] = i
    return direction


def _slope_p(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """(correlation, two-sided p) of y against x with an intercept."""
    if np.std(x) == 0 or len(x) < 4:
        return 0.0, 1.0
    result = scipy.stats.pearsonr(x, y)
    return float(result.statistic), float(result.pvalue)


def residual_structure(table, fit) -> dict:
    """{'unexplained': [...], 'examined': [...], 'skipped': {...}} for the report."""
    capacity = table.load_capacity_si
    residuals = fit.load_residuals
    # point order within each series (centred per series): across series the tares absorb a slow
    # drift
    order = np.arange(table.points, dtype=float)
    for s in np.unique(table.series):
        mask = table.series == s
        order[mask] -= order[mask].mean()
    candidates = {
        'point order': order,
        'load direction': load_direction(table.applied_loads_si, table.series, capacity),
    }
    for i, symbol in enumerate(table.output_symbols):
        if i not in table.bridge_columns:
            candidates[symbol] = table.outputs[:, i]
    tests = len(candidates) * residuals.shape[1]
    unexplained = []
    for name, x in candidates.items():
        hits, evidence = [], []
        for k, symbol in enumerate(table.load_symbols):
            r, p = _slope_p(x, residuals[:, k])
            if p < ALPHA / tests:
                hits.append(symbol)
                evidence.append(f'{symbol} r = {r:+.2f} (p = {p:.1g})')
        if hits:
            tracks = {'point order': 'point order', 'load direction': 'load history'}.get(
                name, name
            )
            sigma = sample_std_pct_fs(residuals, capacity)
            unexplained.append(
                {
                    'components': hits,
                    'evidence': f'residual follows {name}: '
                    + ', '.join(evidence)
                    + ('' if name != 'point order' else ' (drift within the series?)')
                    + ('' if name != 'load direction' else ' (hysteresis: loading vs unloading)'),
                    'tracks': tracks,
                    'sigma_pct_fs': {
                        s: round(float(sigma[table.load_symbols.index(s)]), 5) for s in hits
                    },
                }
            )
    skipped = {
        'temperature': 'no temperature channel in the table'
        if len(candidates) == 2
        else 'examined through the extra channel(s)',
        'zero_drift': 'no sample times: examined against point order instead',
        'creep': 'no sample times within a point',
        'excitation': 'no excitation channel',
        'tare': (
            'series tares are estimated with the model; no calibration body or gravity directions'
        ),
        'bidirectional': 'covered by the |F| terms of r091-96 (see term_statistics)',
        'cross_terms': 'covered by the term sets and their per-term statistics',
    }
    return {'unexplained': unexplained, 'examined': list(candidates), 'skipped': skipped}
