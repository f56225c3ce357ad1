"""The data reduction's pure core (TM-663 §10.3-10.4): axes, weight tare, deflection, moment
transfer, coefficients, held points. Hand-worked cases and simulated runs on the LMC6522 (memo
cubic matrix as the truth of the balance).
"""

from aero_cases import (
    CALIBRATION,
    CONFIG,
    MODEL,
    readings,
    simulated_run,
    TRUE_CG_M,
    TRUE_WEIGHT_N,
)
from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from balance_calib.aero.axes import body_to_wind, gravity_direction, wind_coefficients
from balance_calib.aero.coefficients import (
    coefficients_from_air_loads,
    reduce_loads,
    transfer_moments,
)
from balance_calib.aero.deflection import Deflection, DeflectionDidNotConverge, iterate_attitude
from balance_calib.aero.held_points import find_holds, HoldSettings, HoldTracker
from balance_calib.aero.model_file import load_model, model_from_dict
from balance_calib.aero.run import reduce_run
from balance_calib.aero.weight_tare import (
    declared_tare,
    declared_weight_contradiction,
    fit_weight_tare,
    weight_loads,
    WeightTareError,
)
from balance_calib.config import ConfigError
from balance_calib.model.active_calibration import activate, six_axis_loads
from balance_calib.model.inverse import outputs_for_loads
from balance_calib.tunnel_axes import UPRIGHT

angles = st.floats(min_value=-np.pi, max_value=np.pi, allow_nan=False)


# --- axes --------------------------------------------------------------------------------------
@settings(max_examples=60, deadline=None, derandomize=True)
@given(angles, angles)
def test_body_to_wind_is_a_proper_rotation(alpha, beta):
    rotation = body_to_wind(alpha, beta)
    assert np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(rotation) == pytest.approx(1.0, abs=1e-12)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(st.lists(st.floats(min_value=-5, max_value=5), min_size=6, max_size=6))
def test_at_zero_alpha_and_beta_wind_coefficients_are_the_body_ones(body):
    # documented sign convention: drag counts aft like axial force, lift up like normal force
    assert np.allclose(body_to_wind(0.0, 0.0), np.eye(3))
    assert np.allclose(wind_coefficients(np.array(body), 0.0, 0.0), body, atol=1e-12)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(angles, angles, st.lists(st.floats(min_value=-5, max_value=5), min_size=6, max_size=6))
def test_wind_coefficients_follow_the_interface_formulas(alpha, beta, body):
    caf, cy, cn = body[:3]
    wind = wind_coefficients(np.array(body), alpha, beta)
    assert wind[2] == pytest.approx(cn * np.cos(alpha) - caf * np.sin(alpha), abs=1e-12)
    assert wind[0] == pytest.approx(
        caf * np.cos(alpha) * np.cos(beta) + cn * np.sin(alpha) * np.cos(beta) - cy * np.sin(beta),
        abs=1e-12,
    )


def test_pure_normal_force_at_90_degrees_is_drag():
    wind = wind_coefficients(np.array([0.0, 0.0, 1.3, 0.0, 0.0, 0.0]), np.pi / 2, 0.0)
    assert wind[0] == pytest.approx(1.3, abs=1e-12)  # C_D
    assert wind[2] == pytest.approx(0.0, abs=1e-12)  # C_L


@settings(max_examples=40, deadline=None, derandomize=True)
@given(angles, angles)
def test_gravity_is_a_unit_vector_and_upright_weight_reads_negative_normal_force(roll, alpha):
    assert np.linalg.norm(gravity_direction([roll, alpha, 0.3])) == pytest.approx(1.0)
    loads = weight_loads([0.0, 0.0, 0.0], 10.0, [0.0, 0.0, 0.0])
    assert np.allclose(loads, [0, 0, -10.0, 0, 0, 0])


# --- moment transfer and coefficients ------------------------------------------------------------
def test_pitching_moment_transfers_to_a_moment_reference_centre_ahead_of_the_balance():
    # 100 N normal force (up) at the balance centre, MRC 50 mm ahead: about the MRC the force is
    # 50 mm behind, nose down: M_Y' = M_Y - x_r F_Z = 2 - 0.05*100 = -3 N·m; yaw likewise M_Z' =
    # -x_r F_Y
    loads = np.array([0.0, 10.0, 100.0, 0.0, 2.0, 0.0])
    moved = transfer_moments(loads, [0.05, 0.0, 0.0])
    assert np.allclose(moved, [0.0, 10.0, 100.0, 0.0, -3.0, -0.5])
    # and back again
    assert np.allclose(transfer_moments(moved, [-0.05, 0.0, 0.0]), loads)


def test_coefficients_divide_by_q_s_and_the_reference_lengths():
    model = model_from_dict(
        {
            'reference_area_m2': 0.01,
            'reference_chord_m': 0.1,
            'reference_span_m': 0.2,
            'moment_reference_centre_m': [0, 0, 0],
            'weight_n': 1.0,
            'centre_of_gravity_m': [0, 0, 0],
        }
    )
    body = coefficients_from_air_loads(np.array([5.0, 1.0, 50.0, 2.0, 3.0, 4.0]), 1000.0, model)
    assert np.allclose(body, [0.5, 0.1, 5.0, 1.0, 3.0, 2.0])


def test_wind_off_q_gives_nan_coefficients_not_numbers():
    reduced = reduce_loads(np.zeros(6), np.zeros(3), 0.0, MODEL, declared_tare(1.0, [0, 0, 0]))
    assert np.all(np.isnan(reduced.body)) and np.all(np.isnan(reduced.wind))


# --- weight tare ---------------------------------------------------------------------------------
def test_weight_tare_reverses_sign_when_the_model_is_rolled_180_degrees():
    # hand-worked at α = 0: upright, W = 20 N at x_cg = 10 mm reads F_Z = -20 N, M_Y = -0.2 N·m
    upright = weight_loads([0.0, 0.0, 0.0], 20.0, [0.01, 0.0, 0.0])
    assert np.allclose(upright, [0, 0, -20.0, 0, -0.2, 0])
    assert np.allclose(weight_loads([np.pi, 0.0, 0.0], 20.0, [0.01, 0.0, 0.0]), -upright)
    # at α = 10°: the axial part (W sin α) stays, the normal force and its moment reverse
    a = np.radians(10.0)
    up, down = (weight_loads([roll, a, 0.0], 20.0, [0.01, 0.0, 0.0]) for roll in (0.0, np.pi))
    assert up[0] == pytest.approx(20 * np.sin(a)) and down[0] == pytest.approx(up[0])
    assert down[2] == pytest.approx(-up[2]) and down[4] == pytest.approx(-up[4])


def test_a_single_wind_off_point_cannot_give_weight_and_cg():
    with pytest.raises(WeightTareError, match='cannot determine 10 tare parameters'):
        fit_weight_tare(np.zeros((1, 6)), np.zeros((1, 3)), sigma_loads=np.ones(6))


def test_a_sweep_in_alpha_alone_cannot_separate_the_weight_from_offsets_at_constant_alpha():
    attitudes = np.zeros((4, 3))  # four holds, all at the same attitude
    with pytest.raises(WeightTareError, match='does not determine'):
        fit_weight_tare(np.zeros((4, 6)), attitudes, sigma_loads=np.ones(6))


def test_weight_tare_from_a_wind_off_sweep_recovers_weight_to_0_1_percent_and_cg_to_1_mm():
    noise_pct = 0.002  # σ of a held point's mean load, % FS, every component
    sigma_loads = noise_pct / 100 * CONFIG.capacity
    profile, raw = simulated_run(noise_pct_fs=noise_pct, seed=3)
    result = reduce_run(
        readings(raw),
        profile.support_attitude,
        profile.q_pa,
        MODEL.with_estimated_weight(),
        HoldSettings(),
        sigma_loads,
    )
    tare = result.tares[0]
    assert tare.source == 'estimated' and tare.points == 12
    # the sweep's own precision (propagated from the noise) is well inside the tolerance ...
    assert 4 * tare.weight_sigma_n < 0.001 * TRUE_WEIGHT_N and np.all(4 * tare.cg_sigma_m < 0.001)
    # ... and the estimate lands there
    assert abs(tare.weight_n - TRUE_WEIGHT_N) < 0.001 * TRUE_WEIGHT_N
    assert np.all(np.abs(tare.cg_m - TRUE_CG_M) < 0.001)


def test_tare_in_output_space_is_wrong_for_a_nonlinear_balance_where_load_space_is_exact():
    model = model_from_dict(
        {
            **{
                k: getattr(MODEL, k)
                for k in ('reference_area_m2', 'reference_chord_m', 'reference_span_m')
            },
            'moment_reference_centre_m': list(MODEL.moment_reference_centre_m),
            'weight_n': 'estimate',
            'centre_of_gravity_m': 'estimate',
        }
    )  # no deflection
    profile, raw = simulated_run(model=model)
    result = reduce_run(
        readings(raw), profile.support_attitude, profile.q_pa, model, HoldSettings(), np.ones(6)
    )
    points = result.wind_on
    truth = np.array([profile.body_coefficients[p.first_sample] for p in points])
    load_space = np.array([p.reduced.body for p in points])
    assert np.max(np.abs(load_space - truth)) < 1e-9
    # output space: the wind-off outputs at the same attitude subtracted before the calibration
    cubic = activate(CALIBRATION, 'cubic', UPRIGHT).model
    first = np.array([p.first_sample for p in points])
    attitude = profile.support_attitude[first]
    wind_off_outputs = outputs_for_loads(
        CONFIG.matrices['cubic'].without_constant(),
        UPRIGHT.from_tunnel(weight_loads(attitude, TRUE_WEIGHT_N, TRUE_CG_M)),
    )
    air = UPRIGHT.to_tunnel(six_axis_loads(cubic, raw[first] - wind_off_outputs))
    output_space = coefficients_from_air_loads(air, profile.q_pa[first], model)
    # what a weight off by 0.1 % or a CG off by 1 mm would do to the coefficients
    q_s = profile.q_pa[first] * model.reference_area_m2
    tolerance = np.column_stack(
        [0.001 * TRUE_WEIGHT_N / q_s] * 3
        + [0.001 * TRUE_WEIGHT_N / (q_s * L) for L in model.reference_lengths_m[3:]]
    )
    worst = np.max(np.abs(output_space - truth) / tolerance, axis=0)
    # noise-free, so any excess is the method: C_AF comes out 1.4x the tolerance wrong, C_Y 0.9x
    assert worst[0] > 1.0, worst


# --- deflection ----------------------------------------------------------------------------------
def test_deflection_correction_recovers_the_true_attitude_and_coefficients():
    profile, raw = simulated_run()
    result = reduce_run(
        readings(raw), profile.support_attitude, profile.q_pa, MODEL, HoldSettings(), np.ones(6)
    )
    points = result.wind_on
    first = np.array([p.first_sample for p in points])
    true_alpha = profile.attitude[first, 1]
    # it matters
    assert np.max(np.abs(true_alpha - profile.support_attitude[first, 1])) > np.radians(0.05)
    assert np.allclose([p.reduced.attitude[1] for p in points], true_alpha, atol=1e-12, rtol=0)
    assert np.allclose(
        [p.reduced.wind for p in points], profile.wind_coefficients[first], atol=1e-9, rtol=0
    )


def test_a_sting_too_soft_for_the_loads_is_refused():
    with pytest.raises(DeflectionDidNotConverge):
        iterate_attitude(
            np.zeros(3),
            Deflection(alpha_rad_per_n=2.0),
            lambda a: np.array([0, 0, a[1] + 1, 0, 0, 0]),
        )


# --- held points ---------------------------------------------------------------------------------
def test_live_hold_tracking_finds_the_same_holds_as_the_offline_search():
    rng = np.random.default_rng(1)
    levels = rng.integers(0, 4, size=40)
    lengths = rng.integers(1, 9, size=40)
    attitude = np.repeat(
        np.column_stack([np.zeros(40), np.radians(levels * 2.0), np.zeros(40)]), lengths, axis=0
    )
    q = np.repeat(np.where(rng.random(40) < 0.3, 0.0, 5e4), lengths)
    attitude += rng.normal(scale=2e-5, size=attitude.shape)  # support jitter inside the tolerance
    settings = HoldSettings(point_samples=3, settle_samples=1, min_samples=2)
    holds = find_holds(attitude, q, settings)
    tracker = HoldTracker(settings)
    starts, ready = [], []
    for i in range(len(q)):
        new, is_ready = tracker.add(attitude[i], q[i])
        if new:
            starts.append(i)
        if is_ready:
            ready.append(i)
    assert starts == list(holds[:, 0])
    offline_ready = [
        settings.point_range(a, b)[1] - 1 for a, b in holds if settings.point_range(a, b)
    ]
    assert ready == offline_ready


def test_model_file_errors_name_the_file_and_key(tmp_path):
    path = tmp_path / 'bad.yaml'
    path.write_text(
        'reference_area_m2: 0.01\nreference_chord_m: -1\nreference_span_m: 0.1\n'
        'moment_reference_centre_m: [0,0,0]\nweight_n: estimate\ncentre_of_gravity_m: estimate\n'
    )
    with pytest.raises(ConfigError, match=r'bad.yaml: reference_chord_m must be positive'):
        load_model(path)
    path.write_text(
        'reference_area_m2: 0.01\nreference_chord_m: 1\nreference_span_m: 0.1\n'
        'moment_reference_centre_m: [0,0]\nweight_n: 3\ncentre_of_gravity_m: estimate\n'
    )
    with pytest.raises(
        ConfigError, match=r'bad.yaml: moment_reference_centre_m must be three numbers'
    ):
        load_model(path)
    assert load_model('euler_replica').weight_n == 40.0


def _sweep(weight_n, cg_m, rolls_deg=(0.0, 90.0, 180.0, 270.0), alphas_deg=(-2.0, 10.0, 22.0)):
    """A wind-off α/φ sweep (support attitudes (K, 3) rad) and what the balance reads: a model of
    weight_n at cg_m plus a constant offset, no deflection, no noise.
    """
    support = np.radians([[phi, alpha, 0.0] for phi in rolls_deg for alpha in alphas_deg])
    offset = np.array([3.0, -2.0, 5.0, 0.1, -0.2, 0.05])
    return weight_loads(support, weight_n, cg_m) + offset, support


def test_a_declared_weight_the_sweep_contradicts_is_named():
    readings, support = _sweep(250.0, [0.015, 0.0, -0.004])
    sigma = np.full(6, 0.5)  # N, N·m of a held point's mean: σ_W well below 1 N over 12 points
    check = {'sigma_loads': sigma, 'model_name': 'model file euler_replica'}
    # the right weight and CG: nothing said
    assert (
        declared_weight_contradiction(
            readings, support, weight_n=250.0, cg_m=[0.015, 0.0, -0.004], **check
        )
        == ''
    )
    # another model's file: 40 N at 10 mm, both named
    said = declared_weight_contradiction(
        readings, support, weight_n=40.0, cg_m=[0.010, 0.0, 0.0], **check
    )
    assert 'W = 250' in said and '40 N' in said and 'weight' in said and 'x_cg' in said
    # the weight right, the CG 5 mm off in z only
    said = declared_weight_contradiction(
        readings, support, weight_n=250.0, cg_m=[0.015, 0.0, 0.001], **check
    )
    assert 'z_cg' in said and 'weight,' not in said and 'x_cg' not in said


def test_a_sweep_without_rolls_checks_what_it_can_estimate():
    # no rolled attitude: y_cg and z_cg trade with the offsets, the four cannot all be estimated;
    # with the CG held at its declared value the weight still can, and is checked
    readings, support = _sweep(250.0, [0.015, 0.0, -0.004], rolls_deg=(0.0,))
    said = declared_weight_contradiction(
        readings, support, sigma_loads=np.full(6, 0.5), weight_n=40.0, cg_m=[0.015, 0.0, -0.004]
    )
    assert 'weight' in said and '_cg' not in said
