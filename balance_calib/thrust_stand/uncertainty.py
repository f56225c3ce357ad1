"""Error propagation of the lab manual's Supplement 1, §A1.4, and the measured C_F of §4.1.

Every measured input x_i with uncertainty Δx_i contributes |∂f/∂x_i| Δx_i to the result
(eq. (18)). We report the three ways the manual combines them:
- `sigma`: root-sum-square, eq. (20), when the Δx_i are independent standard deviations;
- `worst_case`: sum of absolute values, eq. (19), for rounding errors or a safe bound;
- `dominant`: the largest single contribution, eq. (21), and which input gives it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np

from .nozzle import circle_area_m2

# names of the inputs of the measured thrust coefficient, in the order the manual lists them
CF_INPUTS = (
    'calibration_slope',
    'thrust_reading',
    'chamber_gauge_pa',
    'ambient_pa',
    'throat_diameter_m',
)


@dataclass(frozen=True)
class PropagatedUncertainty:
    """A derived value with its propagated uncertainty (same units as the value)."""

    value: float
    sigma: float  # eq. (20)
    worst_case: float  # eq. (19)
    dominant: float  # eq. (21)
    dominant_input: str
    contributions: Mapping[str, float]  # |∂f/∂x_i| Δx_i per input, the terms of eq. (18)
    partials: Mapping[str, float]  # ∂f/∂x_i

    @property
    def relative_sigma(self) -> float:
        return self.sigma / abs(self.value) if self.value else float('inf')


def propagate(
    value: float, partials: Mapping[str, float], sigmas: Mapping[str, float]
) -> PropagatedUncertainty:
    """Combine ∂f/∂x_i and Δx_i by eqs. (19), (20) and (21). Inputs missing from `sigmas` are
    exact.
    """
    unknown = sorted(set(sigmas) - set(partials))
    if unknown:
        raise KeyError(f'uncertainty given for unknown input(s) {", ".join(unknown)}')
    contributions = {
        name: abs(float(partials[name]) * float(sigmas.get(name, 0.0))) for name in partials
    }
    terms = np.array(list(contributions.values()))
    dominant_input = (
        max(contributions, key=lambda name: contributions[name]) if contributions else ''
    )
    return PropagatedUncertainty(
        value=float(value),
        sigma=float(np.sqrt(np.sum(terms**2))),  # lab manual eq. (20)
        worst_case=float(np.sum(terms)),  # lab manual eq. (19)
        dominant=float(terms.max()) if terms.size else 0.0,  # lab manual eq. (21)
        dominant_input=dominant_input,
        contributions=contributions,
        partials={name: float(d) for name, d in partials.items()},
    )


def numerical_partials(
    function: Callable[..., float], inputs: Mapping[str, float], relative_step: float = 1e-6
) -> dict[str, float]:
    """∂f/∂x_i by central differences, for functions without hand-written derivatives.

    `function` is called with the inputs as keyword arguments.
    """
    partials = {}
    for name, x in inputs.items():
        step = relative_step * max(abs(float(x)), 1e-300)
        high = function(**{**inputs, name: x + step})
        low = function(**{**inputs, name: x - step})
        partials[name] = (high - low) / (2.0 * step)
    return partials


def measured_thrust_coefficient(thrust_n, chamber_gauge_pa, ambient_pa, throat_diameter_m):
    """C_F = F_t / (p_c A_t) with p_c = p_G + p_a, A_t = π D_t²/4 (manual §4.1; eq. (11) with
    A_t).
    """
    chamber_pa = np.asarray(chamber_gauge_pa) + np.asarray(ambient_pa)
    return np.asarray(thrust_n) / (chamber_pa * circle_area_m2(throat_diameter_m))


def thrust_coefficient_uncertainty(
    calibration_slope: float,
    thrust_reading: float,
    chamber_gauge_pa: float,
    ambient_pa: float,
    throat_diameter_m: float,
    sigmas: Mapping[str, float],
) -> PropagatedUncertainty:
    """Measured C_F = a V_F / ((p_G + p_a) π D_t²/4) and its uncertainty from those of its inputs.

    calibration_slope a and thrust_reading V_F in any units whose product is N (N/mV and mV;
    the manual's gf/V and V must be converted to N first). `sigmas` maps names of CF_INPUTS to
    their standard deviations (or worst-case bounds for eq. (19)), same units as the inputs.
    A caller that has the thrust already calibrated in N (the ROS node) passes
    calibration_slope=1 with its relative uncertainty, and thrust_reading=F_t in N.
    """
    chamber_pa = chamber_gauge_pa + ambient_pa
    if not (chamber_pa > 0 and throat_diameter_m > 0):
        raise ValueError(
            f'need p_c = p_G + p_a > 0 and D_t > 0; got p_c = {chamber_pa} Pa, '
            f'D_t = {throat_diameter_m} m'
        )
    # C_F per N of thrust
    per_newton = 1.0 / (chamber_pa * float(circle_area_m2(throat_diameter_m)))
    cf = float(calibration_slope * thrust_reading * per_newton)
    # a product/quotient, the manual's eq. (24): ∂C_F/∂x_i = (power of x_i) C_F / x_i
    partials = {
        'calibration_slope': thrust_reading * per_newton,
        'thrust_reading': calibration_slope * per_newton,
        'chamber_gauge_pa': -cf / chamber_pa,
        'ambient_pa': -cf / chamber_pa,
        'throat_diameter_m': -2.0 * cf / throat_diameter_m,
    }
    return propagate(cf, partials, sigmas)
