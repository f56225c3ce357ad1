"""The statistic the one outlier rule (outliers.py) judges: leave-one-out residuals standardised to
equal variance, their robust σ, and the flagged points worst first.

TM-663 §6 judges a calibration by its residuals; a point whose load disagrees with its outputs is
seen in its leave-one-out (PRESS) residual, e / (1 - h), which a point cannot pull towards itself.
"""

from __future__ import annotations

import numpy as np


def standardized_press(
    residuals: np.ndarray, press: np.ndarray, capacity: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Leave-one-out residuals in % of capacity, as they are and standardised.

    residuals, press (N, k) in-sample and leave-one-out residuals, N or N·m; capacity (k,).
    Returns (press_pct, standardized), both (N, k) in % of capacity: standardized is
    press · sqrt(1 - h) = press · sqrt(r / press), the same variance for every point whatever
    its leverage h.
    """
    press_pct = press / capacity * 100.0
    with np.errstate(divide='ignore', invalid='ignore'):
        scale = np.sqrt(np.clip(np.where(press != 0, residuals / press, 1.0), 0.0, 1.0))
    return press_pct, press_pct * scale


def robust_sigma(
    standardized: np.ndarray, loaded: np.ndarray, *, tail_quantile: bool = False
) -> np.ndarray:
    """(k,) robust σ of standardised residuals (N, k): 1.4826 MAD over the loaded points (N,)
    bool, or over all points when fewer than 10 are loaded (zero points carry almost no residual
    after TM-663 §5(4) and would shrink the scale). tail_quantile: at least the 90 % point of
    |residual - median| / 1.6449 as well (wide-tailed mixtures of load levels).
    """
    basis = standardized[loaded] if np.count_nonzero(loaded) >= 10 else standardized
    spread = np.abs(basis - np.median(basis, axis=0))
    robust = 1.4826 * np.median(spread, axis=0)
    if tail_quantile:
        robust = np.maximum(robust, np.quantile(spread, 0.9, axis=0) / 1.6449)
    return robust


def worst_first(
    flagged: np.ndarray, standardized: np.ndarray, threshold: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The flagged points, the worst first, and the component each is worst in.

    flagged, standardized (N, k); threshold (k,). Returns (rows (M,), components (M,)): rows
    with any flagged component ordered by their largest |standardized| / threshold (a NaN counts
    as infinitely far), and the index of that component.
    """
    rows = np.flatnonzero(np.any(flagged, axis=1))
    excess = np.nan_to_num(np.abs(standardized) / threshold, nan=np.inf)
    severity = np.max(np.where(flagged, excess, 0.0), axis=1)
    rows = rows[np.argsort(-severity[rows], kind='stable')]
    if not rows.size:
        return rows, np.zeros(0, dtype=int)
    ratio = np.where(flagged[rows], np.abs(standardized[rows]) / threshold, -np.inf)
    return rows, np.nanargmax(ratio, axis=1)
