"""The directed leftover tests (lack_of_fit.slow_structure_bases): a component's own load shape
changing with time, with the gravity vector, or with both, left in the residual after the adopted
model.

Unit part: the partial F-tests on a synthetic problem with independent noise keep their level and
find a planted structure; campaign part: a bridge curvature that grows in time and flips with
gravity (simulation/effects.py GravityTimeNonlinearity, outside every family) on the force
components at one noise floor, where the omnibus lack-of-fit test alone lacks power (F_X) or a
plain temperature zero shift absorbed part of it (F_Y, F_Z: hung weights always load along
gravity, so only its growth in time shows): `unexplained`, nothing adopted.
"""

import numpy as np
import pytest

from balance_calib.diagnosis import diagnose
from balance_calib.diagnosis.lack_of_fit import directed_lack_of_fit, slow_structure_bases
from balance_calib.simulation.diagnosis_rates import (
    calibrated_parameter,
    shape_effects,
    simulate_reduction,
)


class _Plain:
    """The few members of search_state._Problem the directed test uses, without whitening (iid
    noise).
    """

    def __init__(self, columns: dict, loads):
        self.table = columns
        self.loads_white = np.asarray(loads, float)[:, None]

    def white_columns(self, names):
        return np.column_stack([self.table[n] for n in names])

    def whiten(self, values):
        return np.asarray(values, float)


def _layout(rng, n=240):
    times = np.sort(rng.uniform(0.0, 8 * 3600.0, n))
    gravity = np.zeros((n, 3))
    axis = rng.integers(0, 4, n)  # body on ±Y, ±Z in turn
    gravity[np.arange(n), 1 + axis % 2] = np.where(axis < 2, 1.0, -1.0)
    load = rng.choice([-1.0, -0.5, 0.5, 1.0], n) * 1000.0
    base = {'1': np.ones(n), 'L': load, 'L2': load**2, 'L3': load**3}
    return times, gravity, load, base


def test_the_bases_are_the_load_shape_times_time_gravity_and_both(rng):
    times, gravity, load, _ = _layout(rng)
    bases = slow_structure_bases(times, gravity, load)
    assert list(bases) == ['time', 'gravity direction', 'time × gravity direction']
    t = (times - times.mean()) / np.ptp(times)
    x = load / np.max(np.abs(load))
    assert np.allclose(bases['time'], t[:, None] * np.column_stack([x, x**2, x * np.abs(x)]))
    # g_x never varies here: only g_y and g_z enter, three columns each
    assert bases['gravity direction'].shape == (len(times), 6)
    assert np.allclose(bases['time × gravity direction'], t[:, None] * bases['gravity direction'])
    # a single orientation: time only
    assert list(slow_structure_bases(times, np.tile([0.0, 0.0, -1.0], (len(times), 1)), load)) == [
        'time'
    ]


def test_on_independent_noise_the_directed_tests_keep_their_level(rng):
    """Partial F-tests are exact for iid Gaussian noise: Bonferroni over the three bases at α =
    0.05 rejects at most 5 % of noise draws (at least α/3 ≈ 1.7 %: one basis alone rejects that
    often).
    """
    times, gravity, load, base = _layout(rng)
    bases = slow_structure_bases(times, gravity, load)
    draws, rejected = 400, 0
    for _ in range(draws):
        problem = _Plain(base, 3.0 + 2e-3 * load + rng.normal(size=len(load)))
        rejected += (
            directed_lack_of_fit(problem, 0, list(base), list(base), bases, 0.05, len(bases))
            is not None
        )
    bound = 3.0 * np.sqrt(0.05 * 0.95 / draws)
    assert 0.05 / 3 - bound < rejected / draws <= 0.05 + bound, rejected


def test_a_load_curvature_growing_in_time_with_gravity_is_found(rng):
    times, gravity, load, base = _layout(rng)
    bases = slow_structure_bases(times, gravity, load)
    t = (times - times.mean()) / np.ptp(times)
    x = load / np.max(np.abs(load))
    planted = t * gravity[:, 2] * x * np.abs(x)
    planted *= np.sqrt(80.0) / np.linalg.norm(planted)  # non-centrality 80 at unit noise
    noise = rng.normal(size=len(load))
    problem = _Plain({**base, 'planted': planted}, 2e-3 * load + planted + noise)
    name, p, explained = directed_lack_of_fit(
        problem, 0, list(base), list(base), bases, 1e-3, 6 * len(bases)
    )
    assert name == 'time × gravity direction' and p < 1e-6
    assert explained == 0.0  # the tested terms are the base terms: nothing of it explained
    # a model that has the structure leaves none of it
    assert (
        directed_lack_of_fit(
            problem, 0, list(base) + ['planted'], list(base), bases, 1e-3, 6 * len(bases)
        )
        is None
    )


# Force components at one noise floor; each of these came out wrong before the directed tests:
# nothing flagged (F_X: whitened variance / repeatability² 1.2-1.4, omnibus p 5e-4 ... 0.03),
# `temperature` (plain dT) adopted (F_Y, F_Z), or temperature + bidirectional (F_Z).
@pytest.mark.parametrize(
    'balance, component, seed',
    [
        ('lmc6522', 'FX', 2006),
        ('lmc6522', 'FZ', 2005),
        ('b660h', 'FY', 2004),
        ('b660h', 'FZ', 2002),
    ],
)
def test_gravity_time_curvature_on_a_force_is_unexplained_and_nothing_is_adopted(
    balance, component, seed, request
):
    config = request.getfixturevalue(balance)
    effects, estimate = shape_effects(
        'outside_gravity_time',
        calibrated_parameter(balance, 'outside_gravity_time', 1.0, component),
        component,
    )
    reduction, scatter = simulate_reduction(
        config,
        effects,
        seed=seed,
        estimate_body_weight=estimate,
        samples_per_point=8,
        with_scatter=True,
    )
    result = diagnose(reduction, config, **scatter)
    assert result.effects == (), [e.evidence for e in result.effects]
    assert [u.components for u in result.unexplained] == [(component,)], [
        u.evidence for u in result.unexplained
    ]
    assert 'directed test' in result.unexplained[0].evidence
    assert result.adopted.term_names == result.base_fit.term_names
    # the omnibus test and every plain tracker miss it: the basis is what it follows
    if component == 'FX':
        entry = result.unexplained[0]
        assert entry.tracks == 'load FX × time × gravity direction'
        shown = np.isfinite(entry.tracks_values)
        assert np.corrcoef(entry.tracks_values[shown], entry.residual[shown])[0, 1] > 0.3
