"""Isentropic nozzle theory of the thrust-stand lab manual (seed 003), §2.1-2.5.

Pressures are absolute unless a name says `gauge`; p_c is the chamber pressure, p_e the exit
pressure, p_a the ambient pressure, all Pa. The flow is ideal: isentropic, one-dimensional,
choked throat, no shock inside the nozzle. The manual warns (footnote 2) that the measured
thrust of its stand differs a lot from this theory; that gap is what the experiment measures.

Two misprints of the manual are corrected here, not copied:
- eq. (11) and the second term of eq. (9) divide by A_c; the throat area A_t is meant (§4.1 itself
  computes C_F = F_t / (p_c A_t), and eq. (12) only follows from eq. (5) with A_t).
- eq. (9), second term: dividing eq. (1)'s pressure term by m_dot g gives
  (1/g) C* (p_e - p_a)/p_c * A_e/A_t; the printed form puts the pressure and area ratios inside
  the square root and writes p_c - p_e for p_c. We compute I_sp by eqs. (8) and (15), which agree.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize

from ..units import STANDARD_GRAVITY_M_S2

# The manual's nozzle (Fig. 4) and gas (dry air at room temperature, §2.1).
DEFAULT_THROAT_DIAMETER_M = 2.5e-3
DEFAULT_EXIT_DIAMETER_M = 3.3e-3
DEFAULT_GAMMA = 1.402
DEFAULT_GAS_CONSTANT_J_KG_K = 287.1
DEFAULT_CHAMBER_K = 293.15
STANDARD_ATMOSPHERE_PA = 101325.0  # manual footnote 9

# |p_e - p_a| below this fraction of p_a counts as optimum expansion in `expansion_state`.
OPTIMUM_EXPANSION_TOLERANCE = 1e-3


def circle_area_m2(diameter_m):
    return np.pi * np.asarray(diameter_m, dtype=float) ** 2 / 4.0


def _check_gamma(gamma: float) -> None:
    if not gamma > 1.0:
        raise ValueError(f'ratio of specific heats gamma must be > 1, got {gamma}')


def critical_pressure_ratio(gamma: float = DEFAULT_GAMMA) -> float:
    """p*/p_c = (2/(γ+1))^(γ/(γ-1)): the throat pressure of a choked nozzle, and the exit
    pressure ratio where eq. (4)'s supersonic and subsonic branches meet (A_e/A_t = 1).
    """
    _check_gamma(gamma)
    return (2.0 / (gamma + 1.0)) ** (gamma / (gamma - 1.0))


def _eq4_constant(gamma: float) -> float:
    # lab manual eq. (4): ((γ-1)/2) (2/(γ+1))^((γ+1)/(γ-1)), the numerator under the root
    return (gamma - 1.0) / 2.0 * (2.0 / (gamma + 1.0)) ** ((gamma + 1.0) / (gamma - 1.0))


def area_ratio_from_pressure_ratio(pe_over_pc, gamma: float = DEFAULT_GAMMA):
    """A_e/A_t for an exit pressure ratio 0 < p_e/p_c < 1, lab manual eq. (4)."""
    _check_gamma(gamma)
    ratio = np.asarray(pe_over_pc, dtype=float)
    if np.any((ratio <= 0.0) | (ratio >= 1.0)):
        raise ValueError('p_e/p_c must lie strictly between 0 and 1')
    log_ratio = np.log(ratio)
    # r^(2/γ) - r^((γ+1)/γ) = r^(2/γ) (1 - r^((γ-1)/γ)); expm1 keeps it exact as r -> 1
    denominator = np.exp(2.0 / gamma * log_ratio) * -np.expm1((gamma - 1.0) / gamma * log_ratio)
    result = np.sqrt(_eq4_constant(gamma) / denominator)
    return float(result) if result.ndim == 0 else result


def pressure_ratio_from_area_ratio(
    area_ratio: float, gamma: float = DEFAULT_GAMMA, branch: str = 'supersonic'
) -> float:
    """p_e/p_c solving lab manual eq. (4) for a given A_e/A_t >= 1.

    branch 'supersonic' (default) is the design solution p_e/p_c < p*/p_c; 'subsonic' the
    solution above it (throat just choked, subsonic diverging section). Solved by brentq in
    u = ln(p_e/p_c) on g(u) = ln(denominator of eq. (4)) - ln(K / (A_e/A_t)^2), which is smooth,
    O(1) in size, and has its single maximum, 2 ln(A_e/A_t) >= 0, at the critical ratio: each
    branch is one monotone bracket.
    """
    _check_gamma(gamma)
    if branch not in ('supersonic', 'subsonic'):
        raise ValueError(f"branch must be 'supersonic' or 'subsonic', not {branch!r}")
    area_ratio = float(area_ratio)
    if not np.isfinite(area_ratio) or area_ratio < 1.0:
        raise ValueError(
            f'area ratio A_e/A_t must be >= 1 (a converging-diverging nozzle), got {area_ratio}'
        )
    critical = critical_pressure_ratio(gamma)
    if area_ratio == 1.0:
        return critical
    exponent = (gamma - 1.0) / gamma
    log_target = np.log(_eq4_constant(gamma)) - 2.0 * np.log(area_ratio)

    def g(u):
        return 2.0 / gamma * u + np.log(-np.expm1(exponent * u)) - log_target

    u_critical = np.log(critical)
    if branch == 'supersonic':
        # ln(1 - r^k) <= 0, so g(u) <= (2/γ)u - log_target: at this lower end g <= -20/γ < 0
        u_low, u_high = gamma / 2.0 * log_target - 10.0, u_critical
        u_low = min(u_low, u_critical - 1.0)
    else:
        # (2/γ)u <= 0, so g(u) <= ln(1 - r^k) - log_target; choose 1 - r^k = 0.1 exp(log_target)
        small = 0.1 * np.exp(log_target)
        u_low, u_high = u_critical, np.log1p(-small) / exponent
    root = scipy.optimize.brentq(
        g, u_low, u_high, xtol=1e-15, rtol=4 * np.finfo(float).eps, maxiter=200
    )
    return float(np.exp(root))


def mass_flow_kg_s(
    chamber_pa,
    throat_area_m2,
    chamber_k=DEFAULT_CHAMBER_K,
    gamma: float = DEFAULT_GAMMA,
    gas_constant_j_kg_k: float = DEFAULT_GAS_CONSTANT_J_KG_K,
):
    """Choked mass flow through the throat, lab manual eq. (2)."""
    _check_gamma(gamma)
    return (
        np.asarray(chamber_pa)
        * throat_area_m2
        / np.sqrt(gas_constant_j_kg_k * np.asarray(chamber_k))
        * np.sqrt(gamma * (2.0 / (gamma + 1.0)) ** ((gamma + 1.0) / (gamma - 1.0)))
    )


def exit_velocity_m_s(
    pe_over_pc,
    chamber_k=DEFAULT_CHAMBER_K,
    gamma: float = DEFAULT_GAMMA,
    gas_constant_j_kg_k: float = DEFAULT_GAS_CONSTANT_J_KG_K,
):
    """Isentropic exit velocity, lab manual eq. (3)."""
    _check_gamma(gamma)
    expansion = -np.expm1((gamma - 1.0) / gamma * np.log(np.asarray(pe_over_pc, dtype=float)))
    return np.sqrt(
        2.0 * gamma * gas_constant_j_kg_k * np.asarray(chamber_k) / (gamma - 1.0) * expansion
    )


def _momentum_thrust_coefficient(pe_over_pc, gamma: float):
    # first term of lab manual eqs. (5) and (12)
    expansion = -np.expm1((gamma - 1.0) / gamma * np.log(np.asarray(pe_over_pc, dtype=float)))
    return np.sqrt(
        2.0
        * gamma**2
        / (gamma - 1.0)
        * (2.0 / (gamma + 1.0)) ** ((gamma + 1.0) / (gamma - 1.0))
        * expansion
    )


def thrust_coefficient(pe_over_pc, pa_over_pc, area_ratio, gamma: float = DEFAULT_GAMMA):
    """Ideal C_F from γ, p_a/p_c and A_e/A_t (with p_e/p_c from eq. (4)), lab manual eq. (12)."""
    _check_gamma(gamma)
    return _momentum_thrust_coefficient(pe_over_pc, gamma) + (
        np.asarray(pe_over_pc) - np.asarray(pa_over_pc)
    ) * np.asarray(area_ratio)


def thrust_n(
    chamber_pa, ambient_pa, throat_area_m2, exit_area_m2, pe_over_pc, gamma: float = DEFAULT_GAMMA
):
    """Ideal thrust, lab manual eq. (5): p_c A_t (momentum term) + (p_e - p_a) A_e."""
    _check_gamma(gamma)
    chamber_pa = np.asarray(chamber_pa, dtype=float)
    exit_pa = np.asarray(pe_over_pc) * chamber_pa
    return (
        chamber_pa * throat_area_m2 * _momentum_thrust_coefficient(pe_over_pc, gamma)
        + (exit_pa - np.asarray(ambient_pa)) * exit_area_m2
    )


def characteristic_velocity_m_s(
    chamber_k=DEFAULT_CHAMBER_K,
    gamma: float = DEFAULT_GAMMA,
    gas_constant_j_kg_k: float = DEFAULT_GAS_CONSTANT_J_KG_K,
):
    """C*, lab manual eq. (14) (= p_c A_t / m_dot, eq. (13))."""
    _check_gamma(gamma)
    return np.sqrt(
        gas_constant_j_kg_k
        * np.asarray(chamber_k)
        / gamma
        * ((gamma + 1.0) / 2.0) ** ((gamma + 1.0) / (gamma - 1.0))
    )


def specific_impulse_s(cf, c_star_m_s):
    """I_sp = C_F C* / g, lab manual eq. (15) (equal to F_t / (m_dot g), eq. (8))."""
    return np.asarray(cf) * np.asarray(c_star_m_s) / STANDARD_GRAVITY_M_S2


def exit_mach_number(pe_over_pc, gamma: float = DEFAULT_GAMMA):
    """Isentropic Mach number at the exit for p_e/p_c (same relation as eq. (3))."""
    ratio = np.asarray(pe_over_pc, dtype=float)
    return np.sqrt(2.0 / (gamma - 1.0) * np.expm1(-(gamma - 1.0) / gamma * np.log(ratio)))


def choking_ambient_ratio(area_ratio: float, gamma: float = DEFAULT_GAMMA) -> float:
    """Largest p_a/p_c at which the throat is still choked: the subsonic root of eq. (4).

    Above it the whole nozzle is subsonic, eq. (2) overestimates the flow and eqs. (5)/(12) do
    not apply (the stand is not firing, or barely).
    """
    return pressure_ratio_from_area_ratio(area_ratio, gamma, 'subsonic')


def shock_free_ambient_ratio(area_ratio: float, gamma: float = DEFAULT_GAMMA) -> float:
    """Largest p_a/p_c for which no normal shock stands inside the diverging section: a normal
    shock exactly at the exit, p_a = p_e (1 + 2γ/(γ+1) (M_e² - 1)) on the supersonic branch.
    Between this and `choking_ambient_ratio` the flow separates or shocks inside the nozzle and
    the ideal eq. (12) overestimates C_F.
    """
    pe_over_pc = pressure_ratio_from_area_ratio(area_ratio, gamma, 'supersonic')
    mach = exit_mach_number(pe_over_pc, gamma)
    return float(pe_over_pc * (1.0 + 2.0 * gamma / (gamma + 1.0) * (mach**2 - 1.0)))


def expansion_state(exit_pa: float, ambient_pa: float) -> str:
    """'optimum', 'under-expanded' (p_e > p_a) or 'over-expanded' (p_e < p_a), manual §2.3."""
    if abs(exit_pa - ambient_pa) <= OPTIMUM_EXPANSION_TOLERANCE * ambient_pa:
        return 'optimum'
    return 'under-expanded' if exit_pa > ambient_pa else 'over-expanded'


@dataclass(frozen=True)
class NozzlePerformance:
    """Ideal performance of a nozzle at one chamber and ambient state, SI."""

    chamber_pa: float  # p_c, absolute
    ambient_pa: float  # p_a
    chamber_k: float  # T_c
    branch: str  # which root of eq. (4)
    area_ratio: float  # A_e/A_t
    pe_over_pc: float  # eq. (4)
    exit_pa: float  # p_e
    exit_mach: float
    mass_flow_kg_s: float  # eq. (2)
    exit_velocity_m_s: float  # eq. (3)
    thrust_n: float  # eq. (5)
    cf: float  # eq. (12)
    c_star_m_s: float  # eq. (14)
    isp_s: float  # eq. (15)
    expansion: str  # optimum / under-expanded / over-expanded
    flow_regime: str  # 'shock-free', 'shock in nozzle', 'subsonic exit' or 'not choked'

    def as_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass(frozen=True)
class Nozzle:
    """A conical thruster nozzle and its gas; defaults are the manual's (Fig. 4, §2.1)."""

    throat_diameter_m: float = DEFAULT_THROAT_DIAMETER_M
    exit_diameter_m: float = DEFAULT_EXIT_DIAMETER_M
    gamma: float = DEFAULT_GAMMA
    gas_constant_j_kg_k: float = DEFAULT_GAS_CONSTANT_J_KG_K

    def __post_init__(self):
        if not (self.throat_diameter_m > 0 and self.exit_diameter_m > 0):
            raise ValueError('nozzle diameters must be positive')
        if self.exit_diameter_m < self.throat_diameter_m:
            raise ValueError(
                f'exit diameter {self.exit_diameter_m} m is smaller than the throat '
                f'{self.throat_diameter_m} m: not a converging-diverging nozzle'
            )
        _check_gamma(self.gamma)
        if not self.gas_constant_j_kg_k > 0:
            raise ValueError('gas constant must be positive')

    @classmethod
    def from_mapping(cls, data, where: str = 'thrust_stand') -> 'Nozzle':
        """From the `thrust_stand:` section of a balance config (config/thrust_stand.yaml)."""
        try:
            return cls(
                float(data.get('throat_diameter_m', DEFAULT_THROAT_DIAMETER_M)),
                float(data.get('exit_diameter_m', DEFAULT_EXIT_DIAMETER_M)),
                float(data.get('gamma', DEFAULT_GAMMA)),
                float(data.get('gas_constant_j_kg_k', DEFAULT_GAS_CONSTANT_J_KG_K)),
            )
        except (AttributeError, TypeError, ValueError) as error:
            raise ValueError(f'{where}: {error}') from None

    @property
    def throat_area_m2(self) -> float:
        return float(circle_area_m2(self.throat_diameter_m))

    @property
    def exit_area_m2(self) -> float:
        return float(circle_area_m2(self.exit_diameter_m))

    @property
    def area_ratio(self) -> float:
        return (self.exit_diameter_m / self.throat_diameter_m) ** 2

    def pe_over_pc(self, branch: str = 'supersonic') -> float:
        return pressure_ratio_from_area_ratio(self.area_ratio, self.gamma, branch)

    def performance(
        self,
        chamber_pa: float,
        ambient_pa: float = STANDARD_ATMOSPHERE_PA,
        chamber_k: float = DEFAULT_CHAMBER_K,
        branch: str = 'supersonic',
    ) -> NozzlePerformance:
        """Ideal performance at absolute chamber pressure p_c and ambient p_a (Pa), T_c (K)."""
        chamber_pa, ambient_pa, chamber_k = float(chamber_pa), float(ambient_pa), float(chamber_k)
        if not (chamber_pa > 0 and ambient_pa >= 0 and chamber_k > 0):
            raise ValueError(
                f'need p_c > 0, p_a >= 0, T_c > 0; got p_c = {chamber_pa} Pa, '
                f'p_a = {ambient_pa} Pa, T_c = {chamber_k} K'
            )
        if chamber_pa <= ambient_pa:
            raise ValueError(
                f'chamber pressure {chamber_pa:.6g} Pa does not exceed ambient {ambient_pa:.6g} '
                'Pa: no flow (is p_c absolute, p_G + p_a?)'
            )
        ratio = self.pe_over_pc(branch)
        area_ratio = self.area_ratio
        pa_over_pc = ambient_pa / chamber_pa
        cf = float(thrust_coefficient(ratio, pa_over_pc, area_ratio, self.gamma))
        c_star = float(
            characteristic_velocity_m_s(chamber_k, self.gamma, self.gas_constant_j_kg_k)
        )
        if pa_over_pc > choking_ambient_ratio(area_ratio, self.gamma):
            regime = 'not choked'
        elif branch == 'subsonic':
            regime = 'subsonic exit'  # physical only where p_a = p_e of this root
        elif pa_over_pc > shock_free_ambient_ratio(area_ratio, self.gamma):
            regime = 'shock in nozzle'
        else:
            regime = 'shock-free'
        return NozzlePerformance(
            chamber_pa=chamber_pa,
            ambient_pa=ambient_pa,
            chamber_k=chamber_k,
            branch=branch,
            area_ratio=area_ratio,
            pe_over_pc=ratio,
            exit_pa=ratio * chamber_pa,
            exit_mach=float(exit_mach_number(ratio, self.gamma)),
            mass_flow_kg_s=float(
                mass_flow_kg_s(
                    chamber_pa,
                    self.throat_area_m2,
                    chamber_k,
                    self.gamma,
                    self.gas_constant_j_kg_k,
                )
            ),
            exit_velocity_m_s=float(
                exit_velocity_m_s(ratio, chamber_k, self.gamma, self.gas_constant_j_kg_k)
            ),
            thrust_n=float(
                thrust_n(
                    chamber_pa,
                    ambient_pa,
                    self.throat_area_m2,
                    self.exit_area_m2,
                    ratio,
                    self.gamma,
                )
            ),
            cf=cf,
            c_star_m_s=c_star,
            isp_s=float(specific_impulse_s(cf, c_star)),
            expansion=expansion_state(ratio * chamber_pa, ambient_pa),
            flow_regime=regime,
        )
