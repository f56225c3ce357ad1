"""Gates on a bag campaign's load points, body and markers.

interfaces.md gates `zero_points`, `body_weight`, `capacity`, `marker_order`:

    zero_points   consecutive zero points of one block agree (TM-663 §5(4)): a block whose zero
                  points differ by the body's weight turned is two orientations under one
                  /calibration/gravity message (one lost or never sent)
    body_weight   calibration body weight positive and near its declaration (TM-663 §5(5))
    capacity      applied loads within the rated loads
    marker_order  applied_load stamps in the order they were recorded
"""

from __future__ import annotations

import numpy as np

from ..model.inverse import linear_part
from .gate import Gate


def zero_gate(config, points, limits) -> Gate:
    # consecutive zero points (in time) of one block: a maximal run of one orientation, as §5(4)
    order = np.argsort(points.times_s, kind='stable')
    orientation = np.asarray(points.orientation)[order]
    block = np.concatenate([[0], np.cumsum(orientation[1:] != orientation[:-1])])
    is_zero = points.is_zero_point[order]
    zeros, zero_blocks = order[is_zero], block[is_zero]
    same = zero_blocks[1:] == zero_blocks[:-1]
    pairs = list(zip(zeros[:-1][same].tolist(), zeros[1:][same].tolist()))
    details = {'limit_pct_fs': limits.zero_shift_pct_fs, 'pairs': len(pairs)}
    if not pairs:
        return Gate('zero_points', True, 'no block with two zero points to compare', details)
    before, after = np.array(pairs).T
    change_mv = points.outputs_mv[after] - points.outputs_mv[before]
    if 'linear' in config.matrices:
        change = change_mv @ linear_part(config.matrices['linear']).T
    else:
        change = change_mv * (config.capacity / config.rated_output_mv)
    change_pct = np.abs(change) / config.capacity * 100.0
    # noisy zero points differ more: the limit grows with their robust scatter (a turned body is
    # one pair far beyond the others, which leaves the median alone)
    scatter = (
        np.median(change_pct, axis=0) / 0.6745
        if len(change_pct) >= 5
        else np.zeros(change_pct.shape[1])
    )
    limit = np.maximum(limits.zero_shift_pct_fs, limits.outlier_robust_sigmas * scatter)
    ratio = np.nan_to_num(change_pct / limit, nan=np.inf)
    worst = np.unravel_index(int(np.argmax(ratio)), change_pct.shape)
    details['largest_pct_fs'] = float(change_pct[worst])
    details['limit_pct_fs'] = dict(zip(config.components, limit))
    if not change_pct[worst] <= limit[worst[1]]:
        b, a = before[worst[0]], after[worst[0]]
        return Gate(
            'zero_points',
            False,
            f'zero points {int(points.label[b])} and {int(points.label[a])} '
            f'(I_g {int(points.orientation[b])}) differ by {change_pct[worst]:.3g} % FS '
            f'in {config.components[worst[1]]}: the body was turned between them '
            f'without a /calibration/gravity message?',
            details,
        )
    return Gate(
        'zero_points',
        True,
        f'consecutive zero points of each block agree within {change_pct[worst]:.3g} % FS '
        f'({config.components[worst[1]]})',
        details,
    )


def body_gate(config, reduction, limits) -> Gate:
    weight = float(reduction.body.weight_n)
    declared = float(config.calibration_body.weight_n)
    details = {
        'weight_n': weight,
        'declared_n': declared,
        'source': reduction.body_source,
        'tolerance': limits.body_weight_tolerance,
    }
    if not declared > 0:
        return Gate(
            'body_weight',
            False,
            f'declared calibration body weight {declared:g} N is not positive '
            f'({config.path or config.name}: calibration_body.weight_n)',
            details,
        )
    if not weight > 0:
        return Gate(
            'body_weight',
            False,
            f'calibration body weight {weight:.4g} N ({reduction.body_source}) '
            f'is not positive: gravity vectors or output signs reversed?',
            details,
        )
    off = weight / declared - 1.0
    if not abs(off) <= limits.body_weight_tolerance:
        return Gate(
            'body_weight',
            False,
            f'calibration body weight {weight:.4g} N ({reduction.body_source}) is '
            f'{100 * off:+.1f} % from the declared {declared:.4g} N '
            f'(limit ±{100 * limits.body_weight_tolerance:g} %)',
            details,
        )
    return Gate(
        'body_weight',
        True,
        f'body {weight:.2f} N ({reduction.body_source}), {100 * off:+.2f} % '
        f'from the declared {declared:.2f} N',
        details,
    )


def capacity_gate(config, points, limits) -> Gate:
    fraction = np.abs(points.applied_loads) / config.capacity
    worst = np.unravel_index(int(np.argmax(fraction)), fraction.shape)
    details = {
        'max_fraction_of_capacity': dict(zip(config.components, fraction.max(axis=0))),
        'margin': limits.capacity_margin,
    }
    if not fraction[worst] <= 1.0 + limits.capacity_margin:
        count = int(np.count_nonzero(np.any(fraction > 1.0 + limits.capacity_margin, axis=1)))
        return Gate(
            'capacity',
            False,
            f'point {int(points.label[worst[0]])}: applied {config.components[worst[1]]} '
            f'{points.applied_loads[worst]:.4g} is {100 * fraction[worst]:.0f} % of '
            f'capacity ({count} point(s) beyond {100 * (1 + limits.capacity_margin):g} %; '
            f'wrong units or wrong --balance?)',
            details,
        )
    return Gate(
        'capacity',
        True,
        f'applied loads within capacity (largest {100 * fraction[worst]:.1f} %, '
        f'{config.components[worst[1]]})',
        details,
    )


def marker_gate(cut) -> Gate:
    details = {
        'out_of_order': cut.markers_out_of_order,
        'duplicate_stamps': cut.duplicate_marker_stamps,
    }
    if cut.markers_out_of_order:
        return Gate(
            'marker_order',
            False,
            f'applied_load message {cut.first_marker_out_of_order + 1} is stamped '
            f'before the one recorded ahead of it ({cut.markers_out_of_order} '
            f'marker(s) out of time order): points cannot be trusted',
            details,
        )
    return Gate('marker_order', True, 'applied_load markers in time order', details)
