"""One-axis calibration of the thrust stand, lab manual §4.2: weights -> corrected readings ->
line.

Procedure as the manual runs it: with the chamber pressurised to the firing gauge pressure p_G,
hang the pan with 0, 1, ..., 5 weights (about 85 g each, weighed individually), read the strain
channel, take the pan down, and read the channel again. The leaf spring does not quite return
(hysteresis), so each loaded reading is corrected by the residual zero read just after it.
Then fit load = a · reading + b (eqs. (25)-(26)); a is the calibration constant (N per mV here,
gf per V in the manual) and b absorbs the pan and thread (footnote 13: the line need not pass
through the origin).

The fit runs through the package's general term machinery (`fit_model` with terms "1", "FXV"),
so the result is a `BalanceModel` that `balance_calibrator` can load; eq. (27) gives σ_a from
the readings' and masses' own uncertainties (`line_fit.py`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..fit.least_squares import fit_model, FitResult
from ..model.balance_model import BalanceModel
from ..model.terms import parse_terms
from ..units import STANDARD_GRAVITY_M_S2
from .line_fit import fit_line, LineFit
from .one_axis import examine_line, OneAxisExamination
from .significant import format_value_error

COMPONENT = 'FX'  # the stand measures thrust along its axis only
BRIDGE_OUTPUT = 'FXV'  # its one strain channel, mV
TERMS = ('1', BRIDGE_OUTPUT)


@dataclass(frozen=True)
class CalibrationReadings:
    """One calibration run of §4.2: n weights, n + 1 load steps (0 ... n weights on the pan).

    weight_masses_kg: (n,) the weights as weighed, in loading order (step k hangs the first k).
    loaded_mv: (n + 1,) strain reading with the pan and k weights hanging.
    unloaded_mv: (n + 1,) reading after step k's pan was taken down: the residual zero.
    """

    weight_masses_kg: np.ndarray
    loaded_mv: np.ndarray
    unloaded_mv: np.ndarray

    def __post_init__(self):
        for name in ('weight_masses_kg', 'loaded_mv', 'unloaded_mv'):
            array = np.asarray(getattr(self, name), dtype=float).ravel()
            if not np.all(np.isfinite(array)):
                raise ValueError(f'calibration readings: {name} contains NaN or infinity')
            object.__setattr__(self, name, array)
        n = self.weight_masses_kg.size
        if self.loaded_mv.size != n + 1 or self.unloaded_mv.size != n + 1:
            raise ValueError(
                f'{n} weights need {n + 1} loaded and {n + 1} unloaded readings (0 ... {n} '
                f'weights); got {self.loaded_mv.size} and {self.unloaded_mv.size}'
            )
        if n < 1 or np.any(self.weight_masses_kg <= 0):
            raise ValueError('need at least one weight, each of positive mass')

    @property
    def applied_load_n(self) -> np.ndarray:
        """(n + 1,) weight hung at each step, N, excluding pan and thread (the manual's y_i)."""
        return np.concatenate([[0.0], np.cumsum(self.weight_masses_kg)]) * STANDARD_GRAVITY_M_S2

    @property
    def corrected_mv(self) -> np.ndarray:
        """(n + 1,) loaded reading minus the residual zero after it (§4.2's hysteresis
        correction).
        """
        return self.loaded_mv - self.unloaded_mv


@dataclass(frozen=True)
class ThrustStandCalibration:
    """Result of §4.2: F_t = a · V_F (the intercept b is the pan, not part of the thrust)."""

    slope_n_per_mv: float  # a, by fit_model (= eq. (25))
    intercept_n: float  # b (= eq. (26))
    sigma_slope_n_per_mv: float  # σ_a, eq. (27), from the given reading and mass σ
    sigma_intercept_n: float
    standard_error_slope_n_per_mv: float  # σ_a from the scatter of the points about the line
    readings_mv: np.ndarray  # corrected readings, x_i
    loads_n: np.ndarray  # applied weights, y_i
    line: LineFit  # the manual's closed forms, eqs. (25)-(27)
    fit: FitResult  # the package's QR fit
    examination: OneAxisExamination | None = None  # the line's residual examined (one_axis.py)

    @property
    def model(self) -> BalanceModel:
        """Load FX [N] = b + a · FXV [mV], the `matrices.linear` of config/thrust_stand.yaml."""
        return self.fit.model

    def thrust_n(self, reading_mv):
        """F_t = a × V_F (§4.1), V_F measured from the pre-firing baseline."""
        return self.slope_n_per_mv * np.asarray(reading_mv)

    def formatted(self) -> str:
        return format_value_error(self.slope_n_per_mv, self.sigma_slope_n_per_mv, 'N/mV', 'a')

    def config_matrix(self) -> dict:
        """The `matrices: {linear: ...}` entry of a balance config for this stand."""
        return {
            'terms': list(TERMS),
            'coefficients': {COMPONENT: [self.intercept_n, self.slope_n_per_mv]},
        }


def calibrate(
    readings: CalibrationReadings,
    reading_sigma_mv: float,
    mass_sigma_kg: float,
    hysteresis_correction: bool = True,
) -> ThrustStandCalibration:
    """Fit the calibration line of §4.2.

    reading_sigma_mv: σ of one strain reading (a corrected reading is the difference of two, so
    its σ_x is √2 times this; without correction the loaded reading is used alone).
    mass_sigma_kg: σ of one weighing; step k's load sums k weighings, σ_y = g √k σ_m.
    hysteresis_correction=False fits the raw loaded readings, to show what the correction does.
    """
    if reading_sigma_mv < 0 or mass_sigma_kg < 0:
        raise ValueError('uncertainties must be >= 0')
    x = readings.corrected_mv if hysteresis_correction else readings.loaded_mv
    y = readings.applied_load_n
    steps = np.arange(y.size)
    sigma_x = np.full(y.size, reading_sigma_mv * (np.sqrt(2.0) if hysteresis_correction else 1.0))
    sigma_y = STANDARD_GRAVITY_M_S2 * np.sqrt(steps) * mass_sigma_kg
    line = fit_line(x, y, sigma_x, sigma_y)
    fit = fit_model(
        parse_terms(TERMS),
        x[:, None],
        y[:, None],
        name='thrust_stand',
        components=(COMPONENT,),
        inputs=(BRIDGE_OUTPUT,),
        on_unexcited='raise',
    )
    intercept, slope = fit.model.coefficients[0]
    return ThrustStandCalibration(
        slope_n_per_mv=float(slope),
        intercept_n=float(intercept),
        sigma_slope_n_per_mv=line.sigma_slope,
        sigma_intercept_n=line.sigma_intercept,
        standard_error_slope_n_per_mv=float(fit.standard_errors[0, 1]),
        readings_mv=x,
        loads_n=y,
        line=line,
        fit=fit,
        # loading steps only (each corrected by its own residual zero): the examination can adopt
        # terms only where the points carry them, and says when the line leaves more than σ_x, σ_y
        # allow
        examination=examine_line(x, y, np.ones(y.size), sigma_x, sigma_y),
    )
