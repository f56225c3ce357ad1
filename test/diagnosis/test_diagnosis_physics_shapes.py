"""Hysteresis loops and sign asymmetries written from their physics (test/diagnosis_physics.py,
not from the families' terms), one noise floor in size (the RMS they add to that component's
cubic-fit residual = Table 17's cubic σ): the right family named first and alone, nothing
unexplained, σ after (in-sample and cross-validated) within 15 % of the clean campaign of the
same seed. The fast path runs one seed per cell; the slow test the ten seeds of
the issue's ≥ 9/10.

Only the cells that meet the target are here (all cells: tools/physics_cells.py, its table in
docs/results.md). Masing and re-seating on every bridge of LMC6522 (σ 1.17x / 1.18x before), the
Bouc-Wen loop and the re-seating joint on B660H's F_Z (1.20x, 1.18x) came in once the tare was
re-read through the adopted model (retare._retare). Negative curvature on every bridge of
LMC6522 (9/10 and cross-validated σ up to 1.21x before) came in with the one-sided curvature
offered as a pair and its shape settled (families._settle_sign_shape,
test_diagnosis_sign_shape.py). Masing on B660H's F_Z (one seed of ten at a cross-validated σ of
1.16x before) came in with the widest play's loop alone, without its first-loading curve
(candidates.play_loop). Masing, Bouc-Wen and re-seating on every bridge of B660H (8, 8 and 7/10
before) came in once the leftovers judged the tare re-read through the adopted model and a loop's
shape was settled at the lack-of-fit level (retare._retare_passes, _completed_at_lack_of_fit).
Negative curvature on every bridge of B660H (8/10 before) came in once the cross terms were no
longer offered where a specific family left no lack of fit (seed 3004: MYV*MZV² on M_X,
search._cross_terms_only_where_lacking) and a curvature pair reduced for leverage was completed
after the tare's re-read where that lowers PRESS (F_Z cross-validated 1.18x -> 1.04x,
retare._complete_curvature_pairs).
The measured misses: load-path friction 0-5/10 (on this schedule every
loaded point is reached rising, so it is mostly a sign step plus a sensitivity, which no family
holds with the stick band); Preisach on every bridge of LMC6522 7/10 (M_X's play terms fit 70-72 %
of its excess and the leftovers drop them; σ 1.43x there), on B660H's F_Z 4/10 (σ up to 1.40x)
and on every bridge of B660H 8/10; the one negative-curvature campaign of B660H left (seed 3003:
M_X's clean campaign already lacks fit, p 0.003, and with the curvature fitted p 1.4e-4 is
left, below the leftovers' 1.7e-4, so the family is dropped there).
"""

from functools import lru_cache

import diagnosis_physics as physics
import pytest

from balance_calib.config import load_balance_config
from balance_calib.diagnosis import diagnose
from balance_calib.simulation.diagnosis_rates import simulate_reduction

CELLS = [
    ('lmc6522', 'preisach', 'MY'),
    ('lmc6522', 'masing', 'MY'),
    ('lmc6522', 'bouc_wen', 'MY'),
    ('lmc6522', 'reseating', 'MY'),
    ('lmc6522', 'sign_step', 'MY'),
    ('lmc6522', 'negative_curvature', 'MY'),
    ('lmc6522', 'bouc_wen', 'all'),
    ('lmc6522', 'masing', 'all'),
    ('lmc6522', 'reseating', 'all'),
    ('lmc6522', 'sign_step', 'all'),
    ('lmc6522', 'negative_curvature', 'all'),
    ('b660h', 'masing', 'FZ'),
    ('b660h', 'bouc_wen', 'FZ'),
    ('b660h', 'reseating', 'FZ'),
    ('b660h', 'sign_step', 'FZ'),
    ('b660h', 'masing', 'all'),
    ('b660h', 'bouc_wen', 'all'),
    ('b660h', 'reseating', 'all'),
    ('b660h', 'sign_step', 'all'),
    ('b660h', 'negative_curvature', 'all'),
    ('b660h', 'negative_curvature', 'FZ'),
]
SEEDS = tuple(range(3000, 3010))


@lru_cache(maxsize=None)
def _clean(balance, seed):
    config = load_balance_config(balance)
    reduction, scatter = simulate_reduction(
        config, seed=seed, samples_per_point=8, with_scatter=True
    )
    return diagnose(reduction, config, **scatter)


def _outcome(balance, shape, bridges, seed):
    """(right, worst σ after / clean σ, worst cross-validated ratio) over the affected
    components.
    """
    config = load_balance_config(balance)
    effect = physics.scaled(balance, shape, bridges)
    reduction, scatter = simulate_reduction(
        config, [effect], seed=seed, samples_per_point=8, with_scatter=True
    )
    result = diagnose(reduction, config, **scatter)
    clean = _clean(balance, seed)
    assert clean.effects == () and clean.unexplained == () and not clean.warnings
    components = config.components if bridges == 'all' else (bridges,)
    sigma = max(
        result.sigma_pct_fs['after'][c] / clean.sigma_pct_fs['before'][c] for c in components
    )
    crossval = max(
        result.sigma_pct_fs_crossval['after'][c] / clean.sigma_pct_fs_crossval['before'][c]
        for c in components
    )
    right = result.effect_names == (physics.FAMILY[shape],) and not result.unexplained
    return (
        right,
        sigma,
        crossval,
        (result.effect_names, [u.components for u in result.unexplained]),
    )


@pytest.mark.parametrize('balance, shape, bridges', CELLS)
def test_a_physical_loop_or_sign_asymmetry_is_named_alone_one_seed(balance, shape, bridges):
    right, sigma, crossval, found = _outcome(balance, shape, bridges, SEEDS[0])
    assert right, found
    assert sigma <= 1.15 and crossval <= 1.15, (sigma, crossval)


@pytest.mark.slow
@pytest.mark.parametrize('balance, shape, bridges', CELLS)
def test_a_physical_loop_or_sign_asymmetry_is_named_alone_in_nine_of_ten(balance, shape, bridges):
    outcomes = [_outcome(balance, shape, bridges, seed) for seed in SEEDS]
    assert sum(o[0] for o in outcomes) >= 9, [o[3] for o in outcomes]
    assert all(o[1] <= 1.15 and o[2] <= 1.15 for o in outcomes), [(o[1], o[2]) for o in outcomes]


def test_a_loop_term_that_moves_over_the_campaign_is_completed_by_a_second_play():
    """B660H, a Masing loop on every bridge, seed 3005: F_Y's own loop term alone is rejected by
    the Chow test (its coefficient differs between the campaign's halves); a second play keeps it
    (families._completed_while_moving). Without that step F_Y is left `unexplained` at 1.45x.
    """
    config = load_balance_config('b660h')
    effect = physics.scaled('b660h', 'masing', 'all')
    reduction, scatter = simulate_reduction(
        config, [effect], seed=3005, samples_per_point=8, with_scatter=True
    )
    result = diagnose(reduction, config, **scatter)
    assert result.effect_names == ('hysteresis',) and not result.unexplained
    (loop,) = result.effects
    assert len(loop.terms_by_component['FY']) >= 2, loop.terms_by_component


def _named_alone(balance, shape, bridges, seed):
    config = load_balance_config(balance)
    reduction, scatter = simulate_reduction(
        config,
        [physics.scaled(balance, shape, bridges)],
        seed=seed,
        samples_per_point=8,
        with_scatter=True,
    )
    return diagnose(reduction, config, **scatter)


def test_the_leftovers_judge_the_tare_reread_through_the_adopted_loop():
    """B660H, a Masing loop on every bridge, seed 3007: judged before the tare was re-read, F_Y's
    leftover (1.0x the repeatability, lack of fit p = 0.5) still held the bent tare's blocks, which
    the directed test took for F_Y's load shape changing with time (p = 0.001): `unexplained`.
    """
    result = _named_alone('b660h', 'masing', 'all', 3007)
    assert result.effect_names == ('hysteresis',), result.effect_names
    assert not result.unexplained, [u.evidence for u in result.unexplained]
    assert result.tare_reread


def test_a_loop_shape_is_settled_at_the_lack_of_fit_level():
    """B660H, a Bouc-Wen loop on every bridge, seed 3009: M_Z's first play alone leaves a
    cross-validated σ of 1.15x the clean floor; its second play, significant at the leftovers'
    level but not at the family's, takes it to about 1.09x.
    """
    result = _named_alone('b660h', 'bouc_wen', 'all', 3009)
    assert result.effect_names == ('hysteresis',) and not result.unexplained
    (loop,) = result.effects
    assert len(loop.terms_by_component['MZ']) >= 2, loop.terms_by_component
    floor = _clean('b660h', 3009).sigma_pct_fs_crossval['before']['MZ']
    assert result.sigma_pct_fs_crossval['after']['MZ'] / floor <= 1.12


def test_no_generic_family_where_the_specific_one_left_no_lack_of_fit():
    """B660H, a curvature on negative loads of every bridge, seed 3004: the bidirectional pair
    leaves M_X within its repeatability (lack of fit p about 0.35), yet MYV*MZV² passed the cross
    terms' level after it (p 2e-7; 9e-4 on the clean campaign): a generic family is not adopted
    where the specific one explains the structure.
    """
    result = _named_alone('b660h', 'negative_curvature', 'all', 3004)
    assert result.effect_names == ('bidirectional',), result.effect_names
    assert not result.unexplained, [u.evidence for u in result.unexplained]
    assert result.lack_of_fit.lack_of_fit_p['MX'] > 0.001 / 6, result.lack_of_fit.lack_of_fit_p


def test_a_curvature_pair_reduced_for_leverage_is_completed_after_the_reread():
    """Same campaign: F_Z's pair was cut to FZV²|FZV| for two far points' leverage before the tare
    was re-read; after it the pair predicts the points left out better (cross-validated σ 1.18x
    the clean floor with one term, about 1.04x with both).
    """
    result = _named_alone('b660h', 'negative_curvature', 'all', 3004)
    (effect,) = result.effects
    assert set(effect.terms_by_component['FZ']) == {'FZV*|FZV|', 'FZV^2*|FZV|'}, effect.terms
    assert 'added after the tare was re-read' in effect.evidence_by_component['FZ']
    floor = _clean('b660h', 3004).sigma_pct_fs_crossval['before']['FZ']
    assert result.sigma_pct_fs_crossval['after']['FZ'] / floor <= 1.12
