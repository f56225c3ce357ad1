"""Validation of a table calibration on points it was not fitted to.

A validation series the calibration has is the same setup: the calibration's tare is applied,
never re-estimated. A series it lacks is another setup (another fixture orientation): its tare is
estimated from its own points with the model held fixed, T_s = mean over its points of (model
total load − applied load), standard error = the scatter of those differences / sqrt(n_s), and its
points' uncertainty gains that tare's variance. The validation σ of such a series cannot see a
wrong tare (it absorbed it): reported apart, as `validation_series_tares`.

Warnings: validation loads beyond the calibrated range (per component and sign, with the factor),
a sign the calibration never applied, and a coverage of ±1.96 u below 90 %.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import cast, Mapping

import numpy as np

from ..fit.iterative import iterative_point_uncertainty
from ..fit.series_tares import (
    direct_point_uncertainty,
    SeriesTareFit,
    tares_with_model_fixed,
)
from ..model.inverse import InverseDidNotConverge
from ..model.leverage import leverage_of_rows
from .errors import TableCalibrationError

COVERAGE_WARNING = 0.90
RANGE_TOLERANCE = 1.01  # validation beyond 1 % over the calibrated maximum: extrapolation
SIGN_FRACTION = 0.01  # a sign is calibrated when loads reach 1 % of capacity in it


@dataclass(frozen=True)
class FormValidation:
    residuals: np.ndarray  # (N_val, n_loads) applied - predicted, SI
    uncertainty: np.ndarray  # (N_val, n_loads) k = 1, SI
    own_tares: Mapping[int, np.ndarray] = field(default_factory=dict)  # SI
    own_tare_sigma: Mapping[int, np.ndarray] = field(default_factory=dict)  # SI

    @property
    def coverage(self) -> float:
        """Fraction of validation point loads within ±1.96 u."""
        return float(np.mean(np.abs(self.residuals) <= 1.96 * self.uncertainty))


def validate_form(
    method: str, fit: SeriesTareFit, validation, outputs: np.ndarray
) -> FormValidation:
    """Predict the validation points with one fitted form: its tares where it has the series, the
    series' own tares (model fixed) where not.
    """
    try:
        totals = np.atleast_2d(fit.model.loads(outputs))
    except InverseDidNotConverge as err:
        raise TableCalibrationError(f'{validation.source}: {err}') from None
    series = np.asarray(validation.series, int)
    known = np.isin(series, fit.series_labels)
    applied = validation.applied_loads_si
    tares = np.zeros_like(totals)
    own: dict[int, np.ndarray] = {}
    own_sigma: dict[int, np.ndarray] = {}
    if np.any(known):
        tares[known] = fit.tare_rows(series[known])
    if np.any(~known):
        tares[~known], own, own_sigma = tares_with_model_fixed(
            totals[~known], applied[~known], series[~known]
        )
    residuals = applied - (totals - tares)
    # uncertainty: the calibration's series rows where known; a zero series row (the model alone)
    # plus the own tare's variance where not
    proxy = np.where(known, series, fit.series_labels[0])
    point_u = direct_point_uncertainty if method == 'direct' else iterative_point_uncertainty
    u = point_u(fit, outputs, proxy)
    if np.any(~known):
        model_only = _model_only_uncertainty(method, fit, outputs[~known])
        tare_var = np.array([own_sigma[int(s)] for s in series[~known]]) ** 2
        u[~known] = np.sqrt(model_only**2 + np.nan_to_num(tare_var))
    return FormValidation(residuals, u, own, own_sigma)


def _model_only_uncertainty(method: str, fit: SeriesTareFit, outputs: np.ndarray) -> np.ndarray:
    """K = 1 uncertainty of a predicted total load without any series tare (zero series row)."""
    p = len(fit.model.terms)
    covariance = cast(np.ndarray, fit.full_covariance_unscaled)[:p, :p]  # a table fit has it
    if method == 'direct':
        z = fit.model.design(outputs)
        h = leverage_of_rows(z, covariance)
        return fit.residual_sigma[None, :] * np.sqrt(1.0 + h)[:, None]
    totals = fit.model.loads(outputs)
    _, jacobian = fit.model.output_jacobian(totals)
    z = fit.model.design(totals)
    h = leverage_of_rows(z, covariance)
    inverse = np.linalg.inv(jacobian)
    variance = fit.residual_sigma[None, :] ** 2 * (1.0 + h)[:, None]
    return np.sqrt(np.einsum('nmk,nk->nm', inverse**2, variance))


def range_warnings(table, validation) -> list[str]:
    """Per component and sign: validation loads beyond the calibrated ones (factor), or in a sign
    the calibration never applied.
    """
    warnings = []
    cal, val = table.applied_loads_si, validation.applied_loads_si
    capacity = table.load_capacity_si
    for k, symbol in enumerate(table.load_symbols):
        for sign, word in ((1.0, 'positive'), (-1.0, 'negative')):
            cal_max = float(np.max(sign * cal[:, k], initial=0.0))
            val_max = float(np.max(sign * val[:, k], initial=0.0))
            if val_max <= SIGN_FRACTION * capacity[k]:
                continue
            if cal_max <= SIGN_FRACTION * capacity[k]:
                warnings.append(
                    f'validation applies {symbol} {word} (up to '
                    f'{100 * val_max / capacity[k]:.0f} % of capacity), a sign the '
                    f'calibration never applied: its σ there is an extrapolation'
                )
            elif val_max > RANGE_TOLERANCE * cal_max:
                warnings.append(
                    f'validation loads {symbol} {word} to {val_max / cal_max:.2f}x '
                    f'the calibrated {100 * cal_max / capacity[k]:.0f} % of capacity: '
                    f'its σ there is an extrapolation'
                )
    return warnings


def coverage_warning(coverage: float, method: str) -> list[str]:
    if coverage < COVERAGE_WARNING:
        return [
            f'only {100 * coverage:.1f} % of the validation loads lie within ±1.96 u of the '
            f'{method} model (95 % expected, < {100 * COVERAGE_WARNING:.0f} % warned): the '
            f'stated uncertainty is too small for these points (extrapolation, another setup, '
            f'or an effect the model lacks)'
        ]
    return []
