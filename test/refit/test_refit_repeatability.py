"""Refits from bags judge their residuals against the points' own sample scatter.

The load-point cut keeps each point's output variance and sample count (refit/load_points.py) and
the pipeline hands them to diagnose(): report.json's repeatability_pct_fs is then the point noise
propagated to loads, and structure that no effect family explains comes out as `unexplained`
(with the consecutive zero points alone as the yardstick it was named as some family, or missed).
Bags are written from simulated campaigns with few samples a point and a short timeline.
"""

from dataclasses import replace

import numpy as np
import pytest

from balance_calib.calibrate.from_bags import RefitSettings, run_refit
from balance_calib.config import load_balance_config
from balance_calib.model.inverse import linear_part
from balance_calib.model.tm663 import tm663_terms
from balance_calib.simulation.balance_sim import (
    simulate_campaign,
    SimulationSettings,
    table17_noise,
)
from balance_calib.simulation.campaign_bag import write_campaign_bag
from balance_calib.simulation.diagnosis_rates import calibrated_parameter, shape_effects
from balance_calib.zero_points import zero_point_noise_factor


def _settings(samples, seed, **noise):
    return SimulationSettings(
        samples_per_point=samples,
        transition_samples=2,
        point_duration_s=1.0,
        transition_s=0.5,
        seed=seed,
        **noise,
    )


def _propagated_pct_fs(config, point_variance_mv2):
    """% FS per component of independent bridge noise of the given variance (mV²) on a point mean,
    through the truth's linear sensitivity dL_k/dV_i: var L_k = Σ_i C_ki² var V_i.
    """
    sensitivity = linear_part(config.matrices['cubic'].without_constant())
    return (
        np.sqrt(sensitivity**2 @ np.asarray(point_variance_mv2, float)) / config.capacity * 100.0
    )


def test_repeatability_from_a_bag_is_the_point_noise_propagated_to_loads(tmp_path):
    config = load_balance_config('lmc6522')
    n = 6
    # per sample, per bridge
    sigma_sample_mv = np.array([0.004, 0.0025, 0.0015, 0.003, 0.002, 0.0025])
    campaign = simulate_campaign(config, settings=_settings(n, 5, noise_mv=sigma_sample_mv))
    # the samples of every point move by 3 σ_s over the point (settling): not point-to-point
    # scatter, the same in every point, so the point means and the fit are unchanged up to a common
    # offset
    inside = campaign.sample_point >= 0
    elapsed = np.where(
        inside, campaign.times_s - campaign.start_s[np.maximum(campaign.sample_point, 0)], 0.0
    )
    ramp = (elapsed / 1.0)[:, None] * 3.0 * sigma_sample_mv[None, :]
    campaign = replace(campaign, raw_mv=campaign.raw_mv + ramp)
    bag = write_campaign_bag(campaign, tmp_path / 'bag')
    report = run_refit([bag], 'lmc6522', tmp_path / 'out', RefitSettings(plots=False)).report

    # first principles: σ_s / √n on each point mean, through the linear sensitivity, in % FS
    expected = _propagated_pct_fs(config, sigma_sample_mv**2 / n)
    measured = np.array([report['repeatability_pct_fs'][c] for c in config.components])
    assert np.all(np.abs(measured / expected - 1.0) < 0.2), (measured, expected)
    # the variance about each point mean (blind to the settling) would have been far off: the test
    # tells the estimators apart
    about_mean, _ = campaign.point_scatter()
    loaded = ~campaign.is_zero_point
    naive = _propagated_pct_fs(config, np.nanmean(about_mean[loaded], axis=0))
    assert np.all(naive / expected > 1.3), naive / expected
    # the repeatability is that of one point mean; the zero-point subtraction of §5(4) adds the
    # brackets' noise to every loaded point (zero_point_noise_factor, ~1.11), and the cubic fit
    # (34 terms) takes out its share: σ (eq. 44, in-sample) ≈ factor x repeatability x √(1 - p/N)
    points = len(campaign.point)
    factor = zero_point_noise_factor(
        campaign.start_s, campaign.is_zero_point, campaign.orientation
    )
    terms = len(tm663_terms('cubic', config.bridge_outputs))
    sigma = np.array([report['sigma_pct_fs']['before'][c] for c in config.components])
    assert np.all(np.abs(sigma / (factor * expected * np.sqrt(1 - terms / points)) - 1.0) < 0.2), (
        sigma / expected
    )
    assert report['effects'] == [] and report['unexplained'] == []


@pytest.mark.parametrize(
    'balance, shape, component, seed',
    [
        # M_Y leaking into the M_X bridge beyond 40 % of rated
        ('lmc6522', 'outside_dead_band', 'MX', 1),
        ('b660h', 'outside_dead_band', 'FX', 2),
        # a curvature growing in time, flipping with gravity
        ('lmc6522', 'outside_gravity_time', 'FY', 3),
    ],
)
def test_an_effect_outside_every_family_is_unexplained_and_nothing_is_named(
    tmp_path, balance, shape, component, seed
):
    config = load_balance_config(balance)
    # twice the component's noise floor (Table 17's cubic σ): the RMS it adds to the cubic residual
    parameter = calibrated_parameter(balance, shape, 2.0, component)
    effects, _ = shape_effects(shape, parameter, component)
    campaign = simulate_campaign(
        config,
        settings=_settings(8, seed, noise_sigma_pct_fs=table17_noise(config)),
        effects=effects,
    )
    bag = write_campaign_bag(campaign, tmp_path / 'bag')
    report = run_refit([bag], balance, tmp_path / 'out', RefitSettings(plots=False)).report
    assert report['effects'] == [], [e['name'] for e in report['effects']]
    assert component in [c for u in report['unexplained'] for c in u['components']], report[
        'unexplained'
    ]
    assert "points' own samples" in ' '.join(u['evidence'] for u in report['unexplained'])


@pytest.mark.parametrize(
    'balance, seed', [('lmc6522', 21), ('lmc6522', 22), ('b660h', 21), ('b660h', 22)]
)
def test_a_clean_bag_has_nothing_unexplained_and_the_repeatability_of_its_noise(
    tmp_path, balance, seed
):
    config = load_balance_config(balance)
    noise = table17_noise(config)  # per point mean, as load σ in % FS per component
    campaign = simulate_campaign(config, settings=_settings(8, seed, noise_sigma_pct_fs=noise))
    bag = write_campaign_bag(campaign, tmp_path / 'bag')
    report = run_refit([bag], balance, tmp_path / 'out', RefitSettings(plots=False)).report
    assert report['effects'] == [] and report['unexplained'] == [] and report['warnings'] == []
    measured = np.array([report['repeatability_pct_fs'][c] for c in config.components])
    assert np.all(np.abs(measured / noise - 1.0) < 0.2), measured / noise


def test_the_cut_rejects_spikes_but_not_ordinary_noise(tmp_path):
    from balance_calib.bags.reader import read_bags
    from balance_calib.refit.load_points import cut_load_points

    config = load_balance_config('b660h')
    campaign = simulate_campaign(
        config, settings=_settings(8, 22, noise_sigma_pct_fs=table17_noise(config))
    )
    variance, _ = campaign.point_scatter()
    sigma_sample = np.sqrt(np.nanmean(variance, axis=0) * 8)  # per-sample σ per bridge, mV
    raw = campaign.raw_mv.copy()
    rng = np.random.default_rng(0)
    in_points = np.flatnonzero(campaign.sample_point >= 0)
    spiked = rng.choice(in_points, 12, replace=False)
    bridge = rng.integers(0, 6, len(spiked))
    raw[spiked, bridge] += 30.0 * sigma_sample[bridge] * rng.choice([-1.0, 1.0], len(spiked))
    spiky = replace(campaign, raw_mv=raw)
    bag = write_campaign_bag(spiky, tmp_path / 'bag')
    points, cut = cut_load_points(
        read_bags([bag], required=('raw', 'applied_load', 'gravity')), config
    )
    # exactly the spikes go (8 Gaussian samples a point over six bridges: a point's own MAD alone
    # rejected ~5 % of ordinary samples and biased the repeatability low)
    assert cut.samples_rejected_outliers == len(spiked)
    clean_means, _, _ = campaign.point_means()
    assert np.allclose(
        np.delete(points.outputs_mv, np.unique(campaign.sample_point[spiked]), axis=0),
        np.delete(clean_means, np.unique(campaign.sample_point[spiked]), axis=0),
        rtol=0,
        atol=1e-12,
    )
    assert (
        np.array_equal(cut.point_labels, points.label)
        and cut.point_variance_mv2.shape == points.outputs_mv.shape
    )
    counts = np.bincount(campaign.sample_point[spiked], minlength=len(points.label))
    assert np.array_equal(cut.point_samples, 8 - counts)


def test_a_refusal_for_outliers_names_the_unexplained_structure_on_that_component(tmp_path):
    """An effect outside every family at 2× the floor can push points beyond the outlier gate: the
    refusal stays (nothing written), but the reason names the leftover the diagnosis could not
    explain on that component beside a weight or marker error (it used to blame the weights alone).
    """
    from balance_calib.refit.pipeline import RefitError

    config = load_balance_config('lmc6522')
    parameter = calibrated_parameter('lmc6522', 'outside_gravity_time', 2.0, 'MX')
    effects, _ = shape_effects('outside_gravity_time', parameter, 'MX')
    campaign = simulate_campaign(
        config, settings=_settings(8, 3, noise_sigma_pct_fs=table17_noise(config)), effects=effects
    )
    bag = write_campaign_bag(campaign, tmp_path / 'bag')
    with pytest.raises(RefitError) as refused:
        run_refit([bag], 'lmc6522', tmp_path / 'out', RefitSettings(plots=False))
    reason = str(refused.value)
    assert 'outliers' in reason and 'its MX load' in reason
    assert 'left unexplained on MX' in reason and 'an effect the model lacks?' in reason
    assert not (tmp_path / 'out').exists()
