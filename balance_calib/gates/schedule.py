"""The `schedule` gate (interfaces.md; `refit --schedule`): the load points found against the
schedule the campaign ran (TM-663 Appendix A/B, or a schedule file), in count and coverage.
"""

from __future__ import annotations

import numpy as np

from ..config import BalanceConfig, LoadSchedule
from .gate import Gate
from .limits import acceptance_limits, AcceptanceLimits

SCHEDULE_MATCH_PCT_FS = 0.5  # a found point is a scheduled one: every load this close


def match_schedule(
    applied_loads: np.ndarray,
    orientation: np.ndarray,
    schedule: LoadSchedule,
    tolerance: np.ndarray,
) -> np.ndarray:
    """Which schedule row each found load point is, or -1 for a point the schedule does not have.

    Parameters
    ----------
    applied_loads : (P, n) N, N·m, the points' applied loads (body weight excluded).
    orientation : (P,) I_g of each point.
    schedule : the schedule's N rows, loads in the same components and units.
    tolerance : (n,) N, N·m: a point is a row when every load is this close.

    Returns
    -------
    (P,) int: each schedule row is taken by one point at most (the first in the points' order),
    a row of the point's own I_g before a row of another (a schedule repeats loads at each I_g).
    """
    found = np.asarray(applied_loads, float)
    rows = np.asarray(schedule.loads, float)
    close = np.all(np.abs(found[:, None, :] - rows[None, :, :]) <= tolerance, axis=2)  # (P, N)
    same_ig = np.asarray(orientation)[:, None] == np.asarray(schedule.orientation)[None, :]
    taken = np.zeros(len(rows), bool)
    match = np.full(len(found), -1)
    for p in np.flatnonzero(close.any(axis=1)):
        for candidates in (close[p] & same_ig[p] & ~taken, close[p] & ~taken):
            if candidates.any():
                match[p] = int(np.argmax(candidates))
                taken[match[p]] = True
                break
    return match


def schedule_gate(
    config: BalanceConfig,
    points,
    schedule: LoadSchedule | None,
    limits: AcceptanceLimits | None = None,
) -> Gate:
    """The load points found against the schedule the campaign ran: count and coverage.

    A campaign that lost a share of its points (applied_load markers dropped, a session or a
    bag missing) still fits, but its calibration rests on fewer points than the schedule was
    designed with, and a component may have lost the loads that determine its terms. Refused when
    more than `missing_points_share` of the schedule's points are missing, or more than
    `missing_component_share` of the points loading one component (in either direction).

    points: LoadPoints (P,); schedule: LoadSchedule (N,) in the config's components, or None.
    """
    limits = limits or acceptance_limits(config)
    if schedule is None or len(schedule) == 0:
        return Gate('schedule', True, 'no load schedule to compare the points with')
    capacity = np.asarray(config.capacity, float)
    tolerance = SCHEDULE_MATCH_PCT_FS / 100.0 * capacity
    match = match_schedule(points.applied_loads, points.orientation, schedule, tolerance)
    expected = len(schedule)
    found = np.zeros(expected, bool)
    found[match[match >= 0]] = True
    missing = expected - int(found.sum())
    extra = int(np.count_nonzero(match < 0))
    share = missing / expected
    rows = np.asarray(schedule.loads, float)
    coverage, lost = {}, []
    for k, component in enumerate(config.components):
        entry = {}
        for sign, side in ((1.0, '+'), (-1.0, '-')):
            loading = sign * rows[:, k] > tolerance[k]
            if loading.any():
                entry[side] = [
                    int(np.count_nonzero(found & loading)),
                    int(np.count_nonzero(loading)),
                ]
        if not entry:
            continue
        got = sum(e[0] for e in entry.values())
        of = sum(e[1] for e in entry.values())
        coverage[component] = {'found': got, 'expected': of, **entry}
        short = [side for side, (g, n) in entry.items() if g == 0]
        if (of - got) / of > limits.missing_component_share or short:
            none = f' (none {component}{short[0]})' if short else ''
            lost.append(f'{component} {got} of {of}{none}')
    details = {
        'expected': expected,
        'found': expected - missing,
        'missing': missing,
        'not_in_schedule': extra,
        'missing_share': share,
        'coverage': coverage,
        'limit_share': limits.missing_points_share,
        'limit_component_share': limits.missing_component_share,
        'missing_points': [int(p) for p in np.asarray(schedule.point)[~found][:50]],
    }
    counts = (
        f'{expected - missing} of the {expected} scheduled points found ({missing} missing, '
        f'{100 * share:.0f} %'
    )
    unknown = f'; {extra} point(s) not in the schedule' if extra else ''
    if share > limits.missing_points_share or lost:
        hint = (
            '; a campaign of another schedule (--schedule FILE)?'
            if extra > missing / 2
            else '; applied_load markers or a session lost?'
        )
        coverage_text = '; lost coverage: ' + ', '.join(lost) if lost else ''
        return Gate(
            'schedule',
            False,
            f'{counts}, limit {100 * limits.missing_points_share:g} %)'
            f'{coverage_text}{unknown}{hint}',
            details,
        )
    return Gate(
        'schedule',
        True,
        f'{counts}, within {100 * limits.missing_points_share:g} %; '
        f'every component covered){unknown}',
        details,
    )
