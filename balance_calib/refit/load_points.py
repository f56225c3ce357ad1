"""Bag -> load points: cut the raw stream at the applied_load messages and average each point.

interfaces.md: a load point's samples are the /balance/raw messages stamped from its applied_load
message up to the next applied_load message; an all-NaN applied_load means "between points" and
the samples after it belong to no point. Gravity is the last /calibration/gravity before the
point. Each point is averaged per bridge after rejecting outliers (median ± k·MAD).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import BalanceConfig
from ..reduction import LoadPoints


class LoadPointError(ValueError):
    """The bag cannot be cut into load points; the message says why and names the topic."""


@dataclass(frozen=True)
class CutSummary:
    points: int
    samples_used: int
    samples_rejected_outliers: int
    samples_rejected_nan: int
    empty_points: int            # applied_load messages with no samples before the next one


def _orientation_index(gravity: np.ndarray, config: BalanceConfig | None) -> np.ndarray:
    """I_g of each gravity vector when it matches the config's Fig. 3 directions, else 101, 102..."""
    known = dict(config.gravity_directions) if config else {}
    index = np.zeros(len(gravity), dtype=int)
    extra: list[np.ndarray] = []
    for i, g in enumerate(gravity):
        match = [k for k, v in known.items() if np.allclose(v, g, atol=1e-3)]
        if match:
            index[i] = match[0]
            continue
        for j, e in enumerate(extra):
            if np.allclose(e, g, atol=1e-3):
                index[i] = 101 + j
                break
        else:
            extra.append(g)
            index[i] = 100 + len(extra)
    return index


def cut_load_points(bag, config: BalanceConfig | None = None, *, outlier_mad: float = 5.0,
                    source: str = 'bag') -> tuple[LoadPoints, CutSummary]:
    """Load points from BagData (balance_calib.bags.reader.read_bags)."""
    raw, applied, gravity, temperature = bag.raw, bag.applied_load, bag.gravity, bag.temperature
    names = bag.topics
    if len(applied) == 0:
        raise LoadPointError(f'{source} has no {names.applied_load} messages: cannot tell load points apart')
    if len(gravity) == 0:
        raise LoadPointError(f'{source} has no {names.gravity} messages: the orientation of the '
                             f'calibration body is unknown')
    order = np.argsort(raw.stamps_ns, kind='stable')
    stamps = raw.stamps_ns[order]
    values = np.asarray(raw.values, dtype=float)[order]

    marker_stamps = applied.stamps_ns
    marker_loads = np.asarray(applied.values, dtype=float)
    is_point = ~np.all(np.isnan(marker_loads), axis=1)
    if np.any(np.isnan(marker_loads[is_point])):
        bad = np.flatnonzero(is_point & np.any(np.isnan(marker_loads), axis=1))[0]
        raise LoadPointError(f'{source}: {names.applied_load} message {bad + 1} has some but not all fields NaN')
    if np.any(~np.isfinite(marker_loads[is_point])):
        raise LoadPointError(f'{source}: {names.applied_load} has infinite loads')
    point_index = np.flatnonzero(is_point)
    first_gravity = gravity.stamps_ns.min()
    if marker_stamps[point_index[0]] < first_gravity:
        raise LoadPointError(f'{source} has no {names.gravity} messages before its first load point')

    boundaries = np.append(marker_stamps, np.iinfo(np.int64).max)
    starts = np.searchsorted(stamps, marker_stamps[point_index], side='left')
    ends = np.searchsorted(stamps, boundaries[point_index + 1], side='left')

    g_order = np.argsort(gravity.stamps_ns, kind='stable')
    g_stamps = gravity.stamps_ns[g_order]
    g_vectors = np.asarray(gravity.values, float)[g_order]
    g_at = np.searchsorted(g_stamps, marker_stamps[point_index], side='right') - 1
    point_gravity = g_vectors[g_at]
    norms = np.linalg.norm(point_gravity, axis=1)
    if np.any(np.abs(norms - 1.0) > 1e-3):
        raise LoadPointError(f'{source}: {names.gravity} vectors must be unit vectors (got norm {norms.min():.4g})')

    if len(temperature):
        t_order = np.argsort(temperature.stamps_ns, kind='stable')
        t_stamps = temperature.stamps_ns[t_order].astype(float)
        t_values = np.asarray(temperature.values, float)[t_order]
    means = np.full((len(point_index), values.shape[1]), np.nan)
    times = np.full(len(point_index), np.nan)
    temps = np.full(len(point_index), np.nan)
    used = outliers = nans = empty = 0
    for p, (a, b) in enumerate(zip(starts, ends)):
        block = values[a:b]
        finite = np.all(np.isfinite(block), axis=1)
        nans += int(np.count_nonzero(~finite))
        block = block[finite]
        block_stamps = stamps[a:b][finite]
        if len(block) == 0:
            empty += 1
            continue
        median = np.median(block, axis=0)
        mad = np.median(np.abs(block - median), axis=0) * 1.4826
        keep = np.all(np.abs(block - median) <= outlier_mad * np.maximum(mad, 1e-12), axis=1) \
            if len(block) >= 5 else np.ones(len(block), bool)
        outliers += int(np.count_nonzero(~keep))
        used += int(np.count_nonzero(keep))
        means[p] = block[keep].mean(axis=0)
        times[p] = block_stamps[keep].mean() / 1e9
        if len(temperature):
            temps[p] = float(np.mean(np.interp(block_stamps[keep].astype(float), t_stamps, t_values)))
    has_samples = ~np.isnan(times)
    if not np.any(has_samples):
        raise LoadPointError(f'{source}: no {names.raw} samples fall inside any load point')
    keep_points = has_samples
    labels = np.arange(1, len(point_index) + 1)
    points = LoadPoints(labels[keep_points], means[keep_points], times[keep_points], temps[keep_points],
                        _orientation_index(point_gravity, config)[keep_points], point_gravity[keep_points],
                        marker_loads[point_index][keep_points])
    return points, CutSummary(int(keep_points.sum()), used, outliers, nans, empty)
