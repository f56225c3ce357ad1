"""Zero points against temperature drift, TM-663 §5(4).

Every block of 5-10 load points is bracketed by no-load points in the same orientation; within a
block the zero is taken to move linearly in time between its two brackets, and is subtracted.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike


class ZeroPointError(ValueError):
    """A load point has no zero point in its orientation to refer to."""


@dataclass(frozen=True)
class ZeroCorrection:
    zeroed_outputs_mv: np.ndarray  # (N, n) outputs minus the interpolated zero
    zero_mv: np.ndarray  # (N, n) the zero that was subtracted
    before: np.ndarray  # (N,) index of the zero point used before (-1: none)
    after: np.ndarray  # (N,) index of the zero point used after (-1: none)


def subtract_zero_points(
    times_s: ArrayLike,
    outputs_mv: ArrayLike,
    is_zero_point: ArrayLike,
    orientation: ArrayLike,
    point_labels: Sequence[object] | np.ndarray | None = None,
) -> ZeroCorrection:
    """Subtract from every point the zero interpolated in time between its bracketing zero points.

    The brackets of a point are the nearest zero points before and after it *in the same
    orientation, with no change of orientation in between* (a block). A point with one bracket
    uses it alone; a point with none raises ZeroPointError naming it. Zero points are referred to
    themselves (their zeroed outputs are exactly 0), as the memo's corrected data are.
    """
    times = np.asarray(times_s, dtype=float)
    outputs = np.atleast_2d(np.asarray(outputs_mv, dtype=float))
    zero_mask = np.asarray(is_zero_point, dtype=bool)
    orient = np.asarray(orientation)
    labels = point_labels if point_labels is not None else np.arange(1, len(times) + 1)
    n = len(times)
    # blocks: maximal runs of equal orientation in time order
    order = np.argsort(times, kind='stable')
    block = np.empty(n, dtype=int)
    block[order] = np.concatenate([[0], np.cumsum(orient[order][1:] != orient[order][:-1])])

    before = np.full(n, -1)
    after = np.full(n, -1)
    last_zero = -1
    for rank, i in enumerate(order):
        if zero_mask[i]:
            last_zero = i
        if last_zero >= 0 and block[last_zero] == block[i]:
            before[i] = last_zero
    next_zero = -1
    for i in order[::-1]:
        if zero_mask[i]:
            next_zero = i
        if next_zero >= 0 and block[next_zero] == block[i]:
            after[i] = next_zero

    missing = np.flatnonzero((before < 0) & (after < 0))
    if missing.size:
        shown = ', '.join(str(labels[i]) for i in missing[:5])
        raise ZeroPointError(
            f'{missing.size} load point(s) have no zero point in the same orientation block '
            f'(first: {shown}); TM-663 §5(4) brackets every block with zero points'
        )
    b = np.where(before >= 0, before, after)
    a = np.where(after >= 0, after, before)
    span = times[a] - times[b]
    weight = np.where(span > 0, (times - times[b]) / np.where(span > 0, span, 1.0), 0.0)
    zero = outputs[b] + weight[:, None] * (outputs[a] - outputs[b])
    return ZeroCorrection(outputs - zero, zero, before, after)


def zero_point_noise_factor(
    times_s: Sequence[float] | np.ndarray, is_zero_point: ArrayLike, orientation: ArrayLike
) -> float:
    """RMS gain of independent per-point noise through the zero-point subtraction.

    The zeroed outputs are (I - W) v for a fixed interpolation matrix W; a loaded point also
    carries the noise of its brackets, a zero point none at all. For the Appendix A/B schedules
    this is about 1.11: the noise a fit sees is 11 % above the noise of one point.
    """
    n = len(times_s)
    zeroed = subtract_zero_points(times_s, np.eye(n), is_zero_point, orientation).zeroed_outputs_mv
    return float(np.sqrt(np.sum(zeroed**2) / n))
