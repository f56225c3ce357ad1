"""The statistics under the residual diagnosis: PRESS, forward selection, zero-point whitening."""

import importlib

import numpy as np
import pytest

from balance_calib.diagnosis.candidates import load_directions, refer_to_zero_points
from balance_calib.diagnosis.statistics import (
    fit_columns,
    forward_select,
    partial_f,
    ZeroPointWhitening,
)
from balance_calib.simulation.balance_sim import _direction_history
from balance_calib.simulation.diagnosis_rates import simulate_reduction
from balance_calib.tare.calibration_body import tare_loads


def test_press_residuals_are_the_leave_one_out_residuals(rng):
    design = np.column_stack([np.ones(40), rng.normal(size=(40, 4))])
    target = design @ rng.normal(size=5) + rng.normal(size=40)
    fit = fit_columns(design, target)
    brute = []
    for i in range(40):
        keep = np.arange(40) != i
        others = fit_columns(design[keep], target[keep])
        brute.append(target[i] - design[i] @ others.coefficients)
    assert np.allclose(fit.press_residuals, brute, rtol=1e-9, atol=1e-12)


def test_forward_selection_takes_the_planted_term_and_stops_at_noise(rng):
    base = np.column_stack([np.ones(200), rng.normal(size=(200, 3))])
    candidates = rng.normal(size=(200, 30))
    target = base @ [1.0, 2.0, -1.0, 0.5] + 0.4 * candidates[:, 7] + 0.1 * rng.normal(size=200)
    selection = forward_select(
        fit_columns(base, target),
        candidates,
        [(j,) for j in range(30)],
        alpha_per_test=0.01 / 30,
        max_groups=5,
    )
    assert selection.groups == (7,)
    f_value, p_value = partial_f(selection.rss_before, selection.steps[0].rss_after, 1, 200 - 5)
    assert f_value > 100 and p_value < 1e-20


def test_whitening_keeps_the_f_test_at_its_level_under_zero_point_noise(lmc6522):
    """Zero points (§5(4)) share their noise with a whole block: without whitening, a slow
    regressor passes a 5 % F-test on pure noise a fifth of the time or more.
    """
    reduction = simulate_reduction(lmc6522, noise_scale=0.0)
    points = reduction.points
    n = len(points.label)
    whiten = ZeroPointWhitening.for_points(
        points.times_s, points.is_zero_point, points.orientation
    )
    referring = refer_to_zero_points(
        np.eye(n), points.times_s, points.is_zero_point, points.orientation
    )
    base = np.column_stack([np.ones(n), reduction.corrected.bridge_outputs_mv])
    slow = np.sin(2 * np.pi * points.times_s / 20000.0)
    augmented = np.column_stack([base, slow])
    rng = np.random.default_rng(5)
    rejected_plain = rejected_white = 0
    draws = 300
    for _ in range(draws):
        noise = referring @ rng.normal(size=n)
        for design_pair, counter in (
            ((base, augmented), 'plain'),
            ((whiten(base), whiten(augmented)), 'white'),
        ):
            y = noise if counter == 'plain' else whiten(noise)
            small, large = fit_columns(design_pair[0], y), fit_columns(design_pair[1], y)
            rejected = partial_f(small.rss, large.rss, 1, large.dof)[1] < 0.05
            if counter == 'plain':
                rejected_plain += rejected
            else:
                rejected_white += rejected
    assert rejected_white / draws < 0.10
    assert rejected_plain / draws > 0.12  # the reason the whitening is there


def test_load_directions_follow_the_simulated_load_history(lmc6522):
    gravity = np.array([lmc6522.gravity(i) for i in lmc6522.schedule.orientation])
    loads = lmc6522.schedule.loads + tare_loads(lmc6522.calibration_body, gravity)
    times = np.arange(len(loads)) * 90.0
    assert np.array_equal(
        load_directions(loads, times, lmc6522.capacity), _direction_history(loads)
    )
    # the order is time, not row order
    shuffled = np.random.default_rng(1).permutation(len(loads))
    assert np.array_equal(
        load_directions(loads[shuffled], times[shuffled], lmc6522.capacity),
        _direction_history(loads)[shuffled],
    )


def test_variables_referred_to_zero_points_vanish_there_and_keep_fast_changes(lmc6522):
    reduction = simulate_reduction(lmc6522, noise_scale=0.0)
    points, zero = reduction.points, reduction.zero
    ramp = points.times_s / 3600.0
    referred = refer_to_zero_points(
        np.column_stack([ramp, np.sin(points.times_s / 50.0)]),
        points.times_s,
        points.is_zero_point,
        points.orientation,
    )
    assert np.all(referred[points.is_zero_point] == 0.0)
    # a straight line in time is what two brackets follow: it survives only where a block has one
    one_bracket = ((zero.before < 0) | (zero.after < 0)) & ~points.is_zero_point
    assert np.array_equal(np.abs(referred[:, 0]) > 1e-9, one_bracket)
    assert np.std(referred[~points.is_zero_point, 1]) > 0.3


def test_forward_selection_tests_each_group_at_its_own_level(rng):
    """Weighted Bonferroni (small effects): a group passes at its own level; the planted
    term's p sits between a flat and a weighted level, so only the weighted split takes it, and the
    stronger term, tested at a level it does not reach, is not taken instead.
    """
    n = 200
    base = np.column_stack([np.ones(n), rng.normal(size=(n, 2))])
    candidates = rng.normal(size=(n, 10))
    noise = rng.normal(size=n)
    target = base @ [1.0, 0.5, -0.3] + 0.25 * candidates[:, 3] + 0.3 * candidates[:, 6] + noise
    fit = fit_columns(base, target)
    groups = [(j,) for j in range(10)]
    p = {
        j: partial_f(
            fit.rss, fit_columns(np.column_stack([base, candidates[:, j]]), target).rss, 1, n - 4
        )[1]
        for j in (3, 6)
    }
    weak, strong = sorted(p, key=p.get, reverse=True)
    assert p[strong] < p[weak] < 1e-3
    flat = np.full(10, p[strong] / 10)
    assert forward_select(fit, candidates, groups, alpha_per_test=flat, max_groups=1).steps == ()
    levels = np.full(10, p[strong] / 100)
    levels[weak] = 2 * p[weak]
    selection = forward_select(fit, candidates, groups, alpha_per_test=levels, max_groups=1)
    assert selection.groups == (weak,)
    assert np.isclose(selection.steps[0].p_value, p[weak], rtol=1e-9)


def test_temperature_levels_favour_the_own_bridge_and_keep_the_family_level(monkeypatch, b660h):
    """The temperature family's level over its groups, per component: the shares of
    DiagnosisSettings.temperature_level_shares (own bridge first order, second order, the other
    bridges), summing to the flat Bonferroni total; zero drift's levels sum to it too.
    """
    diagnose_module = importlib.import_module('balance_calib.diagnosis.diagnose')
    families_module = importlib.import_module('balance_calib.diagnosis.families')

    seen = []
    original = families_module.forward_select

    def spy(fit, candidates, groups, *, alpha_per_test, max_groups, **kw):
        seen.append((len(groups), np.broadcast_to(alpha_per_test, (len(groups),)).copy()))
        return original(
            fit, candidates, groups, alpha_per_test=alpha_per_test, max_groups=max_groups, **kw
        )

    family_of = []
    original_examine = diagnose_module._examine_family

    def examine(family, *args, **kw):
        start = len(seen)
        out = original_examine(family, *args, **kw)
        family_of.extend([family.name] * (len(seen) - start))
        return out

    monkeypatch.setattr(families_module, 'forward_select', spy)
    monkeypatch.setattr(diagnose_module, '_examine_family', examine)
    reduction, scatter = simulate_reduction(b660h, seed=7, samples_per_point=8, with_scatter=True)
    diagnose_module.diagnose(reduction, b660h, **scatter)
    temperature = [lv for (n, lv), f in zip(seen, family_of) if f == 'temperature']
    drift = [lv for (n, lv), f in zip(seen, family_of) if f == 'zero_drift']
    assert len(temperature) == 6 and drift
    totals = {round(float(np.sum(lv)), 15) for lv in temperature + drift}
    assert len(totals) == 1  # every component's family level is the same total
    settings = diagnose_module.DiagnosisSettings()
    own_first, own_second, others = settings.temperature_level_shares
    for levels in temperature:
        total = np.sum(levels)
        ranked = np.sort(levels)[::-1] / total
        # dT and dT·V_own share the first-order part, dT² and dT²·V_own the second order
        assert np.allclose(ranked[:2], own_first / 2) and np.allclose(ranked[2:4], own_second / 2)
        assert np.allclose(ranked[4:], others / (len(levels) - 4))


@pytest.mark.parametrize(
    'field, value',
    [
        ('alpha', 0.0),
        ('alpha_lack_of_fit', 1.5),
        ('min_explained', -0.1),
        ('max_rounds', 0),
        ('drift_oversampling', float('nan')),
        ('drift_spectrum_exponent', float('inf')),
        ('temperature_level_shares', (0.5, -0.1, 0.6)),
        ('temperature_level_shares', (0.0, 0.0, 0.0)),
        ('effects', ('temperature', 'gremlins')),
    ],
)
def test_settings_out_of_range_are_refused_naming_the_setting(field, value):
    settings_class = importlib.import_module('balance_calib.diagnosis.diagnose').DiagnosisSettings
    with pytest.raises(ValueError, match=f'DiagnosisSettings.{field} ='):
        settings_class(**{field: value})
    settings_class()  # the defaults are in range
