"""Bag -> load points: cut the raw stream at the applied_load messages and average each point.

interfaces.md: a load point's samples are the /balance/raw messages stamped from its applied_load
message up to the next applied_load message; an all-NaN applied_load means "between points" and
the samples after it belong to no point. Gravity is the last /calibration/gravity before the
point. Each point is averaged per bridge after rejecting outliers (median ± k·MAD, the larger of
the point's own MAD and the campaign's typical one).

Everything is cut by the data's structure, never by arrays spanning wall time: markers are taken
in stamp order (a marker whose stamp goes back against the recorder's order is counted for the
acceptance gates), the last point ends one typical point period after its marker (a sample after a
clock jump joins no point), and pauses between sessions (a lunch break, a night) are shortened on
the points' time axis to one typical point spacing, so a campaign split over days refits like the
unsplit one and nothing downstream grows with the length of a pause.

Each point also keeps its own scatter, the repeatability yardstick of the residual diagnosis
(diagnosis/lack_of_fit.py): per bridge, the variance of the point's mean output (mV²) and the
number of samples averaged. The estimator is the mean square successive difference of the samples
kept, in time order (von Neumann): s² = Σ (v[j+1] - v[j])² / (2 (n - 1)), variance of the mean s² /
n. A point's samples are not always stationary: the output settles or creeps after the weights are
hung, the zero drifts; a trend of δ per sample adds only δ²/2 to this estimate, whereas it adds the
trend's whole spread (Δ²/12 over the point) to the variance about the point mean and would make the
yardstick too lenient for exactly the effects the diagnosis should flag. For white noise both
estimate σ²; this one has fewer effective degrees of freedom (about 2 (n - 1)² / (3n - 4) instead
of n - 1 per point), which over hundreds of points hardly moves the F-test. It sees noise within a
point only: scatter slower than a point (the loading hardware, drift) shows in the zero points,
which the diagnosis compares with it. Memory: two (P, n) arrays.
"""

from __future__ import annotations

import numpy as np

from ..calibration_points import CutSummary
from ..config import BalanceConfig
from ..reduction import LoadPoints


class LoadPointError(ValueError):
    """The bag cannot be cut into load points; the message says why and names the topic."""


# An applied load beyond this many rated loads is no calibration weight.
ABSURD_LOAD_CAPACITIES = 1000.0
# A pause longer than this many typical point spacings separates two sessions.
PAUSE_SPACINGS = 10.0
# A point's samples end at most this many typical marker periods after its marker.
POINT_PERIODS = 4


def shorten_pauses(times_s: np.ndarray) -> tuple[np.ndarray, tuple[float, ...]]:
    """Point times with every pause longer than PAUSE_SPACINGS typical spacings cut to one spacing.

    times_s (P,) s. Returns the new times (same order, same first time) and the pauses found (s).
    Within a session nothing moves; the zero points of §5(4) bracket each block in either case.
    """
    times = np.asarray(times_s, dtype=float)
    if len(times) < 3:
        return times, ()
    order = np.argsort(times, kind='stable')
    steps = np.diff(times[order])
    positive = steps[steps > 0]
    spacing = float(np.median(positive)) if len(positive) else 0.0
    if spacing <= 0:
        return times, ()
    long = steps > PAUSE_SPACINGS * spacing
    if not np.any(long):
        return times, ()
    shortened = np.where(long, spacing, steps)
    new = np.empty_like(times)
    new[order] = times[order[0]] + np.concatenate([[0.0], np.cumsum(shortened)])
    return new, tuple(float(x) for x in steps[long])


def successive_difference_variance(samples: np.ndarray) -> np.ndarray:
    """(n_bridges,) variance of one sample from the mean square successive difference, mV².

    samples (n, n_bridges) in time order, n >= 2: Σ (v[j+1] - v[j])² / (2 (n - 1)). Unbiased for
    white noise; a slow trend within the point adds only (its step per sample)² / 2.
    """
    steps = np.diff(np.asarray(samples, dtype=float), axis=0)
    return np.sum(steps**2, axis=0) / (2.0 * len(steps))


def _medians_and_scales(values: np.ndarray, rows: list[np.ndarray]) -> tuple:
    """Per point, the median of its samples and their robust scale (MAD x 1.4826; NaN with fewer
    than 5 samples): two (P, n) arrays, NaN for a point without samples.

    values (S, n) mV; rows[p] the indices into values of point p's samples. The points with as
    many samples as each other are taken together (one np.median for all of them: a campaign's
    points mostly have the same count).
    """
    medians = np.full((len(rows), values.shape[1]), np.nan)
    scales = np.full((len(rows), values.shape[1]), np.nan)
    lengths = np.array([len(r) for r in rows], dtype=int)
    for length in np.unique(lengths):
        if length == 0:
            continue
        points = np.flatnonzero(lengths == length)
        blocks = values[np.stack([rows[p] for p in points])]  # (points, length, n)
        medians[points] = np.median(blocks, axis=1)
        if length >= 5:
            deviations = np.abs(blocks - medians[points][:, None, :])
            scales[points] = np.median(deviations, axis=1) * 1.4826
    return medians, scales


def _flat_tops(values: np.ndarray, point_of_sample: np.ndarray, bridges) -> tuple:
    """Bridges whose samples pile up on one extreme value in several points: a clipped amplifier.

    values (S, n) mV of samples inside points; point_of_sample (S,) the point of each. A real
    bridge's noise makes equal extremes in two points practically impossible.
    """
    found = []
    for k, bridge in enumerate(bridges):
        column = values[:, k]
        if len(column) < 3:
            continue
        for extreme in (column.max(), column.min()):
            at = column == extreme
            samples = int(np.count_nonzero(at))
            points = len(np.unique(point_of_sample[at]))
            if samples >= 3 and points >= 2:
                found.append((bridge, float(extreme), samples, points))
    return tuple(found)


def _orientation_index(gravity: np.ndarray, config: BalanceConfig | None) -> np.ndarray:
    """I_g of each gravity vector when it matches the config's Fig. 3 directions, else 101,
    102...
    """
    known = dict(config.gravity_directions) if config else {}
    gravity = np.asarray(gravity, dtype=float)
    index = np.zeros(len(gravity), dtype=int)
    if known:
        keys = np.array(list(known))
        vectors = np.array([known[k] for k in keys], dtype=float)
        close = np.all(
            np.abs(gravity[:, None, :] - vectors[None, :, :])
            <= 1e-3 + 1e-5 * np.abs(vectors[None]),
            axis=2,
        )
        matched = np.any(close, axis=1)
        index[matched] = keys[np.argmax(close[matched], axis=1)]
    else:
        matched = np.zeros(len(gravity), bool)
    extra: list[np.ndarray] = []
    for i in np.flatnonzero(~matched):
        g = gravity[i]
        for j, e in enumerate(extra):
            if np.allclose(e, g, atol=1e-3):
                index[i] = 101 + j
                break
        else:
            extra.append(g)
            index[i] = 100 + len(extra)
    return index


def cut_load_points(
    bag, config: BalanceConfig | None = None, *, outlier_mad: float = 5.0, source: str = 'bag'
) -> tuple[LoadPoints, CutSummary]:
    """Load points from BagData (balance_calib.bags.reader.read_bags)."""
    raw, applied, gravity, temperature = bag.raw, bag.applied_load, bag.gravity, bag.temperature
    names = bag.topics
    if len(applied) == 0:
        raise LoadPointError(
            f'{source} has no {names.applied_load} messages: cannot tell load points apart'
        )
    if len(gravity) == 0:
        raise LoadPointError(
            f'{source} has no {names.gravity} messages: the orientation of the '
            f'calibration body is unknown'
        )
    order = np.argsort(raw.stamps_ns, kind='stable')
    stamps = raw.stamps_ns[order]
    values = np.asarray(raw.values, dtype=float)[order]

    marker_stamps = np.asarray(applied.stamps_ns)
    marker_loads = np.asarray(applied.values, dtype=float)
    # the recorder's order and the publisher's stamps must agree; points follow the stamps
    backwards = np.flatnonzero(np.diff(marker_stamps) < 0)
    by_stamp = np.argsort(marker_stamps, kind='stable')
    marker_stamps, marker_loads = marker_stamps[by_stamp], marker_loads[by_stamp]
    duplicates = int(np.count_nonzero(np.diff(marker_stamps) == 0))
    is_point = ~np.all(np.isnan(marker_loads), axis=1)
    if np.any(np.isnan(marker_loads[is_point])):
        bad = np.flatnonzero(is_point & np.any(np.isnan(marker_loads), axis=1))[0]
        raise LoadPointError(
            f'{source}: {names.applied_load} message {bad + 1} has some but not all fields NaN'
        )
    if np.any(~np.isfinite(marker_loads[is_point])):
        raise LoadPointError(f'{source}: {names.applied_load} has infinite loads')
    if config is not None:
        # no calibration weight is 1000x the rated load: a flipped exponent bit or wrong units,
        # which would overflow the fits long before the capacity gate could name it
        capacity = np.asarray(config.capacity, float)
        factor = np.abs(marker_loads) / (ABSURD_LOAD_CAPACITIES * capacity)
        absurd = np.flatnonzero(is_point & np.any(factor > 1.0, axis=1))
        if len(absurd):
            i = int(absurd[0])
            k = int(np.argmax(factor[i]))
            raise LoadPointError(
                f'{source}: {names.applied_load} message {i + 1}: '
                f'{config.components[k]} {marker_loads[i, k]:.4g} is beyond '
                f'{ABSURD_LOAD_CAPACITIES:g}x its rated load {capacity[k]:g} '
                f'({len(absurd)} such message(s)): a corrupted value or wrong '
                f'units'
            )
    point_index = np.flatnonzero(is_point)
    first_gravity = gravity.stamps_ns.min()
    if marker_stamps[point_index[0]] < first_gravity:
        order_hint = (
            f'; {len(backwards)} {names.applied_load} message(s) are stamped out of time order '
            f'(first: message {int(backwards[0]) + 2})'
            if len(backwards)
            else ''
        )
        raise LoadPointError(
            f'{source} has no {names.gravity} messages before its first load point{order_hint}'
        )

    # a point ends at the next marker, or at most POINT_PERIODS typical marker periods after its
    # own: samples beyond (a session ended without a marker, a clock jump, a recorder left
    # running over a pause) belong to no point
    periods = np.diff(marker_stamps)
    period = int(np.median(periods[periods > 0])) if np.any(periods > 0) else 10**9
    boundaries = np.append(marker_stamps, np.iinfo(np.int64).max)
    point_ends = np.minimum(
        boundaries[point_index + 1],
        marker_stamps[point_index] + min(POINT_PERIODS * period, 2**62),
    )
    starts = np.searchsorted(stamps, marker_stamps[point_index], side='left')
    ends = np.searchsorted(stamps, point_ends, side='left')
    outside = int(len(stamps) - np.sum(ends - starts))

    g_order = np.argsort(gravity.stamps_ns, kind='stable')
    g_stamps = gravity.stamps_ns[g_order]
    g_vectors = np.asarray(gravity.values, float)[g_order]
    g_at = np.searchsorted(g_stamps, marker_stamps[point_index], side='right') - 1
    point_gravity = g_vectors[g_at]
    norms = np.linalg.norm(point_gravity, axis=1)
    if np.any(np.abs(norms - 1.0) > 1e-3):
        raise LoadPointError(
            f'{source}: {names.gravity} vectors must be unit vectors (got norm {norms.min():.4g})'
        )

    if len(temperature):
        t_order = np.argsort(temperature.stamps_ns, kind='stable')
        t_stamps = temperature.stamps_ns[t_order].astype(float)
        t_values = np.asarray(temperature.values, float)[t_order]
    means = np.full((len(point_index), values.shape[1]), np.nan)
    mean_variance = np.full((len(point_index), values.shape[1]), np.nan)
    counts = np.zeros(len(point_index), dtype=int)
    times = np.full(len(point_index), np.nan)
    temps = np.full(len(point_index), np.nan)
    # no bridge gives 1000x its rated output; without a config, no amplifier gives 1e6 mV
    plausible_mv = (
        1000.0 * np.abs(config.rated_output_mv)
        if config is not None
        else np.full(values.shape[1], 1e6)
    )
    used = outliers = nans = empty = 0
    inside_values, inside_points = [], []
    # robust scale (MAD) of each point's samples per bridge; the outlier limit is k x the larger of
    # the point's own and the campaign's median one: with few samples a point's MAD alone is often
    # small by chance, and rejecting ordinary noise (5 % of the samples at 8 a point over six
    # bridges) truncates the points' scatter and biases the repeatability low. A spike is far
    # beyond either.
    # a finite but absurd output (a flipped exponent bit) is as unusable as a NaN
    usable = np.all(np.isfinite(values) & (np.abs(values) <= plausible_mv), axis=1)
    rows = [a + np.flatnonzero(usable[a:b]) for a, b in zip(starts, ends)]
    medians, scales = _medians_and_scales(values, rows)
    typical_scale = (
        np.nanmedian(scales, axis=0) if np.any(np.isfinite(scales)) else np.zeros(values.shape[1])
    )
    for p, (a, b) in enumerate(zip(starts, ends)):
        nans += int(b - a - len(rows[p]))
        block = values[rows[p]]
        block_stamps = stamps[rows[p]]
        inside_values.append(block)
        inside_points.append(np.full(len(block), p))
        if len(block) == 0:
            empty += 1
            continue
        limit = outlier_mad * np.maximum(np.fmax(scales[p], typical_scale), 1e-12)
        keep = (
            np.all(np.abs(block - medians[p]) <= limit, axis=1)
            if len(block) >= 5
            else np.ones(len(block), bool)
        )
        if not np.any(keep):  # no sample near the median of all bridges at once: keep them all
            keep = np.ones(len(block), bool)
        outliers += int(np.count_nonzero(~keep))
        used += int(np.count_nonzero(keep))
        means[p] = block[keep].mean(axis=0)
        counts[p] = int(np.count_nonzero(keep))
        if counts[p] >= 2:
            mean_variance[p] = successive_difference_variance(block[keep]) / counts[p]
        times[p] = block_stamps[keep].mean() / 1e9
        if len(temperature):
            temps[p] = float(
                np.mean(np.interp(block_stamps[keep].astype(float), t_stamps, t_values))
            )
    has_samples = ~np.isnan(times)
    if not np.any(has_samples):
        raise LoadPointError(f'{source}: no {names.raw} samples fall inside any load point')
    keep_points = has_samples
    labels = np.arange(1, len(point_index) + 1)
    session_times, pauses = shorten_pauses(times[keep_points])
    points = LoadPoints(
        labels[keep_points],
        means[keep_points],
        session_times,
        temps[keep_points],
        _orientation_index(point_gravity, config)[keep_points],
        point_gravity[keep_points],
        marker_loads[point_index][keep_points],
    )
    bridges = (
        config.bridge_outputs
        if config
        else tuple(f'output {k + 1}' for k in range(values.shape[1]))
    )
    clipped = (
        _flat_tops(np.concatenate(inside_values), np.concatenate(inside_points), bridges)
        if inside_values
        else ()
    )
    return points, CutSummary(
        int(keep_points.sum()),
        used,
        outliers,
        nans,
        empty,
        markers_out_of_order=len(backwards),
        first_marker_out_of_order=int(backwards[0] + 1) if len(backwards) else -1,
        duplicate_marker_stamps=duplicates,
        samples_outside_points=outside,
        pauses_s=pauses,
        clipped=clipped,
        point_labels=points.label.copy(),
        point_variance_mv2=mean_variance[keep_points],
        point_samples=counts[keep_points],
    )
