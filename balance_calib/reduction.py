"""Load points -> corrected data: zero points (§5(4)), then calibration-body tare (§6-7).

The input is one row per load point (mean outputs, time, orientation, applied load); the output
is the 修正データ of §7.1 that the fit of §3 uses.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .config import BalanceConfig, CalibrationBody
from .model.balance_model import BalanceModel
from .tare.calibration_body import (
    BodyEstimate,
    corrected_data,
    CorrectedData,
    estimate_body,
    fit_inverse_linear,
    tare_loads,
    tare_outputs,
)
from .zero_points import subtract_zero_points, ZeroCorrection


@dataclass(frozen=True)
class LoadPoints:
    """One row per load point, as cut from a campaign (simulated or recorded)."""

    label: np.ndarray  # (P,) point numbers
    outputs_mv: np.ndarray  # (P, 6) mean bridge outputs (electrical zero included)
    times_s: np.ndarray  # (P,) mean sample time
    temperature_c: np.ndarray  # (P,) mean temperature (NaN if none)
    # (P,) orientation index (I_g, or an index of distinct gravity vectors)
    orientation: np.ndarray
    gravity: np.ndarray  # (P, 3) unit gravity vector, balance axes
    applied_loads: np.ndarray  # (P, 6) N / N·m, excluding the body weight

    @property
    def is_zero_point(self) -> np.ndarray:
        return np.all(self.applied_loads == 0.0, axis=1)

    def subset(self, mask) -> 'LoadPoints':
        return LoadPoints(*(getattr(self, f)[mask] for f in self.__dataclass_fields__))


@dataclass(frozen=True)
class Reduction:
    points: LoadPoints
    zero: ZeroCorrection
    body: CalibrationBody
    body_source: str  # 'estimated' or 'declared'
    body_estimate: BodyEstimate | None
    inverse_linear: BalanceModel  # eqs. (32)-(37)
    corrected: CorrectedData


def opposite_zero_pairs(points: LoadPoints, zeroed_reference=None):
    """Mean raw outputs of zero points per orientation, paired with the opposite orientation.

    Returns a list of (gravity, ΔV = V(g) - V(-g)) for every orientation whose opposite also has
    zero points. The electrical zero and slow drift cancel to first order in ΔV.
    """
    zero = points.is_zero_point
    pairs = []
    keys: dict[tuple[float, ...], list[np.ndarray]] = {}
    for g, v in zip(points.gravity[zero], points.outputs_mv[zero]):
        key = tuple(np.round(g, 6))
        keys.setdefault(key, []).append(v)
    for key, values in keys.items():
        opposite = tuple(np.round(-np.array(key), 6) + 0.0)
        if opposite in keys and key > opposite:
            pairs.append(
                (np.array(key), np.mean(values, axis=0) - np.mean(keys[opposite], axis=0))
            )
    return pairs


def retare_with_model(reduction: Reduction, model: BalanceModel) -> Reduction:
    """Tare outputs from the inverse of a fitted model instead of the linear eqs. (32)-(37).

    The memo's linear inverse misplaces the tare outputs by the balance's nonlinearity at the
    body's weight (about 0.007 % FS on LMC6522 F_X); one fit -> Newton inverse -> refit removes it.
    """
    from .model.inverse import outputs_for_loads

    body_outputs = outputs_for_loads(model.without_constant(), reduction.corrected.tare_loads)
    corrected = corrected_data(
        reduction.points.applied_loads,
        reduction.zero.zeroed_outputs_mv,
        reduction.corrected.tare_loads,
        body_outputs,
    )
    return Reduction(
        reduction.points,
        reduction.zero,
        reduction.body,
        reduction.body_source,
        reduction.body_estimate,
        reduction.inverse_linear,
        corrected,
    )


def reduce_points(
    points: LoadPoints,
    config: BalanceConfig,
    *,
    estimate_body_weight: bool = True,
    linear_model: BalanceModel | None = None,
) -> Reduction:
    """Zero-point subtraction, tare loads and tare outputs: the corrected data of §7.1.

    With estimate_body_weight and zero points at opposite orientations, the body's weight and CG
    come from eqs. (29)-(31) through `linear_model` (default: a first linear fit of these data);
    otherwise the declared body of the config is used. The result says which.
    """
    zero = subtract_zero_points(
        points.times_s, points.outputs_mv, points.is_zero_point, points.orientation, points.label
    )
    loaded = ~points.is_zero_point
    inverse = fit_inverse_linear(
        zero.zeroed_outputs_mv[loaded],
        points.applied_loads[loaded],
        config.components,
        config.bridge_outputs,
    )
    body, source, estimate = config.calibration_body, 'declared', None
    pairs = opposite_zero_pairs(points) if estimate_body_weight else []
    if pairs:
        if linear_model is None:
            # first linear calibration (eqs. (1)-(6)) of zeroed outputs vs applied loads
            from .fit.least_squares import fit_model
            from .model.tm663 import tm663_terms

            linear_model = fit_model(
                tm663_terms('linear', config.bridge_outputs),
                zero.zeroed_outputs_mv[loaded],
                points.applied_loads[loaded],
                name='linear',
                components=config.components,
                inputs=config.bridge_outputs,
                on_unexcited='drop',
            ).model
        estimate = estimate_body(linear_model, [g for g, _ in pairs], [d for _, d in pairs])
        body = estimate.as_body(config.calibration_body.axial_jig_weight_n)
        source = 'estimated'
    body_loads = tare_loads(body, points.gravity)
    body_outputs = tare_outputs(inverse, body_loads)
    corrected = corrected_data(
        points.applied_loads, zero.zeroed_outputs_mv, body_loads, body_outputs
    )
    return Reduction(points, zero, body, source, estimate, inverse, corrected)
