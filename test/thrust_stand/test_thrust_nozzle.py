"""Nozzle theory of the thrust-stand manual, eqs. (1)-(15)."""

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest
import scipy.optimize

from balance_calib.config import load_balance_config
from balance_calib.thrust_stand.nozzle import (
    area_ratio_from_pressure_ratio,
    characteristic_velocity_m_s,
    critical_pressure_ratio,
    mass_flow_kg_s,
    Nozzle,
    pressure_ratio_from_area_ratio,
    thrust_coefficient,
)

GAMMA = 1.402
P_A = 101325.0
P_C = 0.5e6 + P_A  # the manual's regulator fully open, about p_G = 0.5 MPa


@given(area_ratio=st.floats(1.01, 100.0), branch=st.sampled_from(['supersonic', 'subsonic']))
@settings(max_examples=300, deadline=None)
def test_eq4_round_trip_over_area_ratios(area_ratio, branch):
    ratio = pressure_ratio_from_area_ratio(area_ratio, GAMMA, branch)
    critical = critical_pressure_ratio(GAMMA)
    assert (ratio < critical) if branch == 'supersonic' else (ratio > critical)
    assert area_ratio_from_pressure_ratio(ratio, GAMMA) == pytest.approx(area_ratio, rel=1e-10)


@given(log_ratio=st.floats(np.log(2.6e-4), np.log(0.99997)))
@settings(max_examples=300, deadline=None)
def test_eq4_solution_is_accurate_to_1e_10_relative(log_ratio):
    # pick p_e/p_c (A_e/A_t between ~1.01 and ~100), go forward through eq. (4), solve back
    ratio = float(np.exp(log_ratio))
    area_ratio = area_ratio_from_pressure_ratio(ratio, GAMMA)
    if area_ratio < 1.01:
        return  # the two roots merge at A_e/A_t = 1; outside the asked range
    branch = 'supersonic' if ratio < critical_pressure_ratio(GAMMA) else 'subsonic'
    assert pressure_ratio_from_area_ratio(area_ratio, GAMMA, branch) == pytest.approx(
        ratio, rel=1e-10
    )


def _mach_from_area_ratio(area_ratio, gamma, supersonic=True):
    # the textbook area-Mach relation, independent of eq. (4)'s pressure form
    def f(mach):
        return (
            1
            / mach
            * (2 / (gamma + 1) * (1 + (gamma - 1) / 2 * mach**2))
            ** ((gamma + 1) / (2 * (gamma - 1)))
            - area_ratio
        )

    return (
        scipy.optimize.brentq(f, 1.0, 50.0) if supersonic else scipy.optimize.brentq(f, 1e-6, 1.0)
    )


def test_manual_nozzle_at_half_a_megapascal_matches_the_mach_number_route():
    performance = Nozzle().performance(P_C, P_A)
    assert performance.area_ratio == pytest.approx((3.3 / 2.5) ** 2)
    mach = _mach_from_area_ratio(performance.area_ratio, GAMMA)
    ratio = (1 + (GAMMA - 1) / 2 * mach**2) ** (-GAMMA / (GAMMA - 1))
    assert performance.pe_over_pc == pytest.approx(ratio, rel=1e-10)
    # thrust by eq. (1) from the exit state: m_dot u_e + (p_e - p_a) A_e, u_e = M_e a_e
    t_exit = 293.15 / (1 + (GAMMA - 1) / 2 * mach**2)
    u_exit = mach * np.sqrt(GAMMA * 287.1 * t_exit)
    nozzle = Nozzle()
    m_dot = mass_flow_kg_s(P_C, nozzle.throat_area_m2)
    thrust = m_dot * u_exit + (ratio * P_C - P_A) * nozzle.exit_area_m2
    assert performance.thrust_n == pytest.approx(thrust, rel=1e-9)
    assert performance.exit_velocity_m_s == pytest.approx(u_exit, rel=1e-9)
    # the numbers quoted in the report: p_e/p_c 0.1202, over-expanded, C_F 1.137, F_t 3.36 N
    assert performance.pe_over_pc == pytest.approx(0.12017, abs=1e-5)
    assert performance.cf == pytest.approx(1.13664, abs=1e-5)
    assert performance.thrust_n == pytest.approx(3.3551, abs=1e-4)
    assert performance.expansion == 'over-expanded' and performance.flow_regime == 'shock-free'


def test_subsonic_branch_matches_the_subsonic_mach_number():
    area_ratio = 1.7424
    mach = _mach_from_area_ratio(area_ratio, GAMMA, supersonic=False)
    ratio = (1 + (GAMMA - 1) / 2 * mach**2) ** (-GAMMA / (GAMMA - 1))
    assert pressure_ratio_from_area_ratio(area_ratio, GAMMA, 'subsonic') == pytest.approx(
        ratio, rel=1e-10
    )


def test_cf_is_largest_where_the_exit_pressure_equals_ambient():
    # vary A_e at fixed p_c, p_a (eq. (7)): the best area ratio is the one whose p_e = p_a
    pa_over_pc = P_A / P_C

    def cf_of(area_ratio):
        ratio = pressure_ratio_from_area_ratio(area_ratio, GAMMA)
        return thrust_coefficient(ratio, pa_over_pc, area_ratio, GAMMA)

    best = scipy.optimize.minimize_scalar(
        lambda e: -cf_of(e), bounds=(1.0001, 5.0), method='bounded', options={'xatol': 1e-10}
    )
    optimum_area_ratio = area_ratio_from_pressure_ratio(pa_over_pc, GAMMA)
    assert best.x == pytest.approx(optimum_area_ratio, rel=1e-4)
    assert pressure_ratio_from_area_ratio(best.x, GAMMA) == pytest.approx(pa_over_pc, rel=1e-4)
    for other in (1.05, 1.3, 1.7424, 2.5, 4.0):
        assert cf_of(other) < cf_of(optimum_area_ratio)


def test_thrust_slope_with_exit_area_is_exit_minus_ambient_pressure():
    # eq. (7): dF/dA_e = p_e - p_a, here by central differences on the manual's nozzle
    nozzle = Nozzle()
    area = nozzle.exit_area_m2
    h = area * 1e-6

    def thrust_at(exit_area_m2):
        diameter = np.sqrt(4 * exit_area_m2 / np.pi)
        return Nozzle(exit_diameter_m=diameter).performance(P_C, P_A).thrust_n

    slope = (thrust_at(area + h) - thrust_at(area - h)) / (2 * h)
    exit_pa = nozzle.performance(P_C, P_A).exit_pa
    assert slope == pytest.approx(exit_pa - P_A, rel=1e-5)


def test_specific_impulse_eq8_equals_eq15_and_c_star_eq13_equals_eq14():
    performance = Nozzle().performance(P_C, P_A, chamber_k=300.0)
    assert performance.isp_s == pytest.approx(
        performance.thrust_n / (performance.mass_flow_kg_s * 9.80665), rel=1e-12
    )
    assert characteristic_velocity_m_s(300.0) == pytest.approx(
        P_C * Nozzle().throat_area_m2 / performance.mass_flow_kg_s, rel=1e-12
    )


def test_flow_regimes_and_bad_input():
    nozzle = Nozzle()
    assert nozzle.performance(P_A * 1.05, P_A).flow_regime == 'not choked'
    assert nozzle.performance(P_A * 1.5, P_A).flow_regime == 'shock in nozzle'
    with pytest.raises(ValueError, match='does not exceed ambient'):
        nozzle.performance(0.5e6, 0.6e6)
    with pytest.raises(ValueError, match='area ratio'):
        pressure_ratio_from_area_ratio(0.9)
    with pytest.raises(ValueError, match='converging-diverging'):
        Nozzle(exit_diameter_m=2e-3)


def test_thrust_stand_config_loads_and_describes_the_manual_nozzle():
    config = load_balance_config('thrust_stand')
    assert config.components == ('FX',) and config.bridge_outputs == ('FXV',)
    linear = config.matrices['linear']
    assert linear.term_names == ('1', 'FXV')
    assert linear.coefficient('FX', 'FXV') == pytest.approx(5.0)
    assert Nozzle.from_mapping(config.raw['thrust_stand']) == Nozzle()
