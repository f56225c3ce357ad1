"""One live pipeline for every batch size: a lone sample (1 kHz: one sample a wake-up), batches of
3 and a whole run give the same wrenches, uncertainties, flags and counts, for the models the C
kernel does not take (a temperature term, load-history terms, an iterative R-091 model).

A lone valid sample takes the pure core's whole-batch checks (no per-sample masks); a batch with a
NaN, an infinite or a saturated sample takes the masks: both must give the same numbers.
"""

from dataclasses import replace

from live_cases import calibration_with_covariance, MEMO, show_run, take, temperature_calibration
import numpy as np
import pytest

from balance_calib.calibration_file import Calibration
from balance_calib.fit.fitted_covariance import with_fitted_covariance
from balance_calib.live.calibrator_core import compute_wrench
from balance_calib.live.stream import LiveCalibrator, LiveSettings
from balance_calib.model.active_calibration import activate
from balance_calib.model.balance_model import BalanceModel
from balance_calib.model.terms import parse_terms
from balance_calib.tables import synthetic as sy
from balance_calib.tables.calibrate import calibrate_table
from balance_calib.tunnel_axes import INVERTED, UPRIGHT


def _with_covariance(model, rng, extra_names=()):
    """The model with a coefficient covariance from 200 made-up points (residuals of 1 N)."""
    n = 200
    extra = {name: rng.uniform(-5.0, 5.0, n) for name in extra_names if name == 'dT'}
    extra.update({name: rng.choice([-1.0, 1.0], n) for name in extra_names if name != 'dT'})
    outputs = rng.uniform(-1.5, 1.5, (n, 6))
    return with_fitted_covariance(model, outputs, rng.normal(0.0, 1.0, (n, 6)), extra or None)


def _temperature():
    calibration = temperature_calibration()
    model = calibration.models['linear+temperature']
    model = _with_covariance(model, np.random.default_rng(41), ('dT',))
    return replace(calibration, models={**calibration.models, model.name: model})


def _load_history():
    """The memo's linear model plus hysteresis terms on F_Z (7 N) and M_Y (0.3 N·m)."""
    linear = MEMO.model('linear')
    coefficients = np.hstack([linear.coefficients, np.zeros((6, 2))])
    coefficients[2, -2], coefficients[4, -1] = 7.0, 0.3
    model = BalanceModel(
        'linear+hysteresis', linear.terms + parse_terms(['dir_FZ', 'dir_MY']), coefficients
    )
    model = _with_covariance(model, np.random.default_rng(5), ('dir_FZ', 'dir_MY'))
    return Calibration(
        'LMC6522',
        {'linear': linear, model.name: model},
        model.name,
        'linear',
        MEMO.capacity,
        MEMO.rated_output_mv,
    )


def _iterative():
    """An R-091 model fitted from a noisy table of a known truth (not the memo's)."""
    rng = np.random.default_rng(22)
    truth = sy.iterative_truth(rng)
    schedule = sy.support_schedule(rng, 11, 30)
    tares = sy.tares_for(rng, np.unique(schedule.series))
    applied, outputs = sy.iterative_campaign(rng, truth, schedule, tares, 0.0005)
    table = sy.make_table(applied, outputs, schedule.series, natural_zero_mv=[0.05] * 6)
    return calibrate_table(table, method='iterative', statistics=False).calibration


CASES = {
    'temperature': (_temperature, UPRIGHT, LiveSettings(), 26.0),
    'load history, low-pass': (_load_history, INVERTED, LiveSettings(lowpass_hz=40.0), None),
    'iterative': (_iterative, UPRIGHT, LiveSettings(overload_fraction=0.3), None),
    'direct, overload': (calibration_with_covariance, INVERTED, LiveSettings(0.5, 0.3), None),
}


@pytest.mark.parametrize('case', list(CASES))
def test_sample_kernels_batches_of_three_and_a_whole_run_publish_the_same(case):
    make, installation, settings, temperature_c = CASES[case]
    calibration = make()
    zero, wind_off, wind_on, _ = show_run(installation, samples_per_condition=3, seed=8)
    samples = wind_on.reshape(-1, 6).copy()
    samples[4, 2] = 50.0 * MEMO.rated_output_mv[2]  # saturated: never published
    samples[7, 0] = np.nan  # not finite: never published
    samples[10, 3] = -np.inf  # not finite either
    samples[13, 2] = 1.8 * MEMO.rated_output_mv[2]  # beyond the envelope: published, flagged
    stamps = 2 * 10**9 + np.arange(len(samples)) * 10**6
    runs = {}
    for size in (1, 3, len(samples)):
        live = LiveCalibrator(activate(calibration, 'adopted', installation), settings)
        assert take(live, 'zero', zero).ok and take(live, 'tare', wind_off, 10**9).ok
        published = []
        for k in range(0, len(samples), size):
            out = live.process(
                samples[k : k + size],
                stamps[k : k + size],
                now_s=1e-3 * k,
                temperature_c=temperature_c,
            )
            assert out.batch.model_used == live.active.model_name, out.batch.fallback_reason
            if len(out.indices):  # a lone rejected sample publishes nothing
                assert out.uncertainty is not None and np.isfinite(out.uncertainty).all()
            none = np.empty((0, 6))
            uncertainty = none if out.uncertainty is None else out.uncertainty
            published.append((out.indices + k, out.wrench, uncertainty, out.batch))
        runs[size] = published, live
    whole, whole_live = runs[len(samples)]
    indices, wrench, uncertainty, batch = whole[0]
    assert 4 not in indices and 7 not in indices and 10 not in indices and 13 in indices
    assert batch.saturated[4] and (batch.out_of_envelope[13] or case == 'iterative')
    scale = MEMO.capacity.max()
    for size in (1, 3):
        published, live = runs[size]
        np.testing.assert_array_equal(np.concatenate([p[0] for p in published]), indices)
        np.testing.assert_allclose(
            np.vstack([p[1] for p in published]) / scale, wrench / scale, rtol=0, atol=1e-12
        )
        np.testing.assert_allclose(np.vstack([p[2] for p in published]), uncertainty, rtol=1e-12)
        for flag in ('accepted', 'saturated', 'out_of_envelope', 'not_converged'):
            lone = np.concatenate([getattr(p[3], flag) for p in published])
            np.testing.assert_array_equal(lone, getattr(batch, flag), err_msg=flag)
        assert vars(live.counters) == vars(whole_live.counters)
        # the components named, in the order they first went over within the batch
        assert (live.overload.active, set(live.overload.components)) == (
            whole_live.overload.active,
            set(whole_live.overload.components),
        )
        np.testing.assert_allclose(
            live.overload.peak_fraction, whole_live.overload.peak_fraction, rtol=1e-12
        )


def test_terms_with_absolute_values_and_fourth_powers_are_the_products_written_out():
    """The live core evaluates a direct model's terms as products of gathered factors (outputs,
    their absolute values): written out by hand here, term by term, on two bridge columns taken
    out of order (a 3-component calibration of FX, FZ and MY).
    """
    names = ['FXV', 'MYV', 'FZV', 'FXV*|FXV|', '|FZV|', 'MYV^4', 'FXV*FZV*|MYV|^2', '|MYV|^3']
    rng = np.random.default_rng(3)
    coefficients = rng.normal(0.0, 100.0, (3, len(names)))
    model = BalanceModel(
        'signed', parse_terms(names), coefficients, ('FX', 'FZ', 'MY'), ('FXV', 'FZV', 'MYV')
    )
    calibration = Calibration(
        'three',
        {'signed': model},
        'signed',
        'signed',
        np.array([100.0, 400.0, 20.0]),
        np.full(3, 2.0),
        ('FX', 'FZ', 'MY'),
        ('FXV', 'FZV', 'MYV'),
    )
    active = activate(calibration, 'adopted', 'balance')
    outputs = rng.uniform(-2.0, 2.0, (7, 6))
    outputs[3, 1] = np.nan  # FYV: a channel the calibration does not read
    x, z, m = outputs[:, 0], outputs[:, 2], outputs[:, 4]
    by_hand = (
        np.column_stack([x, m, z, x * abs(x), abs(z), m**4, x * z * m**2, abs(m) ** 3])
        @ coefficients.T
    )
    for rows in (slice(None), slice(2, 3), slice(3, 4)):
        batch = compute_wrench(active, outputs[rows])
        assert batch.accepted.all()
        np.testing.assert_allclose(batch.loads_total[:, [0, 2, 4]], by_hand[rows], rtol=1e-13)
        np.testing.assert_array_equal(batch.loads_total[:, [1, 3, 5]], 0.0)
