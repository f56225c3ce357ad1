"""The live calibrator applies an iterative (AIAA R-091) calibration fitted from a table.

A table is generated from a known R-091 truth (outputs = A·g(total loads), 96 terms, one unknown
tare load per series), fitted with `--method iterative`'s code and written to calibration.yaml; the
live core then evaluates it through the model's own vectorised Newton iteration, by the batch path
and the one-sample path, with an electrical zero and a tare load. A sample whose Newton iteration
does not converge is not published, is counted, and /diagnostics says so at ERROR.
"""

from dataclasses import replace
import time

import numpy as np
import pytest

from balance_calib.calibration_file import load_calibration, save_calibration
from balance_calib.live.calibrator_core import compute_wrench
from balance_calib.live.diagnostics_status import diagnostics, ERROR, LiveState
from balance_calib.live.stream import LiveCalibrator, LiveSettings
from balance_calib.model.active_calibration import activate
from balance_calib.model.inverse import InverseDidNotConverge
from balance_calib.model.r091 import IterativeModel
from balance_calib.model.terms import parse_terms
from balance_calib.model.uncertainty import load_standard_uncertainty
from balance_calib.nodes._messages import set_wrench
from balance_calib.tables import synthetic as sy
from balance_calib.tables.calibrate import calibrate_table
from balance_calib.tunnel_axes import parse_installation

CAPACITY = sy.capacity_si()


def _fitted(tmp_path_factory, noise_mv: float, seed: int):
    rng = np.random.default_rng(seed)
    truth = sy.iterative_truth(rng)
    schedule = sy.support_schedule(rng, 11, 30)  # 6 x 11 + 15 x 30 = 516 points, 21 series
    tares = sy.tares_for(rng, np.unique(schedule.series))
    applied, outputs = sy.iterative_campaign(rng, truth, schedule, tares, noise_mv)
    fitted = calibrate_table(
        sy.make_table(applied, outputs, schedule.series, natural_zero_mv=[0.05] * 6),
        method='iterative',
        statistics=False,
    )
    path = tmp_path_factory.mktemp('iterative') / 'calibration.yaml'
    save_calibration(path, fitted.calibration)  # what balance_calibrator reads
    return truth, load_calibration(path), rng


@pytest.fixture(scope='module')
def noise_free(tmp_path_factory):
    return _fitted(tmp_path_factory, 0.0, 21)


@pytest.fixture(scope='module')
def noisy(tmp_path_factory):
    return _fitted(tmp_path_factory, 0.0005, 22)


def _samples(rng, truth, zero_mv):
    """Raw outputs (bridge zero added) of loads in the schedule's support and of six loads at
    once.
    """
    inside = np.zeros((40, 6))
    for i in range(40):
        pair = rng.choice(6, 2, replace=False)
        inside[i, pair] = rng.uniform(-0.9, 0.9, 2) * CAPACITY[pair]
    loads = np.vstack([inside, sy.six_at_once(rng, 40, 0.5)])
    return loads, truth.outputs(loads) + zero_mv


@pytest.mark.parametrize('installation', ['upright', 'inverted'])
def test_live_loads_are_the_truths_and_the_models_through_both_paths(noise_free, installation):
    truth, calibration, rng = noise_free
    model = calibration.model()
    assert getattr(model, 'form', '') == 'iterative' and calibration.adopted == 'iterative'
    active = activate(calibration, 'adopted', installation)
    assert active.iterative and active.model is model  # without_constant(): nothing to drop
    zero = np.array([0.011, -0.007, 0.02, 0.0, -0.013, 0.004])  # mV: the bridges' electrical zero
    tare = 0.1 * CAPACITY * np.array([0.2, -0.1, -3.0, 0.05, 0.5, -0.2])  # N, N·m: a model weight
    loads, raw = _samples(rng, truth, zero)
    batch = compute_wrench(active, raw, zero_mv=zero, tare_load=tare)
    assert batch.accepted.all() and not batch.not_converged.any()
    # the fit recovered the truth (noise-free table): the balance's total loads, then minus the
    # tare load
    np.testing.assert_allclose(batch.loads_total / CAPACITY, loads / CAPACITY, rtol=0, atol=1e-9)
    # exactly the model's own Newton solution (one implementation of the math)
    own = model.loads(raw - zero)
    np.testing.assert_allclose(batch.loads_total / CAPACITY, own / CAPACITY, rtol=0, atol=1e-12)
    axes = parse_installation(installation)
    np.testing.assert_allclose(
        batch.wrench_tunnel, axes.to_tunnel(own - tare), rtol=0, atol=1e-12 * CAPACITY.max()
    )
    # the one-sample path (a lone sample at low rates) gives the batch's numbers
    for k in range(0, len(raw), 7):
        one = compute_wrench(active, raw[k : k + 1], zero_mv=zero, tare_load=tare)
        assert one.accepted.all() and not one.not_converged.any() and not one.saturated.any()
        np.testing.assert_allclose(
            one.wrench_tunnel[0] / CAPACITY.max(),
            batch.wrench_tunnel[k] / CAPACITY.max(),
            rtol=0,
            atol=1e-12,
        )
        np.testing.assert_allclose(
            one.loads_total[0] / CAPACITY, batch.loads_total[k] / CAPACITY, rtol=0, atol=1e-12
        )


def test_series_tares_are_not_the_balances_constant(noise_free):
    """The fit's series tares are loads on the balance during calibration, not a term of its
    response: zero outputs read zero load, and the outputs of a series' tare load read that load.
    """
    truth, calibration, _ = noise_free
    active = activate(calibration)
    np.testing.assert_array_equal(compute_wrench(active, np.zeros((1, 6))).loads_total, 0.0)
    series_tares = np.array(list(calibration.extra['series_tares_si'].values()))
    assert np.abs(series_tares / CAPACITY).max() > 0.01
    batch = compute_wrench(active, truth.outputs(series_tares))
    np.testing.assert_allclose(
        batch.loads_total / CAPACITY, series_tares / CAPACITY, rtol=0, atol=1e-9
    )


def test_noisy_fit_live_loads_and_uncertainty_through_the_stream(noisy):
    """LiveCalibrator (what the node runs): wrench = the model's loads, uncertainty =
    model/uncertainty's, for a batch and for lone samples; the fitted model reads the truth within
    its noise.
    """
    truth, calibration, rng = noisy
    model = calibration.model()
    active = activate(calibration)
    zero = np.array([0.01, 0.0, -0.02, 0.005, 0.0, 0.01])
    loads, raw = _samples(rng, truth, zero)
    stamps = 1_000_000 * (1 + np.arange(len(raw)))
    live = LiveCalibrator(active, LiveSettings(publish_uncertainty=True))
    live.tare = replace(live.tare, zero_mv=zero)
    batch = live.process(raw, stamps, now_s=0.0)
    own = model.loads(raw - zero)
    expected_u = load_standard_uncertainty(model, raw - zero)
    assert len(batch.indices) == len(raw)
    np.testing.assert_allclose(
        batch.wrench / CAPACITY.max(),
        active.installation.to_tunnel(own) / CAPACITY.max(),
        rtol=0,
        atol=1e-12,
    )
    np.testing.assert_allclose(
        batch.uncertainty, np.abs(active.installation.to_tunnel(expected_u)), rtol=1e-12
    )
    # truth within 5 u (0.0005 mV of output noise ≈ 0.02 % of rated output: u a few 1e-4 FS)
    error = np.abs(active.installation.to_tunnel(own - loads))
    assert np.all(error < 5 * batch.uncertainty)
    single = LiveCalibrator(active, LiveSettings(publish_uncertainty=True))
    single.tare = replace(single.tare, zero_mv=zero)
    for k in range(0, len(raw), 9):
        one = single.process(raw[k : k + 1], stamps[k : k + 1], now_s=0.0)
        np.testing.assert_allclose(
            one.wrench[0] / CAPACITY.max(), batch.wrench[k] / CAPACITY.max(), rtol=0, atol=1e-12
        )
        np.testing.assert_allclose(one.uncertainty[0], batch.uncertainty[k], rtol=1e-12)


def _folding_calibration(calibration):
    """An iterative model V = r (L/cap - 0.3 (L/cap)³) per bridge: monotonic within capacity, with
    no solution for an output above (2/3) r / √0.9 ≈ 0.70 r: Newton cannot converge there.
    """
    rated = np.asarray(calibration.rated_output_mv, float)
    names = list(calibration.components) + [f'{c}^3' for c in calibration.components]
    coefficients = np.hstack([np.diag(rated / CAPACITY), np.diag(-0.3 * rated / CAPACITY**3)])
    folding = IterativeModel(
        'folding',
        parse_terms(names),
        coefficients,
        tuple(calibration.components),
        tuple(calibration.bridge_outputs),
        {'capacity': CAPACITY.tolist()},
    )
    return replace(
        calibration, models={'folding': folding}, adopted='folding', base_model='folding'
    ), folding


def test_a_sample_where_newton_does_not_converge_is_counted_not_published(noise_free):
    _, calibration, _ = noise_free
    folding_cal, folding = _folding_calibration(calibration)
    active = activate(folding_cal)
    rated = np.asarray(calibration.rated_output_mv, float)
    # within the fold
    good = folding.outputs(0.8 * CAPACITY[None, :] * np.array([1, -1, 0.5, 0, 0.2, -0.4]))[0]
    unreachable = good.copy()
    unreachable[2] = 0.9 * rated[2]  # within the bridge's range (2x rated), beyond the fold
    nan = good.copy()
    nan[4] = np.nan
    saturated = good.copy()
    saturated[1] = 3.0 * rated[1]
    raw = np.vstack([good, unreachable, good, nan, saturated])
    with pytest.raises(InverseDidNotConverge, match='did not converge'):
        folding.loads(unreachable[None, :])  # the model's own interface still raises
    batch = compute_wrench(active, raw)
    assert batch.accepted.tolist() == [True, False, True, False, False]
    assert batch.not_converged.tolist() == [False, True, False, False, False]
    assert batch.saturated.tolist() == [False, False, False, False, True]
    assert batch.nonfinite.tolist() == [False, False, False, True, False]
    assert np.isnan(batch.wrench_tunnel[~batch.accepted]).all()  # no number for them
    for k in (0, 2):
        np.testing.assert_allclose(
            batch.loads_total[k] / CAPACITY,
            0.8 * np.array([1, -1, 0.5, 0, 0.2, -0.4]),
            rtol=0,
            atol=1e-12,
        )
    one = compute_wrench(active, raw[1:2])
    assert (
        one.not_converged.tolist() == [True]
        and not one.accepted.any()
        and np.isnan(one.wrench_tunnel).all()
    )

    live = LiveCalibrator(active)
    published = live.process(raw, 1000 * (1 + np.arange(5)), now_s=0.0)
    assert published.indices.tolist() == [0, 2]
    c = live.counters
    assert (c.received, c.published, c.not_converged, c.saturated, c.rejected_nonfinite) == (
        5,
        2,
        1,
        1,
        1,
    )
    live.process(raw[1:2], np.array([6000]), now_s=0.0)
    assert c.not_converged == 2
    reports = diagnostics(
        active,
        LiveState(
            period_s=1.0,
            counters=c,
            last_sample_age_s=0.1,
            stale_after_s=1.0,
            temperature_age_s=None,
            fallback_reason='',
            tare_zero_mv=None,
        ),
    )
    status = reports[0]
    assert (
        status.level == ERROR
        and "2 samples where the folding model's Newton iteration" in status.message
    )
    assert dict(status.values)['newton_not_converged'] == '2'


@pytest.mark.ros
def test_table_fitted_iterative_calibration_drives_the_calibrator_over_dds(tmp_path):
    """balance_calibrator (its own process, real DDS) with an iterative calibration.yaml fitted
    from a table by `balance-calib fit --method iterative`: every wrench and its uncertainty are
    the model's.
    """
    from calibrator_harness import wrench_values
    from geometry_msgs.msg import WrenchStamped
    from ros_harness import new_domain_id, NodeProcess, Probe, RELIABLE, wait_for

    from balance_calib.cli import main
    from balance_calib.tables.balfit_writer import write_table

    rng = np.random.default_rng(31)
    truth = sy.iterative_truth(rng)
    schedule = sy.support_schedule(rng, 11, 30)
    tares = sy.tares_for(rng, np.unique(schedule.series))
    applied, outputs = sy.iterative_campaign(rng, truth, schedule, tares, 0.0005)
    write_table(
        tmp_path / 'cal.csv',
        sy.make_table(applied, outputs, schedule.series, natural_zero_mv=[0.1] * 6),
    )
    assert (
        main(
            [
                'fit',
                str(tmp_path / 'cal.csv'),
                '--out',
                str(tmp_path / 'fit'),
                '--method',
                'iterative',
                '--no-plots',
            ]
        )
        == 0
    )
    calibration = load_calibration(tmp_path / 'fit' / 'calibration.yaml')
    model = calibration.model()
    assert model.form == 'iterative'
    loads, samples = _samples(rng, truth, np.zeros(6))  # mV, natural zero removed
    upright = parse_installation('upright')
    expected = upright.to_tunnel(model.loads(samples))
    expected_u = np.abs(upright.to_tunnel(load_standard_uncertainty(model, samples)))

    probe = Probe(new_domain_id())
    calibrator = NodeProcess(
        'balance_calibrator',
        probe.domain_id,
        tmp_path / 'logs',
        {'calibration_file': str(tmp_path / 'fit' / 'calibration.yaml')},
    )
    try:
        wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
        uncertainties = probe.subscribe(WrenchStamped, '/balance/wrench_uncertainty')
        publisher = probe.node.create_publisher(WrenchStamped, '/balance/raw', RELIABLE)
        subscriptions = [
            s for s in probe.node.subscriptions if s.topic_name.startswith('/balance/wrench')
        ]
        wait_for(
            lambda: (
                publisher.get_subscription_count() >= 1
                and all(s.get_publisher_count() >= 1 for s in subscriptions)
            ),
            60.0,
            'the calibrator to connect',
        )

        # Matched on the probe's side is not yet matched on the calibrator's: it computes the
        # uncertainty only once it sees a subscriber. Warm-up samples (stamp 99 s) until one
        # wrench and one uncertainty of them are back, so no sample of the test is lost.
        def warm_up_back():
            warm = WrenchStamped()
            warm.header.stamp.sec = 99
            warm.wrench.force.x, warm.wrench.force.y, warm.wrench.force.z = (
                float(v) for v in samples[0][:3]
            )
            warm.wrench.torque.x, warm.wrench.torque.y, warm.wrench.torque.z = (
                float(v) for v in samples[0][3:]
            )
            publisher.publish(warm)
            return wrenches and uncertainties

        wait_for(warm_up_back, 60.0, 'a warm-up wrench and its uncertainty')
        time.sleep(0.2)  # the warm-up samples still on their way
        wrenches.clear()
        uncertainties.clear()
        for i, values in enumerate(samples):
            msg = WrenchStamped()
            msg.header.stamp.sec, msg.header.stamp.nanosec = 100, (i + 1) * 1000
            set_wrench(msg.wrench, values)
            publisher.publish(msg)

        def of_the_test(messages):
            return [m for m in messages if m.header.stamp.sec == 100]

        wait_for(
            lambda: (
                len(of_the_test(wrenches)) >= len(samples)
                and len(of_the_test(uncertainties)) >= len(samples)
            ),
            60.0,
            f'{len(samples)} wrenches and uncertainties',
        )
        wrenches[:], uncertainties[:] = of_the_test(wrenches), of_the_test(uncertainties)

        def as_array(messages):
            return wrench_values(sorted(messages, key=lambda m: m.header.stamp.nanosec))

        received = as_array(wrenches)
        np.testing.assert_allclose(received, expected, rtol=1e-9, atol=1e-9 * CAPACITY.max())
        np.testing.assert_allclose(as_array(uncertainties), expected_u, rtol=1e-9)
        # the loads are the truth's within the calibration's uncertainty
        assert np.all(np.abs(received - upright.to_tunnel(loads)) < 5 * expected_u)
    finally:
        calibrator.stop()
        probe.close()


def test_uncertainty_of_a_model_with_a_temperature_input_uses_that_input():
    """The uncertainty publisher no longer skips models with extra inputs: it evaluates them with
    the same dT as the loads; when the model falls back to its base (no temperature) the base's
    (none here) is used.
    """
    from balance_calib.calibration_file import Calibration
    from balance_calib.config import CONFIG_DIR
    from balance_calib.fit.fitted_covariance import with_fitted_covariance
    from balance_calib.model.balance_model import BalanceModel

    memo = load_calibration(CONFIG_DIR / 'lmc6522.yaml')
    linear = memo.model('linear')
    coefficients = np.hstack([linear.coefficients, np.zeros((6, 1))])
    coefficients[2, -1] = 10.0  # 10 N/K on F_Z
    augmented = BalanceModel(
        'linear+temperature', linear.terms + parse_terms(['dT']), coefficients
    )
    rng = np.random.default_rng(41)
    fit_outputs = rng.uniform(-1.5, 1.5, (200, 6))
    fit_extra = {'dT': rng.uniform(-5, 5, 200)}
    augmented = with_fitted_covariance(
        augmented, fit_outputs, rng.normal(0, 1.0, (200, 6)), fit_extra
    )
    calibration = Calibration(
        'LMC6522',
        {'linear': linear, 'linear+temperature': augmented},
        'linear+temperature',
        'linear',
        memo.capacity,
        memo.rated_output_mv,
        reference_temperature_c=20.0,
    )
    active = activate(calibration)
    raw = rng.uniform(-1, 1, (5, 6))
    live = LiveCalibrator(active, LiveSettings(publish_uncertainty=True))
    published = live.process(raw, 1000 * (1 + np.arange(5)), now_s=0.0, temperature_c=26.0)
    assert published.batch.model_used == 'linear+temperature'
    expected = load_standard_uncertainty(active.model, raw, {'dT': np.full(5, 6.0)})
    np.testing.assert_allclose(
        published.uncertainty, np.abs(active.installation.to_tunnel(expected)), rtol=1e-12
    )
    # dT enters the design row: the same outputs at another temperature give another uncertainty
    other = load_standard_uncertainty(active.model, raw, {'dT': np.full(5, -4.0)})
    assert np.abs(other - expected).max() > 1e-6 * expected.max()
    fallback = live.process(raw, 1000 * (6 + np.arange(5)), now_s=0.0, temperature_c=None)
    assert fallback.batch.model_used == 'linear' and fallback.uncertainty is None


def test_tare_window_without_a_load_is_refused_and_a_zero_without_a_solution_is_described_as_nan(
    noise_free,
):
    from balance_calib.live.load_text import describe_zero
    from balance_calib.live.tare_window import evaluate_window, TareWindow

    _, calibration, _ = noise_free
    folding_cal, folding = _folding_calibration(calibration)
    active = activate(folding_cal)
    rated = np.asarray(calibration.rated_output_mv, float)
    window = TareWindow(10)
    rows = np.tile(folding.outputs(0.1 * CAPACITY[None, :])[0], (10, 1))
    rows[3, 2] = 0.9 * rated[2]  # beyond the fold: no load for this sample
    window.add(rows)
    result = evaluate_window(window, active, max_ratio=4.0)
    assert not result.ok and "1 of the window's 10 samples give no load" in result.message
    zero = np.zeros(6)
    zero[2] = 0.9 * rated[2]
    assert 'FZ=+nan' in describe_zero(zero, active)
