"""The shape of a sign asymmetry: the bidirectional family offers a one-sided curvature
as a pair (x|x| with x²|x|, V|V| with V²|V|), drops the pair's term the points do not resolve,
and completes a shape whose fit moves with the gravity direction (families._settle_sign_shape).

The campaigns are the physics generator's (test/diagnosis_physics.py: a curvature |x|^2.5 on
negative loads, not a term of the family), one noise floor in size, on seeds where each step
decides the outcome; the clean campaign of the same seed is the σ floor.
"""

from functools import lru_cache

import diagnosis_physics as physics
import pytest

from balance_calib.config import load_balance_config
from balance_calib.diagnosis import diagnose
from balance_calib.diagnosis.candidates import bidirectional_family, canonical
from balance_calib.simulation.diagnosis_rates import run_one, simulate_reduction

OUTPUTS = ('FXV', 'FYV', 'FZV', 'MXV', 'MYV', 'MZV')
COMPONENTS = ('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ')


@lru_cache(maxsize=None)
def _diagnosed(balance: str, bridges: str, seed: int, effect: bool = True):
    config = load_balance_config(balance)
    effects = [physics.scaled(balance, 'negative_curvature', bridges)] if effect else []
    reduction, scatter = simulate_reduction(
        config, effects, seed=seed, samples_per_point=8, with_scatter=True
    )
    return diagnose(reduction, config, **scatter)


def _ratios(balance: str, bridges: str, seed: int, component: str) -> tuple[float, float]:
    """(in-sample, cross-validated) σ after over the clean campaign's σ on component."""
    found, clean = _diagnosed(balance, bridges, seed), _diagnosed(balance, bridges, seed, False)
    return (
        found.sigma_pct_fs['after'][component] / clean.sigma_pct_fs['before'][component],
        found.sigma_pct_fs_crossval['after'][component]
        / clean.sigma_pct_fs_crossval['before'][component],
    )


def test_a_one_sided_curvature_is_offered_as_a_pair_and_a_slope_alone():
    groups = set(bidirectional_family(OUTPUTS, COMPONENTS).groups)
    for v, c in zip(OUTPUTS, COMPONENTS):
        assert (f'|{v}|',) in groups and (f'absload_{c}',) in groups
        assert (canonical(f'{v}*|{v}|'), canonical(f'{v}^2*|{v}|')) in groups
        assert (f'absload2_{c}', f'absload3_{c}') in groups
    assert len(groups) == 4 * len(OUTPUTS)


def test_a_curvature_pair_that_moves_with_gravity_is_completed_by_the_output_keyed_pair():
    # LMC6522 F_Y, curvature on every bridge, seed 3003: the load-keyed pair alone fits with
    # coefficients that change with the gravity direction (the body shifts F_Y by 14 % of
    # capacity between orientations) and F_Y was left unexplained, σ 1.6x; the single x²|x| of
    # the family before pairs left σ 1.18x
    result = _diagnosed('lmc6522', 'all', 3003)
    assert result.effect_names == ('bidirectional',) and not result.unexplained
    terms = set(result.effects[0].terms_by_component['FY'])
    assert {'absload2_FY', 'absload3_FY'} <= terms
    assert {canonical('FYV*|FYV|'), canonical('FYV^2*|FYV|')} <= terms
    sigma, crossval = _ratios('lmc6522', 'all', 3003, 'FY')
    assert sigma <= 1.15 and crossval <= 1.15, (sigma, crossval)


def test_a_pair_term_the_points_do_not_resolve_is_dropped():
    # B660H F_Z, curvature on that bridge, seed 3007: two points beyond -0.8 capacity carry the
    # negative side; x|x| beside x²|x| has p 0.2 and the pair's leverage (0.89) made the
    # cross-validated σ 1.16x
    result = _diagnosed('b660h', 'FZ', 3007)
    assert result.effect_names == ('bidirectional',) and not result.unexplained
    assert len(result.effects[0].terms_by_component['FZ']) == 1
    sigma, crossval = _ratios('b660h', 'FZ', 3007, 'FZ')
    assert sigma <= 1.15 and crossval <= 1.15, (sigma, crossval)


@pytest.mark.parametrize('seed', [2001, 2007])
def test_the_other_loads_curvature_is_not_offered_to_an_effect_outside_every_family(seed):
    # A load leaking into the neighbouring bridge beyond a 40 % dead band (simulation/effects.py),
    # 2x the floor on LMC6522 F_Y: with the other loads' curvature pairs offered at the
    # lack-of-fit level they fitted part of it, and a tare was adopted beside (these seeds);
    # nothing may be named for it
    outcome = run_one('lmc6522', 'outside_dead_band', 2.0, seed, 'FY', 'forces')
    assert outcome.found == () and 'FY' in outcome.unexplained, outcome
