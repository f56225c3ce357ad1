"""Hysteresis or sign asymmetry decided by the direction contrast (deliver 1;
diagnosis/loop_or_sign.py): a residual whose falling branch sits above its rising one at equal
load is a loop and bidirectional yields there; a residual the same on both branches is no loop and
hysteresis yields; with too few pairs, or a contrast significant but small, it decides nothing.

The residuals are built by hand: 40 pairs of points at equal load, noise σ = 1 (any unit), a loop
of half-width a (falling +a, rising -a: contrast 2a, ratio mean(c²)/(2σ²) = 1 + 2a²) or a sign
step (the same offset on both branches of a pair: contrast 0, ratio ≈ 1).
"""

import diagnosis_physics as physics
import numpy as np
import pytest

from balance_calib.config import load_balance_config
from balance_calib.diagnosis import diagnose
from balance_calib.diagnosis.loop_or_sign import (
    beside_its_partner,
    components_to_drop,
    direction_pairs,
    LOOP_RATIO,
    MIN_DIRECTION_PAIRS,
    shows_loop,
)
from balance_calib.simulation.diagnosis_rates import simulate_reduction

PAIRS = [(2 * i, 2 * i + 1) for i in range(40)]  # (falling, rising)


def _residual(loop_half_width: float, sign_offset: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    branch = np.tile([1.0, -1.0], 40)  # falling, rising
    load_sign = np.repeat(rng.choice([-1.0, 1.0], 40), 2)
    return loop_half_width * branch + sign_offset * (load_sign > 0) + rng.normal(0, 1, 80)


@pytest.mark.parametrize('seed', range(5))
def test_a_loop_shows_and_a_sign_step_does_not(seed):
    # a = 1.5: ratio 1 + 2 · 2.25 = 5.5 > LOOP_RATIO; a sign step of 3 σ: ratio ≈ 1
    assert shows_loop(_residual(1.5, 0.0, seed), PAIRS, 1.0) is True
    assert shows_loop(_residual(0.0, 3.0, seed), PAIRS, 1.0) is False
    assert shows_loop(_residual(0.0, 0.0, seed), PAIRS, 1.0) is False
    # a = 0.8: ratio ≈ 2.3, significant with 40 pairs but below LOOP_RATIO: a small loop, left
    # to the selection (neither adopted nor refused by the contrast)
    assert shows_loop(_residual(0.8, 0.0, seed), PAIRS, 1.0) is None
    assert shows_loop(_residual(1.5, 0.0, seed), PAIRS[: MIN_DIRECTION_PAIRS - 1], 1.0) is None
    assert LOOP_RATIO < 1 + 2 * 1.5**2


def test_each_family_keeps_only_what_its_contrast_explains():
    loop, step, few = _residual(1.5, 0.0, 0), _residual(0.0, 3.0, 1), _residual(1.5, 0.0, 2)
    current = [loop, step, few]
    noise = np.random.default_rng(9).normal(0, 1, 80)  # what a good fit leaves
    after = {0: noise, 1: noise, 2: noise}
    pairs = [PAIRS, PAIRS, PAIRS[:3]]
    loop_drop, sign_drop = components_to_drop(after, after, current, pairs)
    assert loop_drop == {1}  # no branch difference: not a loop
    assert sign_drop == {0}  # a branch difference: the loop first
    # bidirectional not offered on the loop's component: nothing to yield
    loop_drop, sign_drop = components_to_drop(after, {1: noise}, current, pairs)
    assert loop_drop == {1} and sign_drop == set()


def test_the_schedule_pairs_are_equal_loads_on_opposite_branches():
    config = load_balance_config('lmc6522')
    reduction, scatter = simulate_reduction(
        config,
        [physics.scaled('lmc6522', 'sign_step', 'MY')],
        seed=3000,
        samples_per_point=8,
        with_scatter=True,
    )
    diagnosis = diagnose(reduction, config, **scatter)
    assert diagnosis.effect_names == ('bidirectional',)
    pairs = direction_pairs(
        diagnosis.corrected, diagnosis.orientation, diagnosis.load_direction, diagnosis.capacity
    )
    k = diagnosis.components.index('MY')
    assert len(pairs[k]) >= MIN_DIRECTION_PAIRS and len(pairs[0]) == 0  # none on F_X here
    direction = diagnosis.load_direction[:, k]
    for falling, rising in pairs[k]:
        assert direction[falling] == -1 and direction[rising] == 1
    # the sign step leaves no direction contrast on M_Y against its own residual's variance
    variance = float(np.mean(diagnosis.residuals_after[:, k] ** 2))
    assert shows_loop(diagnosis.residuals_before[:, k], pairs[k], variance) is False


# A loop and a sign step on one bridge (LMC6522 M_Y, one floor each). The direction
# contrast shows the loop, which is adopted first; what is left of the step (|x| beside the loop,
# p ~1e-11, 0.0092 % FS removed) fell under the search's 0.01 % FS size gate, and the leftovers,
# finding M_Y still lacking fit with the loop 62 % of it, named nothing (seeds 3000 and 3002:
# `unexplained` alone). Beside its partner on a component still lacking fit, a family is judged
# without the size gate: both named, nothing unexplained.
@pytest.mark.parametrize('seed', [3000, 3002])
def test_a_loop_and_a_sign_step_on_one_bridge_are_both_named(seed):
    config = load_balance_config('lmc6522')
    effects = [physics.scaled('lmc6522', s, 'MY') for s in ('preisach', 'sign_step')]
    reduction, scatter = simulate_reduction(
        config, effects, seed=seed, samples_per_point=8, with_scatter=True
    )
    diagnosis = diagnose(reduction, config, **scatter)
    assert set(diagnosis.effect_names) == {'hysteresis', 'bidirectional'}, diagnosis.effect_names
    for effect in diagnosis.effects:
        assert effect.components == ('MY',)
    assert not diagnosis.unexplained


def test_only_the_partner_of_an_adopted_family_waives_the_size_gate():
    from types import SimpleNamespace

    def entry(family, components):
        return {'candidate': SimpleNamespace(family=family, components=dict.fromkeys(components))}

    effects = [entry('hysteresis', [1, 4]), entry('temperature', [0])]
    fits = ['fit0', 'fit1', 'fit2', 'fit3', 'fit4', 'fit5']
    lacking = {4}  # component 1 fits within its repeatability: nothing left to explain there

    def fitted_well(k, fit):
        assert fit == fits[k]
        return k not in lacking

    assert beside_its_partner('bidirectional', effects, fits, fitted_well) == {4}
    assert beside_its_partner('hysteresis', effects, fits, fitted_well) == set()
    assert beside_its_partner('creep', effects, fits, fitted_well) == set()
    effects = [entry('bidirectional', [0, 4])]
    assert beside_its_partner('hysteresis', effects, fits, lambda k, f: False) == {0, 4}
