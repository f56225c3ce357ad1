"""The straight line y = a x + b of the lab manual's Supplement 2, eqs. (25)-(27), written out.

The manual fits the weights y_i (gf) against the strain-meter readings x_i (V); any consistent
units work (this package uses N against mV). The general, QR-based machinery of the package
(`balance_calib.fit.least_squares.fit_model`) gives the same a and b; this module keeps the
manual's closed forms so a student can check each number, and its σ_a, eq. (27), which
propagates the *measurement* uncertainties σ_x, σ_y of every point rather than estimating σ_y
from the scatter.

Eq. (27) as printed, re-derived from eq. (25) with D = n Σx² - (Σx)², N = n Σxy - Σx Σy:
    ∂a/∂y_i = (n x_i - Σx) / D
    ∂a/∂x_i = (n y_i - Σy) / D - N ∂D/∂x_i / D² = (n y_i - Σy)/D - 2 (n x_i - Σx) N / D²
which is what the manual prints (∂D/∂x_i = 2 (n x_i - Σx) gives the factor 2); no correction
was needed. test_thrust_line_fit checks these against finite differences of eq. (25).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LineSums:
    """The sums of the manual's worksheet (Supplement 2)."""

    n: int
    sum_x: float
    sum_y: float
    sum_xy: float
    sum_xx: float

    @property
    def denominator(self) -> float:
        return self.n * self.sum_xx - self.sum_x**2  # D of eqs. (25)-(27)


@dataclass(frozen=True)
class LineFit:
    """y = slope x + intercept, with uncertainties. Units: slope [y]/[x], intercept [y]."""

    slope: float  # a, eq. (25)
    intercept: float  # b, eq. (26)
    sigma_slope: float  # σ_a, eq. (27)
    sigma_intercept: float  # σ_b, the same propagation applied to b
    n: int
    residual_std: float  # sqrt(Σ r² / (n - 2)); NaN for n = 2
    sigma_source: str  # 'eq27' (given σ_x, σ_y) or 'residuals' (σ_y = residual_std, σ_x = 0)
    sums: LineSums


def line_sums(x, y) -> LineSums:
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    return LineSums(
        int(x.size), float(x.sum()), float(y.sum()), float((x * y).sum()), float((x * x).sum())
    )


def slope_and_intercept(sums: LineSums) -> tuple[float, float]:
    """A and b from the worksheet sums, eqs. (25) and (26)."""
    d = sums.denominator
    a = (sums.n * sums.sum_xy - sums.sum_x * sums.sum_y) / d  # lab manual eq. (25)
    b = (sums.sum_xx * sums.sum_y - sums.sum_x * sums.sum_xy) / d  # lab manual eq. (26)
    return a, b


def slope_partials(x, y) -> tuple[np.ndarray, np.ndarray]:
    """(∂a/∂x_i, ∂a/∂y_i), each (n,), the derivative terms of eq. (27)."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    s = line_sums(x, y)
    d = s.denominator
    numerator = s.n * s.sum_xy - s.sum_x * s.sum_y
    # lab manual eq. (27)
    da_dx = (s.n * y - s.sum_y) / d - 2.0 * (s.n * x - s.sum_x) * numerator / d**2
    da_dy = (s.n * x - s.sum_x) / d  # lab manual eq. (27)
    return da_dx, da_dy


def fit_line(x, y, sigma_x=None, sigma_y=None) -> LineFit:
    """Least-squares line through (x_i, y_i), eqs. (25)-(27).

    sigma_x, sigma_y: per-point standard deviations (scalars broadcast). If both are None, σ_y
    is estimated from the residuals (needs n >= 3) and σ_x taken as 0; eq. (27) then reduces to
    the textbook standard error of the slope, s / sqrt(Σ(x - x̄)²).
    """
    x = np.asarray(x, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    if x.shape != y.shape:
        raise ValueError(f'{x.size} x values but {y.size} y values')
    if x.size < 2:
        raise ValueError(f'a line needs at least 2 points, got {x.size}')
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ValueError('x and y must be finite numbers')
    # Eqs. (25)-(27) are invariant to shifting x and y; evaluating them about the means avoids
    # the cancellation in n Σx² - (Σx)² when the readings carry a large offset.
    x_mean, y_mean = float(x.mean()), float(y.mean())
    xc, yc = x - x_mean, y - y_mean
    sums_c = line_sums(xc, yc)
    if np.ptp(x) <= 4.0 * np.finfo(float).eps * float(np.max(np.abs(x))):
        raise ValueError('all x values are equal: the slope is undetermined')
    slope, intercept_c = slope_and_intercept(sums_c)
    intercept = intercept_c + y_mean - slope * x_mean
    residuals = y - (slope * x + intercept)
    dof = x.size - 2
    residual_std = float(np.sqrt(np.sum(residuals**2) / dof)) if dof > 0 else float('nan')

    if sigma_x is None and sigma_y is None:
        if dof <= 0:
            raise ValueError(
                'with 2 points and no σ_x, σ_y the uncertainty of the slope is undetermined'
            )
        sigma_source = 'residuals'
        sx, sy = np.zeros_like(x), np.full_like(y, residual_std)
    else:
        sigma_source = 'eq27'
        sx = np.broadcast_to(np.asarray(0.0 if sigma_x is None else sigma_x, dtype=float), x.shape)
        sy = np.broadcast_to(np.asarray(0.0 if sigma_y is None else sigma_y, dtype=float), y.shape)
        if (
            np.any(sx < 0)
            or np.any(sy < 0)
            or not (np.all(np.isfinite(sx)) and np.all(np.isfinite(sy)))
        ):
            raise ValueError('σ_x and σ_y must be finite and >= 0')

    da_dx, da_dy = slope_partials(xc, yc)
    # lab manual eq. (27)
    sigma_slope = float(np.sqrt(np.sum((da_dx * sx) ** 2) + np.sum((da_dy * sy) ** 2)))
    # b = ȳ - a x̄, so ∂b/∂x_i = -a/n - x̄ ∂a/∂x_i and ∂b/∂y_i = 1/n - x̄ ∂a/∂y_i (eq. (20) again)
    db_dx = -slope / x.size - x_mean * da_dx
    db_dy = 1.0 / x.size - x_mean * da_dy
    sigma_intercept = float(np.sqrt(np.sum((db_dx * sx) ** 2) + np.sum((db_dy * sy) ** 2)))
    return LineFit(
        float(slope),
        float(intercept),
        sigma_slope,
        sigma_intercept,
        int(x.size),
        residual_std,
        sigma_source,
        line_sums(x, y),
    )
