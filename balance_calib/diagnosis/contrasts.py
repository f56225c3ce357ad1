"""Hysteresis and sign asymmetry told apart by the schedule's own structure.

Both families fit a residual that differs between points of one load magnitude, so in a forward
selection they compete for it. The schedule itself separates them where it repeats a load:

    direction contrast  two points (not zero points) with the same applied load vector (same
                        orientation), that component's load last rising at one, falling at the
                        other (its own load may be zero: a loop is widest there):
                        c_dir = r(falling) - r(rising). A loop makes it non-zero; a sensitivity
                        that depends only on the load's sign cannot (the load is the same).
    sign contrast       two points whose load on that component is +L and -L (|L| >= 5 % of
                        capacity), every other component's load equal, both reached moving away
                        from zero: c_sign = r(+L) + r(-L), the part of the residual even in the
                        load's sign. A sensitivity step or a curvature on one sign makes it
                        non-zero; a loop traversed the same way on both sides does not (its offset
                        is odd in the load's sign there).

r is the base model's residual in % FS. Each contrast is compared with the repeatability s of
that component (lack_of_fit.py): a difference of two points has variance 2 s², so
ratio = mean(c²) / (2 s²), and the one-sided chi-square p-value of n · ratio with n pairs (pairs
that share a point are not independent: the p-value is indicative; the figure is the evidence).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import scipy.stats

EQUAL_LOAD = 1e-3  # x capacity: two applied loads this close are the same load
MIN_SIGN_LOAD = 0.05  # x capacity: a sign pair needs at least this much load


@dataclass(frozen=True)
class Contrast:
    """One component's direction or sign contrast over the pairs the schedule offers."""

    component: str
    kind: str  # 'direction' or 'sign'
    load_fraction: np.ndarray  # (n,) |L| / capacity of the pair
    value_pct_fs: np.ndarray  # (n,) c_dir or c_sign, % FS
    pairs: tuple[tuple[int, int], ...]  # point labels (falling, rising) or (+L, -L)
    ratio: float  # mean(c²) / (2 s²); nan without pairs or repeatability
    p_value: float

    @property
    def count(self) -> int:
        return len(self.value_pct_fs)


def pairs_of(
    applied: np.ndarray,
    orientation: np.ndarray,
    direction: np.ndarray,
    is_zero_point: np.ndarray,
    capacity: np.ndarray,
    k: int,
) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """Index pairs (falling, rising) of equal load and (+L, -L) of opposite load on component k.

    applied (N, 6) applied loads N, N·m; orientation (N,); direction (N, 6) ±1 raw load history;
    is_zero_point (N,); capacity (6,).
    """
    return pairs_of_components(applied, orientation, direction, is_zero_point, capacity, [k])[0]


def pairs_of_components(
    applied: np.ndarray,
    orientation: np.ndarray,
    direction: np.ndarray,
    is_zero_point: np.ndarray,
    capacity: np.ndarray,
    components: Sequence[int],
) -> list[tuple[list[tuple[int, int]], list[tuple[int, int]]]]:
    """pairs_of for each component index in `components`, in that order: the comparisons of
    every point with every other (the same for all components) made once.
    """
    applied = np.asarray(applied, dtype=float)
    orientation = np.asarray(orientation)
    direction = np.asarray(direction)
    capacity = np.asarray(capacity, dtype=float)
    candidates = np.flatnonzero(~np.asarray(is_zero_point, bool))
    strong = np.abs(applied) >= MIN_SIGN_LOAD * capacity  # (N, 6)
    sign = np.sign(applied)
    # every pair (i, j) of candidates with i before j, a block of rows i at a time, in the order
    # of the loop over i then j the rule reads as (np.nonzero is row-major)
    found: list[tuple[list[tuple[int, int]], list[tuple[int, int]]]] = [
        ([], []) for _ in components
    ]
    n = len(candidates)
    rows = max(1, 200_000 // max(n, 1))
    for first in range(0, n, rows):
        i = candidates[first : first + rows][:, None]  # (r, 1)
        j = candidates[None, :]  # (1, n)
        later = np.arange(first, min(first + rows, n))[:, None] < np.arange(n)[None, :]
        same = later & (orientation[i] == orientation[j])
        close = np.abs(applied[i] - applied[j]) <= EQUAL_LOAD * capacity  # (r, n, 6)
        n_close = np.count_nonzero(close, axis=2)
        equal = n_close == close.shape[2]
        for (direction_pairs, sign_pairs), k in zip(found, components):
            # equal on every component but k (any load on k)
            equal_but_k = n_close - close[:, :, k] == close.shape[2] - 1
            # equal load, any size on k itself (the loop is widest at zero): opposite history
            opposite_history = same & (direction[i, k] != direction[j, k]) & equal
            opposite_sign = (
                same
                & ~opposite_history
                & strong[i, k]
                & strong[j, k]
                & (sign[i, k] == -sign[j, k])
                & (
                    np.abs(np.abs(applied[i, k]) - np.abs(applied[j, k]))
                    <= EQUAL_LOAD * capacity[k]
                )
                & equal_but_k
                # both moving away from zero: a loop's offset is then odd in the sign
                & (direction[i, k] * sign[i, k] == direction[j, k] * sign[j, k])
            )
            for a, b in zip(*np.nonzero(opposite_history)):
                p, q = int(i[a, 0]), int(j[0, b])
                direction_pairs.append((p, q) if direction[p, k] < 0 else (q, p))
            for a, b in zip(*np.nonzero(opposite_sign)):
                p, q = int(i[a, 0]), int(j[0, b])
                sign_pairs.append((p, q) if applied[p, k] > 0 else (q, p))
    return found


def _contrast(component, kind, pairs, values, load_fraction, labels, repeatability) -> Contrast:
    values = np.asarray(values, float)
    ratio, p_value = float('nan'), float('nan')
    if len(values) and repeatability and repeatability > 0:
        ratio = float(np.mean(values**2) / (2.0 * repeatability**2))
        p_value = float(scipy.stats.chi2.sf(len(values) * ratio, len(values)))
    return Contrast(
        component,
        kind,
        np.asarray(load_fraction, float),
        values,
        tuple((int(labels[a]), int(labels[b])) for a, b in pairs),
        ratio,
        p_value,
    )


def schedule_contrasts(
    diagnosis, residuals: np.ndarray | None = None
) -> dict[str, tuple[Contrast, Contrast]]:
    """Component -> (direction contrast, sign contrast) of the base model's residuals (or of
    `residuals` (N, 6) N, N·m, e.g. the adopted model's).
    """
    corrected = diagnosis.corrected
    applied = np.asarray(corrected.loads, float) - np.asarray(corrected.tare_loads, float)
    capacity = np.asarray(diagnosis.capacity, float)
    residual = np.asarray(diagnosis.residuals_before if residuals is None else residuals, float)
    residual_pct = residual / capacity * 100.0
    is_zero = np.all(np.abs(applied) <= EQUAL_LOAD * capacity, axis=1)
    out = {}
    pairs = pairs_of_components(
        applied,
        diagnosis.orientation,
        diagnosis.load_direction,
        is_zero,
        capacity,
        range(len(diagnosis.components)),
    )
    for k, component in enumerate(diagnosis.components):
        direction_pairs, sign_pairs = pairs[k]
        s = float(diagnosis.repeatability_pct_fs.get(component, float('nan')))
        c_dir = [residual_pct[f, k] - residual_pct[r, k] for f, r in direction_pairs]
        x_dir = [abs(applied[f, k]) / capacity[k] for f, _ in direction_pairs]
        c_sign = [residual_pct[p, k] + residual_pct[m, k] for p, m in sign_pairs]
        x_sign = [abs(applied[p, k]) / capacity[k] for p, _ in sign_pairs]
        out[component] = (
            _contrast(
                component, 'direction', direction_pairs, c_dir, x_dir, diagnosis.point_labels, s
            ),
            _contrast(component, 'sign', sign_pairs, c_sign, x_sign, diagnosis.point_labels, s),
        )
    return out
