"""Residual diagnosis on simulated campaigns with one undeclared effect.

Each effect sits on the F_X bridge with a size of two Table 17 noise floors: the RMS it adds to
the F_X residual of the cubic fit is twice the memo's cubic σ_FX (as LMC6522's F_X stays at
0.08 % FS while the other components reach 0.02-0.05).
"""

import numpy as np
import pytest

from balance_calib.diagnosis import diagnose, DiagnosisSettings, EFFECT_NAMES
from balance_calib.simulation.diagnosis_rates import (
    calibrated_parameter,
    injected_effects,
    noise_floor_pct_fs,
    simulate_reduction,
)

SEED = 11
NOISE_FLOORS = 2.0


def _campaign(config, effect, seed=SEED, noise_floors=NOISE_FLOORS):
    balance = config.name.lower()
    effects, estimate = injected_effects(
        effect, calibrated_parameter(balance, effect, noise_floors)
    )
    return simulate_reduction(config, effects, seed=seed, estimate_body_weight=estimate)


@pytest.mark.parametrize('effect', EFFECT_NAMES)
def test_the_injected_effect_is_named_first_and_sigma_returns_to_the_noise_floor(balance, effect):
    result = diagnose(_campaign(balance, effect), balance)
    assert result.effect_names[:1] == (effect,), [e.evidence for e in result.effects]
    first = result.effects[0]
    assert 'FX' in first.components and first.p_value['FX'] < 0.01
    floor = noise_floor_pct_fs(balance)[0]
    before, after = result.sigma_pct_fs['before']['FX'], result.sigma_pct_fs['after']['FX']
    assert before > 1.8 * floor  # the effect is really there
    assert after <= 1.5 * floor or after**2 - floor**2 <= 0.5 * (before**2 - floor**2)
    assert (
        result.sigma_pct_fs_crossval['after']['FX']
        < 0.8 * result.sigma_pct_fs_crossval['before']['FX']
    )
    # a bridge effect leaves the other components alone (a new body weight, a supply drift change
    # them all)
    for component in ('MX', 'MY') if effect not in ('tare', 'excitation') else ():
        assert result.sigma_pct_fs['after'][component] == pytest.approx(
            result.sigma_pct_fs['before'][component], rel=0.05
        )


def test_a_generic_term_set_that_fits_part_of_an_effect_is_not_adopted(lmc6522):
    """With hysteresis in the data and only the generic families to try, the time basis fits part
    of it at best and leaves structure beyond the repeatability: nothing is adopted and the F_X
    residual is reported unexplained. With every family, hysteresis explains it with one term.
    """
    reduction = _campaign(lmc6522, 'hysteresis')
    generic = diagnose(
        reduction, lmc6522, settings=DiagnosisSettings(effects=('zero_drift', 'cross_terms'))
    )
    assert generic.effects == ()
    assert [u.components for u in generic.unexplained] == [('FX',)]
    assert generic.adopted.term_names == generic.base_fit.term_names
    full = diagnose(reduction, lmc6522)
    assert full.effect_names == ('hysteresis',) and full.unexplained == ()
    assert full.effects[0].terms == ('dir_FX',)


def test_adopted_model_reproduces_its_residuals_and_the_live_model_drops_nuisance_terms(lmc6522):
    effects = []
    for name in ('temperature', 'hysteresis', 'zero_drift'):
        effects += injected_effects(name, calibrated_parameter('lmc6522', name, NOISE_FLOORS))[0]
    reduction = simulate_reduction(lmc6522, effects, seed=4)
    result = diagnose(reduction, lmc6522)
    assert set(result.effect_names) == {'temperature', 'hysteresis', 'zero_drift'}
    corrected = result.corrected
    fitted = result.adopted.loads(corrected.bridge_outputs_mv, result.extra_variables)
    assert np.allclose(
        corrected.loads - fitted,
        result.residuals_after,
        atol=1e-9 * np.max(np.abs(corrected.loads)),
    )
    assert set(result.live_variables) == {'dT', 'dir_FX'}
    assert not any(v.startswith('drift_') for v in result.live.variables)
    assert result.reference_temperature_c == pytest.approx(np.mean(reduction.points.temperature_c))
    drift = next(e for e in result.effects if e.name == 'zero_drift')
    assert drift.nuisance and all(t.startswith('drift_') for t in drift.terms)


def test_report_entries_keep_the_interface_names(lmc6522):
    result = diagnose(_campaign(lmc6522, 'temperature'), lmc6522)
    report = result.to_report()
    assert set(report) == {
        'sigma_pct_fs',
        'sigma_pct_fs_crossval',
        'effects',
        'unexplained',
        'repeatability_pct_fs',
        'warnings',
    }
    assert report['unexplained'] == [] and set(report['repeatability_pct_fs']) == set(
        lmc6522.components
    )
    assert set(report['sigma_pct_fs']) == {'before', 'after'} and set(
        report['sigma_pct_fs']['after']
    ) == {'FX', 'FY', 'FZ', 'MX', 'MY', 'MZ'}
    entry = report['effects'][0]
    assert set(entry) == {'name', 'components', 'evidence', 'terms', 'sigma_after_pct_fs'}
    assert entry['name'] == 'temperature' and entry['terms'] == ['dT*FXV']
    assert (
        entry['evidence'].startswith('FX residual follows dT*FXV: r = ')
        and '\n' not in entry['evidence']
    )
    assert '% FS' in entry['evidence'] and 'p = ' in entry['evidence']


def test_tare_refits_the_body_weight_it_finds(lmc6522):
    parameter = calibrated_parameter('lmc6522', 'tare', NOISE_FLOORS)
    result = diagnose(_campaign(lmc6522, 'tare'), lmc6522)
    assert result.effect_names[:1] == ('tare',) and result.body_source == 'fitted'
    true_weight = lmc6522.calibration_body.weight_n * (1 + parameter)
    assert result.calibration_body.weight_n == pytest.approx(true_weight, rel=0.15)
    assert result.effects[0].terms == () and result.live.term_names == result.base_fit.term_names
