"""Hysteresis and sign asymmetry told apart by the schedule's own structure (issue 24).

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
that component (leftovers.py): a difference of two points has variance 2 s², so
ratio = mean(c²) / (2 s²), and the one-sided chi-square p-value of n · ratio with n pairs (pairs
that share a point are not independent: the p-value is indicative; the figure is the evidence).
"""

from __future__ import annotations

from dataclasses import dataclass

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


def _equal(a: np.ndarray, b: np.ndarray, capacity: np.ndarray, skip: int | None = None) -> bool:
    close = np.abs(a - b) <= EQUAL_LOAD * capacity
    if skip is not None:
        close[skip] = True
    return bool(np.all(close))


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
    not_zero = ~np.asarray(is_zero_point, bool)
    strong = np.abs(applied[:, k]) >= MIN_SIGN_LOAD * capacity[k]
    candidates = np.flatnonzero(not_zero)
    direction_pairs, sign_pairs = [], []
    for a_index, i in enumerate(candidates):
        for j in candidates[a_index + 1 :]:
            if orientation[i] != orientation[j]:
                continue
            # equal load, any size on k itself (the loop is widest at zero): opposite history
            if direction[i, k] != direction[j, k] and _equal(applied[i], applied[j], capacity):
                falling, rising = (i, j) if direction[i, k] < 0 else (j, i)
                direction_pairs.append((int(falling), int(rising)))
            elif (
                strong[i]
                and strong[j]
                and np.sign(applied[i, k]) == -np.sign(applied[j, k])
                and abs(abs(applied[i, k]) - abs(applied[j, k])) <= EQUAL_LOAD * capacity[k]
                and _equal(applied[i], applied[j], capacity, skip=k)
                # both moving away from zero: a loop's offset is then odd in the sign
                and (
                    direction[i, k] * np.sign(applied[i, k])
                    == direction[j, k] * np.sign(applied[j, k])
                )
            ):
                plus, minus = (i, j) if applied[i, k] > 0 else (j, i)
                sign_pairs.append((int(plus), int(minus)))
    return direction_pairs, sign_pairs


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
    for k, component in enumerate(diagnosis.components):
        direction_pairs, sign_pairs = pairs_of(
            applied, diagnosis.orientation, diagnosis.load_direction, is_zero, capacity, k
        )
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
