"""Measured against theoretical thrust coefficient (lab manual §2.3 and §4.3), from averaged
signals.

Data flow: windows of thrust (N), chamber gauge pressure p_G and ambient pressure p_a (Pa)
-> `WindowMean`s -> `compare_with_theory` -> `ThrustComparison` (measured C_F with its error
budget, ideal nozzle performance at the measured p_c, p_a) -> report / diagnostics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .nozzle import DEFAULT_CHAMBER_K, Nozzle, NozzlePerformance
from .significant import format_value_error
from .uncertainty import PropagatedUncertainty, thrust_coefficient_uncertainty


@dataclass(frozen=True)
class WindowMean:
    """Mean of a window of samples and its standard uncertainty (same units as the samples)."""

    mean: float
    sigma: float
    samples: int


def window_mean(values, instrument_variance=None) -> WindowMean:
    """Mean of (N,) samples. σ² = s²/N (random scatter, averages out) + the instrument's variance
    (e.g. sensor_msgs/FluidPressure.variance, a calibration error that does not average out).
    """
    values = np.asarray(values, dtype=float).ravel()
    values = values[np.isfinite(values)]
    if values.size == 0:
        raise ValueError('no finite samples in the window')
    scatter = float(np.var(values, ddof=1)) / values.size if values.size > 1 else 0.0
    instrument = 0.0
    if instrument_variance is not None:
        variances = np.asarray(instrument_variance, dtype=float).ravel()
        variances = variances[np.isfinite(variances) & (variances > 0)]
        instrument = float(variances.mean()) if variances.size else 0.0
    return WindowMean(float(values.mean()), float(np.sqrt(scatter + instrument)), int(values.size))


@dataclass(frozen=True)
class ThrustComparison:
    thrust_n: WindowMean
    chamber_gauge_pa: WindowMean
    ambient_pa: WindowMean
    nozzle: Nozzle
    chamber_k: float
    cf_measured: PropagatedUncertainty  # C_F = F_t / (p_c A_t), eqs. (19)-(21)
    theory: NozzlePerformance | None  # eqs. (2)-(5), (12), (14), (15); None without flow
    thrust_relative_sigma: float
    throat_diameter_sigma_m: float

    @property
    def chamber_pa(self) -> float:
        return self.chamber_gauge_pa.mean + self.ambient_pa.mean

    @property
    def firing(self) -> bool:
        """True when the throat is choked, i.e. eqs. (2)-(12) apply at all."""
        return self.theory is not None and self.theory.flow_regime != 'not choked'

    @property
    def cf_ratio(self) -> float:
        """Measured / theoretical C_F: the nozzle's thrust efficiency."""
        if self.theory is None or self.theory.cf == 0:
            return float('nan')
        return self.cf_measured.value / self.theory.cf

    @property
    def cf_formatted(self) -> str:
        try:
            return format_value_error(self.cf_measured.value, self.cf_measured.sigma, name='C_F')
        except ValueError:
            return f'C_F = {self.cf_measured.value:.4g}'

    def as_dict(self) -> dict:
        """Plain data for JSON (report.json of the analyzer)."""
        theory = self.theory.as_dict() if self.theory else None
        return {
            'nozzle': {
                'throat_diameter_m': self.nozzle.throat_diameter_m,
                'exit_diameter_m': self.nozzle.exit_diameter_m,
                'gamma': self.nozzle.gamma,
                'gas_constant_j_kg_k': self.nozzle.gas_constant_j_kg_k,
                'area_ratio': self.nozzle.area_ratio,
            },
            'inputs': {
                'thrust_n': self.thrust_n.__dict__,
                'chamber_gauge_pa': self.chamber_gauge_pa.__dict__,
                'ambient_pa': self.ambient_pa.__dict__,
                'chamber_pa': self.chamber_pa,
                'chamber_k': self.chamber_k,
                'thrust_relative_sigma': self.thrust_relative_sigma,
                'throat_diameter_sigma_m': self.throat_diameter_sigma_m,
            },
            'measured': {
                'cf': self.cf_measured.value,
                'cf_sigma_eq20': self.cf_measured.sigma,
                'cf_worst_case_eq19': self.cf_measured.worst_case,
                'cf_dominant_eq21': self.cf_measured.dominant,
                'dominant_input': self.cf_measured.dominant_input,
                'contributions': dict(self.cf_measured.contributions),
                'formatted': self.cf_formatted,
            },
            'theory': theory,
            'cf_ratio': self.cf_ratio,
            'firing': self.firing,
        }


def compare_with_theory(
    thrust_n: WindowMean,
    chamber_gauge_pa: WindowMean,
    ambient_pa: WindowMean,
    nozzle: Nozzle = Nozzle(),
    *,
    thrust_relative_sigma: float = 0.0,
    throat_diameter_sigma_m: float = 0.0,
    chamber_k: float = DEFAULT_CHAMBER_K,
) -> ThrustComparison:
    """Measured C_F with its uncertainty, and the ideal nozzle at the same p_c and p_a.

    thrust_relative_sigma: relative σ of the calibration constant a (it scales every thrust);
    the thrust window's own σ is the reading's. T_c only enters m_dot, u_e, C*, I_sp.
    """
    chamber_pa = chamber_gauge_pa.mean + ambient_pa.mean
    # thrust already in N: a = 1 carries the calibration's relative σ, V_F = F_t the reading's
    cf = thrust_coefficient_uncertainty(
        1.0,
        thrust_n.mean,
        chamber_gauge_pa.mean,
        ambient_pa.mean,
        nozzle.throat_diameter_m,
        {
            'calibration_slope': thrust_relative_sigma,
            'thrust_reading': thrust_n.sigma,
            'chamber_gauge_pa': chamber_gauge_pa.sigma,
            'ambient_pa': ambient_pa.sigma,
            'throat_diameter_m': throat_diameter_sigma_m,
        },
    )
    theory = None
    if chamber_pa > ambient_pa.mean and ambient_pa.mean >= 0:
        theory = nozzle.performance(chamber_pa, ambient_pa.mean, chamber_k)
    return ThrustComparison(
        thrust_n,
        chamber_gauge_pa,
        ambient_pa,
        nozzle,
        float(chamber_k),
        cf,
        theory,
        float(thrust_relative_sigma),
        float(throat_diameter_sigma_m),
    )
