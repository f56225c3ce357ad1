"""Design of calibration points: which combined loads to add to a schedule so that a calibration
reads a run's envelope of loads best (I-optimal exchange).

The criterion is the predicted variance the calibration will have, averaged over the envelope:
with X the design rows of the schedule's points (the direct model's terms of their bridge
outputs), u_k² = σ_k² (1 + x (XᵀX)⁻¹ xᵀ) (model/uncertainty.py) and

    I = mean over envelope loads e of  x_e (XᵀX)⁻¹ x_eᵀ  = trace((XᵀX)⁻¹ W),  W = mean x_eᵀ x_e,

common to all components (σ_k only scales it). Adding a row c lowers I by
c A cᵀ / (1 + c (XᵀX)⁻¹ cᵀ), A = (XᵀX)⁻¹ W (XᵀX)⁻¹ (Sherman-Morrison): points are added
greedily, then exchanged one at a time (Fedorov) while that lowers I.

Candidates are loads the rig can apply: the envelope's loads and the same stretched by STRETCH,
each in the orientation I_g (among those the balance's schedule uses: the calibration body is
set up for them) that needs the lightest weights, where the weights to hang (total load minus the
body's own weight in that orientation, tare/calibration_body.py) and the total load are within
capacity, and the total load within the combined-loading limit ‖load / capacity‖₂ ≤
combined_limit (a stated limit, default 1.5: all six components at 61 % of capacity at once).
Added points go in blocks of at most BLOCK_POINTS of one orientation, each bracketed by zero
points in that orientation (TM-663 §5(4)).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ..config import BalanceConfig, LoadSchedule
from ..fit.svd import unscaled_covariance
from ..model.balance_model import BalanceModel
from ..model.inverse import outputs_for_loads
from ..model.leverage import leverage_of_rows
from ..model.uncertainty import load_standard_uncertainty, with_covariance
from ..tare.calibration_body import tare_loads
from ..units import STANDARD_GRAVITY_M_S2

DEFAULT_COMBINED_LIMIT = 1.5  # ‖total load / capacity‖₂ of a candidate
STRETCH = (1.0, 1.2)  # candidates: envelope loads times these
BLOCK_POINTS = 6  # loaded points between two zero points
MAX_CANDIDATES = 4000  # envelope loads beyond this are thinned evenly
EXCHANGE_PASSES = 4
ROUND_KGF = 1e-3  # weights hung to 1 gf (and 1 gf·m)


class DesignError(ValueError):
    """An envelope or request that cannot be designed for; the message says what and where."""


@dataclass(frozen=True)
class Design:
    schedule: LoadSchedule  # the balance's points, then the added blocks
    added_loads: np.ndarray  # (n_added, n) total loads of the added points, N / N·m
    predicted_before: np.ndarray  # (E, n) predicted u at the envelope, N / N·m
    predicted_after: np.ndarray  # (E, n)
    components: tuple[str, ...]
    capacity: np.ndarray
    notes: tuple[str, ...] = ()  # what the user should know (a weight set that falls short)

    def summary(self) -> dict:
        """design.json (interfaces.md)."""
        before = _rms_pct(self.predicted_before, self.capacity)
        after = _rms_pct(self.predicted_after, self.capacity)
        return {
            'added': int(len(self.added_loads)),
            'predicted_u_pct_fs': {
                'before': dict(zip(self.components, before)),
                'after': dict(zip(self.components, after)),
            },
            'worst_component': self.components[int(np.argmax(after))],
        }


def _rms_pct(u: np.ndarray, capacity: np.ndarray) -> list[float]:
    rms = np.sqrt(np.mean(u**2, axis=0)) / capacity * 100.0
    return [round(float(v), 6) for v in rms]


def check_envelope(envelope_loads, capacity, components, where: str = 'envelope') -> np.ndarray:
    """The envelope (E, n) as an array, or DesignError: empty, not finite, beyond capacity."""
    loads = np.asarray(envelope_loads, dtype=float)
    if loads.size == 0:
        raise DesignError(f'{where}: the envelope has no loads')
    loads = np.atleast_2d(loads)
    bad = np.flatnonzero(~np.all(np.isfinite(loads), axis=1))
    if bad.size:
        raise DesignError(f'{where}: row {bad[0] + 1}: loads must be finite numbers')
    over = np.abs(loads) > np.asarray(capacity, float)
    if over.any():
        row, k = np.argwhere(over)[0]
        raise DesignError(
            f'{where}: row {row + 1}: {components[k]} = {loads[row, k]:.6g} is '
            f"beyond the balance's capacity {capacity[k]:.6g} "
            f'({int(over.any(axis=1).sum())} of {len(loads)} loads are)'
        )
    return loads


def schedule_total_loads(config: BalanceConfig, schedule: LoadSchedule) -> np.ndarray:
    """(P, n) loads on the balance at each point: applied + the body's weight, N / N·m."""
    gravity = np.array([config.gravity(i) for i in schedule.orientation])
    return np.asarray(schedule.loads, float) + tare_loads(config.calibration_body, gravity)


def _schedule(config: BalanceConfig) -> LoadSchedule:
    """The config's load schedule; DesignError naming the config if it has none."""
    if config.schedule is None:
        raise DesignError(f'{config.path or config.name}: the balance config has no load schedule')
    return config.schedule


def rig_loading(
    config: BalanceConfig, total_loads, combined_limit: float = DEFAULT_COMBINED_LIMIT
):
    """How the rig applies each total load (C, n), N / N·m: (feasible (C,) bool, orientation (C,)
    I_g, applied (C, n) the weights to hang). The orientation is, among those the schedule uses,
    the one needing the lightest weights (largest fraction of capacity); feasible when those and
    the total load are within capacity and ‖total / capacity‖₂ ≤ combined_limit.
    """
    loads = np.atleast_2d(np.asarray(total_loads, dtype=float))
    capacity = np.asarray(config.capacity, float)
    orientations = np.array(
        sorted({int(i) for i in _schedule(config).orientation} & set(config.gravity_directions))
    )
    applied = np.stack(
        [loads - tare_loads(config.calibration_body, config.gravity(i)) for i in orientations]
    )  # (O, C, n)
    fraction = np.max(np.abs(applied) / capacity, axis=2)  # (O, C)
    best = np.argmin(fraction, axis=0)
    rows = np.arange(len(loads))
    feasible = (
        (fraction[best, rows] <= 1.0)
        & np.all(np.abs(loads) <= capacity, axis=1)
        & (np.linalg.norm(loads / capacity, axis=1) <= combined_limit)
    )
    return feasible, orientations[best], applied[best, rows]


def schedule_with(
    config: BalanceConfig,
    total_loads,
    combined_limit: float = DEFAULT_COMBINED_LIMIT,
    weight_set=None,
) -> LoadSchedule:
    """The balance's schedule with these total loads (A, n) added as rig_loading applies them
    (weights rounded to ROUND_KGF, or with weight_set = (masses kg, counts) to the loads that set
    makes, coverage/weight_set.py), in blocks of one orientation bracketed by zero points,
    numbered after the last point. DesignError if one of them cannot be applied.
    """
    feasible, orientations, applied = rig_loading(config, total_loads, combined_limit)
    if not feasible.all():
        raise DesignError(
            f'load {int(np.flatnonzero(~feasible)[0]) + 1} to add cannot be applied '
            f'within capacity and the combined-loading limit {combined_limit}'
        )
    if weight_set is not None:
        from .weight_set import round_to_weight_set, WeightSetError

        try:
            hung, _ = round_to_weight_set(applied, config, *weight_set)
        except WeightSetError as err:
            raise DesignError(str(err)) from None
    else:
        step = ROUND_KGF * STANDARD_GRAVITY_M_S2
        hung = np.round(applied / step) * step
    base = _schedule(config)
    number = int(np.max(base.point)) + 1
    points, orientation_rows, load_rows = [], [], []
    zero = np.zeros(hung.shape[1])
    for i_g in sorted({int(o) for o in orientations}):
        rows = hung[orientations == i_g]
        for start in range(0, len(rows), BLOCK_POINTS):
            for loads in [zero] + list(rows[start : start + BLOCK_POINTS]) + [zero]:
                points.append(number)
                orientation_rows.append(i_g)
                load_rows.append(loads)
                number += 1
    added = [np.array(load_rows)] if load_rows else []
    return LoadSchedule(
        np.concatenate([base.point, points]).astype(int),
        np.concatenate([base.orientation, orientation_rows]).astype(int),
        np.vstack([base.loads] + added),
        tuple(base.byproduct) + ('',) * len(points),
    )


def _exchange(
    candidate_rows: np.ndarray, base_inverse: np.ndarray, weight: np.ndarray, count: int
) -> list[int]:
    """Indices of at most `count` candidate rows (C, p) that minimise trace(M⁻¹ W), M = X₀ᵀX₀ +
    Σ cᵀc: greedy, then Fedorov exchange; base_inverse = (X₀ᵀX₀)⁻¹ and weight = W (p, p).
    """

    def gains(inverse):
        # c A cᵀ / (1 + h), h = c M⁻¹ cᵀ the candidate's leverage in the design so far
        a = inverse @ weight @ inverse
        return np.einsum('ij,jk,ik->i', candidate_rows, a, candidate_rows) / (
            1.0 + leverage_of_rows(candidate_rows, inverse)
        )

    def add(inverse, row):
        v = inverse @ row
        return inverse - np.outer(v, v) / (1.0 + row @ v)

    def remove(inverse, row):
        v = inverse @ row
        return inverse + np.outer(v, v) / (1.0 - row @ v)

    inverse = base_inverse.copy()
    chosen: list[int] = []
    for _ in range(count):
        gain = gains(inverse)
        gain[chosen] = -np.inf
        best = int(np.argmax(gain))
        if not gain[best] > 0:
            break
        chosen.append(best)
        inverse = add(inverse, candidate_rows[best])
    for _ in range(EXCHANGE_PASSES):
        changed = False
        for position in range(len(chosen)):
            without = remove(inverse, candidate_rows[chosen[position]])
            gain = gains(without)
            gain[[c for i, c in enumerate(chosen) if i != position]] = -np.inf
            best = int(np.argmax(gain))
            if best != chosen[position] and gain[best] > gain[chosen[position]] * (1 + 1e-9):
                chosen[position], changed = best, True
            inverse = add(without, candidate_rows[chosen[position]])
        if not changed:
            break
    return chosen


def _rows(model: BalanceModel, total_loads: np.ndarray) -> np.ndarray:
    """Design rows (N, p) of the direct model at the outputs that give these total loads."""
    return model.design(outputs_for_loads(model.without_constant(), total_loads))


def design_points(
    config: BalanceConfig,
    envelope_loads,
    points: int,
    *,
    model: BalanceModel | None = None,
    sigma=None,
    combined_limit: float = DEFAULT_COMBINED_LIMIT,
    where: str = 'envelope',
    weight_set=None,
) -> Design:
    """Add at most `points` combined load points to the balance's schedule for this envelope.

    Parameters
    ----------
    config : the balance (schedule, capacity, calibration body, gravity directions).
    envelope_loads : (E, n) loads of the run to be measured, N and N·m, balance axes.
    points : how many loaded points may be added (zero points come on top), ≥ 1.
    model : the direct model whose terms the calibration fits (default the config's cubic
        matrix): it maps loads to the bridge outputs the design rows are made of.
    sigma : (n,) the residual σ the calibration reaches, N / N·m (default Table 17's cubic row).
    combined_limit : the rig's combined-loading limit, ‖total load / capacity‖₂.
    weight_set : (masses kg, counts) of the rig's weights: the added points are rounded to the
        loads they make (coverage/weight_set.py); default: to ROUND_KGF.

    Returns
    -------
    Design, whose predicted u before and after are computed as the live node does
    (model/uncertainty.py) for a calibration on the schedule's points with this σ.
    """
    if not isinstance(points, (int, np.integer)) or points < 1:
        raise DesignError(f'--points {points}: add at least 1 point')
    _schedule(config)  # DesignError without one
    if not combined_limit > 0:
        raise DesignError(f'combined-loading limit {combined_limit}: must be positive')
    capacity = np.asarray(config.capacity, float)
    envelope = check_envelope(envelope_loads, capacity, config.components, where)
    model = model or config.matrices['cubic']
    if model.extra_variables:
        raise DesignError(
            f'model {model.name} needs {", ".join(model.extra_variables)} besides '
            f'the outputs; design for its base model'
        )
    if sigma is None:
        row = config.table17_sigma_pct_fs.get('cubic', {})
        sigma = np.array([float(row.get(c, 0.0)) for c in config.components]) * capacity / 100.0
    sigma = np.asarray(sigma, float)

    thinned = envelope
    if len(thinned) > MAX_CANDIDATES // len(STRETCH):
        keep = np.linspace(0, len(thinned) - 1, MAX_CANDIDATES // len(STRETCH)).astype(int)
        thinned = thinned[keep]
    candidates = np.vstack([thinned * s for s in STRETCH])
    candidates = candidates[rig_loading(config, candidates, combined_limit)[0]]
    if len(candidates) == 0:
        raise DesignError(
            f'{where}: no load of the envelope can be applied by the rig within '
            f'capacity and the combined-loading limit {combined_limit}'
        )
    base_rows = _rows(model, schedule_total_loads(config, _schedule(config)))
    envelope_rows = _rows(model, envelope)
    scales = np.linalg.norm(base_rows, axis=0)
    scales[scales == 0] = 1.0
    base_inverse, _ = unscaled_covariance(base_rows / scales)
    weight = (envelope_rows / scales).T @ (envelope_rows / scales) / len(envelope_rows)
    chosen = _exchange(_rows(model, candidates) / scales, base_inverse, weight, int(points))

    schedule = schedule_with(config, candidates[chosen], combined_limit, weight_set)
    notes: list[str] = []
    if weight_set is not None:
        from .weight_set import round_to_weight_set

        applied = rig_loading(config, candidates[chosen], combined_limit)[2]
        notes = round_to_weight_set(applied, config, *weight_set)[1]
    base_points = len(_schedule(config))
    total = schedule_total_loads(config, schedule)
    loaded = ~np.all(schedule.loads[base_points:] == 0.0, axis=1)
    before = predicted_uncertainty(model, base_rows, sigma, envelope)
    after = predicted_uncertainty(model, _rows(model, total), sigma, envelope)
    return Design(
        schedule,
        total[base_points:][loaded],
        before,
        after,
        tuple(config.components),
        capacity,
        tuple(notes),
    )


def predicted_uncertainty(model: BalanceModel, point_rows: np.ndarray, sigma, loads) -> np.ndarray:
    """(E, n) u (k = 1) at loads (E, n) of a calibration fitted on points with design rows
    (P, p) and residual σ (n,), N / N·m: the live node's computation (model/uncertainty.py).
    """
    covariance, rank = unscaled_covariance(point_rows)
    fitted = with_covariance(model, covariance, sigma, max(len(point_rows) - rank, 1))
    return load_standard_uncertainty(fitted, outputs_for_loads(model.without_constant(), loads))


def sigma_of(model: BalanceModel) -> np.ndarray | None:
    """The residual σ (n,) a fitted model records, N / N·m, or None."""
    meta: Mapping = (model.metadata or {}).get('uncertainty') or {}
    return None if 'residual_sigma' not in meta else np.asarray(meta['residual_sigma'], float)
