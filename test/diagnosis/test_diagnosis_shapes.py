"""The diagnosis on effects it does not model exactly: a deterministic CI subset of
launchless_scripts/diagnosis_rates.

Every campaign carries one effect in an alternative shape of simulation/effects.py (play or
turning-point hysteresis loops, dT² or lagged temperature, two-constant creep, a supply drift with
a step, a sensitivity keyed to the load's sign, another cross term), one noise floor in size (the
RMS it adds to that component's cubic-fit residual = Table 17's cubic σ of it), on several
components of both balances. Expected: that family named and no other, and σ after within 15 % of
the σ the same campaign has without the effect (the same seed draws the same noise). Two effects
outside every family must come out as `unexplained`, with nothing adopted.
"""

import numpy as np
import pytest

from balance_calib.diagnosis import diagnose
from balance_calib.reduction import LoadPoints, reduce_points, retare_with_model
from balance_calib.simulation.diagnosis_rates import (
    calibrated_parameter,
    shape_effects,
    shape_family,
    simulate_reduction,
)

CASES = [
    ('lmc6522', 'temperature_dt2', 'FZ'),
    ('b660h', 'temperature_lagged', 'MY'),
    ('lmc6522', 'hysteresis_play', 'MX'),
    ('b660h', 'hysteresis_turning', 'FZ'),
    ('lmc6522', 'creep_two_constants', 'FX'),
    ('b660h', 'creep_two_constants', 'MZ'),
    ('lmc6522', 'excitation_steps', 'MY'),
    ('b660h', 'excitation_steps', 'FX'),
    ('lmc6522', 'bidirectional_load_sign', 'FY'),
    ('b660h', 'bidirectional_load_sign', 'MZ'),
    ('lmc6522', 'cross_terms_other', 'MZ'),
    ('b660h', 'zero_drift', 'MX'),
]
SEEDS = (2000, 2001)


def _campaign(balance, shape, component, seed, noise_floors=1.0):
    parameter = calibrated_parameter(balance, shape, noise_floors, component)
    effects, estimate = shape_effects(shape, parameter, component)
    return simulate_reduction(
        balance_config(balance),
        effects,
        seed=seed,
        estimate_body_weight=estimate,
        samples_per_point=8,
        with_scatter=True,
    )


def balance_config(name):
    from balance_calib.config import load_balance_config

    return load_balance_config(name)


@pytest.mark.parametrize('balance, shape, component', CASES)
def test_an_effect_in_another_shape_is_named_alone_and_sigma_returns_to_the_clean_one(
    balance, shape, component
):
    config = balance_config(balance)
    family = shape_family(shape)
    for seed in SEEDS:
        reduction, scatter = _campaign(balance, shape, component, seed)
        result = diagnose(reduction, config, **scatter)
        assert result.effect_names == (family,), (
            seed,
            [e.evidence for e in result.effects],
            [u.evidence for u in result.unexplained],
        )
        assert component in result.effects[0].components
        clean_reduction, clean_scatter = simulate_reduction(
            config, seed=seed, samples_per_point=8, with_scatter=True
        )
        clean = diagnose(clean_reduction, config, **clean_scatter)
        assert clean.effects == ()
        before, after = (
            result.sigma_pct_fs['before'][component],
            result.sigma_pct_fs['after'][component],
        )
        floor = clean.sigma_pct_fs['before'][component]
        assert before > 1.2 * floor  # the effect was really there
        assert after <= 1.15 * floor, (seed, after / floor)
        assert (
            result.sigma_pct_fs_crossval['after'][component]
            <= 1.2 * clean.sigma_pct_fs_crossval['before'][component]
        )


@pytest.mark.parametrize(
    'balance, shape, component',
    [
        ('lmc6522', 'outside_dead_band', 'FY'),
        ('b660h', 'outside_dead_band', 'MX'),
        ('lmc6522', 'outside_gravity_time', 'MY'),
        ('b660h', 'outside_gravity_time', 'MZ'),
    ],
)
def test_an_effect_outside_every_family_is_unexplained_and_nothing_is_adopted(
    balance, shape, component
):
    config = balance_config(balance)
    for seed in SEEDS:
        reduction, scatter = _campaign(balance, shape, component, seed)
        result = diagnose(reduction, config, **scatter)
        assert result.effects == (), (seed, [e.evidence for e in result.effects])
        assert [u.components for u in result.unexplained] == [(component,)], [
            u.evidence for u in result.unexplained
        ]
        entry = result.unexplained[0].to_report()
        assert set(entry) == {'components', 'evidence', 'tracks', 'sigma_pct_fs'}
        assert 'the repeatability' in entry['evidence'] and entry['sigma_pct_fs'][component] > 0
        assert result.adopted.term_names == result.base_fit.term_names


def _rotated_about_x(gravity, degrees):
    a = np.radians(degrees)
    rotation = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    return np.asarray(gravity) @ rotation.T


def test_a_calibration_body_rolled_from_its_declared_orientation_is_a_warning(lmc6522):
    """The body truly hangs 0.66° rolled: the simulated gravity is rotated, the declared one
    not.
    """
    from dataclasses import replace

    from balance_calib.fit.least_squares import fit_model
    from balance_calib.model.tm663 import tm663_terms
    from balance_calib.simulation.balance_sim import (
        simulate_campaign,
        SimulationSettings,
        table17_noise,
    )

    settings = SimulationSettings(noise_sigma_pct_fs=table17_noise(lmc6522), seed=3)
    true_schedule = lmc6522.schedule
    rolled = replace(
        lmc6522,
        gravity_directions={
            k: _rotated_about_x(v, 0.66) for k, v in lmc6522.gravity_directions.items()
        },
    )
    campaign = simulate_campaign(rolled, settings=settings, schedule=true_schedule)
    means, times, temperatures = campaign.point_means()
    declared = np.array([lmc6522.gravity(i) for i in campaign.orientation])
    points = LoadPoints(
        campaign.point,
        means,
        times,
        temperatures,
        campaign.orientation,
        declared,
        campaign.applied_loads,
    )
    reduction = reduce_points(points, lmc6522)
    first = fit_model(
        tm663_terms('cubic', lmc6522.bridge_outputs),
        reduction.corrected.bridge_outputs_mv,
        reduction.corrected.loads,
        name='cubic',
        components=lmc6522.components,
        inputs=lmc6522.bridge_outputs,
        on_unexcited='drop',
    )
    result = diagnose(retare_with_model(reduction, first.model), lmc6522)
    assert abs(result.lack_of_fit.roll_deg) == pytest.approx(0.66, abs=0.3)
    assert any('rolled by' in w for w in result.warnings), result.warnings
