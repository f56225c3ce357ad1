"""The loop closed on table data (interfaces.md, "Effects found in table calibrations").

The tables here are written from physics the candidate terms do not hold exactly: a bridge whose
sensitivity changes with temperature as a factor on its whole response (1 + s·ΔT) and whose zero
moves with ΔT², read in degF with outputs in V; a position channel in mm that follows a load; a
humidity channel with no effect; a temperature that is constant within each series. What must
hold: an effect in the data is adopted and lowers the cross-validated σ; a channel without one,
or one that only follows a load, is never taken for an effect; a channel constant within each
series is never an effect alone. The σ before/after of each effect are printed (-s) for the note.
"""

from __future__ import annotations

import numpy as np
import pytest
from table_cases import table as make_table

from balance_calib.calibration_file import load_calibration, save_calibration
from balance_calib.calibration_points import load_direction, returning_series
from balance_calib.errors import ConfigError
from balance_calib.model.active_calibration import activate
from balance_calib.tables.calibrate import calibrate_table

LOADS = ('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ')
BRIDGES = ('FXV', 'FYV', 'FZV', 'MXV', 'MYV', 'MZV')
CAPACITY_LBS = np.array([50.0, 80.0, 400.0, 120.0, 300.0, 100.0])  # in-lbs for the moments
LBF = 4.4482216152605
INCH = 0.0254
RATED_V = 0.010  # 10 mV at capacity, written in V
NOISE_V = 2e-6  # 0.02 % of rated output


def _schedule(rng, repeats=1):
    """Per load a series up and down: 0 → +cap → 0 → −cap → 0 in 10 % steps (it returns to its
    loads, so order and direction are both defined), then pairs of loads at random.
    """
    ramp = np.concatenate(
        [np.linspace(0, 1, 11), np.linspace(0.9, -1, 20), np.linspace(-0.9, 0, 10)]
    )
    rows, series = [], []
    for repeat in range(repeats):
        first = 12 * repeat
        for k in range(6):
            block = np.zeros((len(ramp), 6))
            block[:, k] = ramp
            rows.append(block)
            series += [first + k + 1] * len(ramp)
        pairs = [(0, 2), (1, 3), (2, 4), (3, 5), (0, 5), (1, 4)]
        for label, (a, b) in enumerate(pairs, start=first + 7):
            block = np.zeros((30, 6))
            block[:, a] = rng.uniform(-1, 1, 30)
            block[:, b] = rng.uniform(-1, 1, 30)
            rows.append(block)
            series += [label] * 30
    return np.vstack(rows), np.array(series)


def _balance(
    rng,
    *,
    temperature_f=None,
    sensitivity_per_k=None,
    zero_per_k2=None,
    extra=(),
    repeats=1,
    shape=None,
):
    """A table (loads lbs / in-lbs, outputs V) of a balance with 2 % cross-talk and a small
    square, optionally warmed up during the campaign: output = response(x)·(1 + s·ΔT) + z·ΔT²
    (ΔT in K from 20 °C). `extra`: (symbol, unit, values) channels appended; `shape(x, series)`
    adds to the response (fractions of rated output) what a test puts in.
    """
    fraction, series = _schedule(rng, repeats)
    applied = fraction * CAPACITY_LBS
    tares = {s: rng.uniform(-0.02, 0.02, 6) for s in np.unique(series)}
    x = fraction + np.array([tares[s] for s in series])
    crosstalk = np.eye(6) + rng.uniform(-0.02, 0.02, (6, 6)) * (1 - np.eye(6))
    response = x @ crosstalk.T + 0.003 * x**2
    if shape is not None:
        response = response + shape(x, series)
    outputs = RATED_V * response
    symbols, units, columns = list(BRIDGES), ['V'] * 6, [outputs]
    if temperature_f is not None:
        delta_k = (temperature_f - 68.0) * 5.0 / 9.0
        if sensitivity_per_k is not None:
            outputs *= 1.0 + np.asarray(sensitivity_per_k)[None, :] * delta_k[:, None]
        if zero_per_k2 is not None:
            outputs += RATED_V * np.asarray(zero_per_k2)[None, :] * delta_k[:, None] ** 2
        symbols.append('TEMP')
        units.append('degF')
        columns.append(temperature_f[:, None])
    columns[0] = outputs + rng.normal(0, NOISE_V, outputs.shape)
    for symbol, unit, values in extra:
        symbols.append(symbol)
        units.append(unit)
        columns.append(np.asarray(values, float)[:, None])
    return make_table(
        'physical',
        LOADS,
        symbols,
        ('lbs',) * 3 + ('in-lbs',) * 3,
        units,
        CAPACITY_LBS,
        applied,
        np.hstack(columns),
        series,
    )


def _warm_up(n, rng):
    """degF: a warm-up over the campaign with a wobble, varying within every series."""
    i = np.arange(n)
    return 66.0 + 16.0 * (1 - np.exp(-i / 150.0)) + 1.5 * np.sin(i / 7.0) + rng.normal(0, 0.05, n)


def _note(name, report):
    """σ and cross-validated σ before/after, % FS, for the closing note (pytest -s)."""
    for key in ('sigma_pct_fs', 'sigma_pct_fs_crossval'):
        print(name, key, report[key]['before'], '->', report[key]['after'])


def test_load_direction_and_returning_series_by_hand():
    applied = np.array([[0, 0], [1, 0], [2, 0], [1, 0], [0, 5], [0, 3], [1, 1], [1, 1]], float)
    series = np.array([1, 1, 1, 1, 2, 2, 3, 3])
    # series 1 rises, rises, falls; series 2 falls; series 3 does not change
    assert load_direction(applied, series, np.array([2.0, 5.0])).tolist() == [
        0,
        1,
        1,
        -1,
        0,
        -1,
        0,
        0,
    ]
    # series 1 returns to its load of point 2 at point 4; series 3 repeats only the point just
    # before (not a return)
    assert returning_series(applied, series, np.array([2.0, 5.0])).tolist() == [
        True,
        True,
        True,
        True,
        False,
        False,
        False,
        False,
    ]


@pytest.fixture(scope='module')
def warmed():
    """A warm-up with a sensitivity change (−0.05 … +0.04 %/K by bridge) and a zero shift
    quadratic in ΔT, outputs in V, temperature in degF.
    """
    rng = np.random.default_rng(36)
    n = 6 * 41 + 6 * 30
    temperature = _warm_up(n, rng)
    sensitivity = np.array([4e-4, -3e-4, 2e-4, -5e-4, 3e-4, 1e-4])
    zero = np.array([4e-5, 0.0, -3e-5, 2e-5, 0.0, 3e-5])  # of rated output per K²
    table = _balance(
        rng, temperature_f=temperature, sensitivity_per_k=sensitivity, zero_per_k2=zero
    )
    return table, calibrate_table(table, method='direct', statistics=False)


def test_a_physical_temperature_effect_in_degf_is_adopted_and_lowers_the_crossval(warmed):
    table, result = warmed
    report = result.report
    _note('temperature', report)
    names = [e['name'] for e in report['effects'] if e.get('adopted')]
    assert names.count('temperature') == 1, report['effects']
    effect = next(e for e in report['effects'] if e['name'] == 'temperature')
    assert effect['channel'] == 'TEMP'
    assert all('dTEMP' in t for t in effect['terms']), effect['terms']
    assert report['adopted'] is True and report['requires'] == ['TEMP']
    before, after = (
        report['sigma_pct_fs_crossval']['before'],
        report['sigma_pct_fs_crossval']['after'],
    )
    floor = 100 * NOISE_V / RATED_V  # the noise, % of rated output ~ % of capacity
    # every load the warm-up visibly moved (cross-validated σ 1.3x the noise floor) is listed,
    # and each listed one comes down to the floor (within 15 %: 2 % cross-talk, the tares)
    moved = {load for load, value in before.items() if value > 1.3 * floor}
    assert moved <= set(effect['components']), (moved, effect['components'])
    for load in effect['components']:
        assert after[load] < before[load] and after[load] < 1.15 * floor, (load, after[load])
    # the calibration: the adopted model reads dTEMP; the reference is the mean in degC
    calibration = result.calibration
    assert calibration.extra['requires'] == ['TEMP']
    reference_c = float(np.mean((table.outputs[:, 6] - 32) * 5 / 9))
    assert calibration.reference_temperature_c == pytest.approx(reference_c, abs=1e-7)
    assert calibration.extra['channels']['TEMP']['unit_in_table'] == 'degF'
    assert 'dTEMP' in calibration.model('adopted').extra_variables


def test_calibration_yaml_carries_requires_and_the_live_path_applies_temperature(warmed, tmp_path):
    """Written and read back: `requires` and the references at the top of calibration.yaml; the
    live calibrator's model evaluates dTEMP as dT from a °C temperature, and a point's loads come
    back from its outputs at its own temperature better than without it.
    """
    from balance_calib.live.calibrator_core import model_loads

    table, result = warmed
    path = tmp_path / 'calibration.yaml'
    save_calibration(path, result.calibration)
    text = path.read_text()
    assert '\nrequires:\n- TEMP\n' in text and '\nchannels:\n  TEMP:\n' in text
    loaded = load_calibration(path)
    assert loaded.requires() == ('temperature',)
    active = activate(loaded)
    assert active.requires == ('temperature',)
    assert 'dT' in active.model.extra_variables
    outputs_mv = table.bridge_outputs  # V written: mV inside
    temperature_c = (table.outputs[:, 6] - 32) * 5 / 9
    warm = model_loads(active, outputs_mv, temperature_c=temperature_c)
    cold = model_loads(active, outputs_mv)  # no temperature: the base model, and says so
    assert warm[1] == loaded.adopted and cold[1] != loaded.adopted and cold[2]
    # each model against the total loads with its own series tares
    adopted_tares = loaded.extra['series_tares_si']
    total_warm = table.applied_loads_si + np.array([adopted_tares[str(s)] for s in table.series])
    total_cold = table.applied_loads_si + result.fits['direct'].tare_rows(table.series)
    capacity = table.load_capacity_si
    error_warm = np.sqrt(np.mean(((warm[0] - total_warm) / capacity) ** 2))
    error_cold = np.sqrt(np.mean(((cold[0] - total_cold) / capacity) ** 2))
    # warm: down to the noise (2e-4 of capacity); cold: the base model's σ (0.02-0.045 %)
    assert error_warm < 1.15 * NOISE_V / RATED_V and error_warm < 0.75 * error_cold, (
        error_warm,
        error_cold,
    )


def test_a_channel_no_topic_provides_is_refused_naming_it(tmp_path):
    """A position channel (mm) that changes the sensitivity of FZ: adopted as `channel` with its
    symbol; the calibration requires JAW, which no topic provides: refused at activation.
    """
    rng = np.random.default_rng(7)
    n = 6 * 41 + 6 * 30
    jaw_mm = rng.uniform(-2.0, 2.0, n)  # a clamp's position reset at random at every point
    base = _balance(np.random.default_rng(7))
    outputs = base.outputs.copy()
    outputs[:, 2] *= 1.0 + 2e-3 * jaw_mm  # FZ's bridge: 0.2 % per mm
    table = make_table(
        'jaw',
        LOADS,
        BRIDGES + ('JAW',),
        base.load_units,
        base.output_units + ('mm',),
        CAPACITY_LBS,
        base.applied_loads,
        np.hstack([outputs, jaw_mm[:, None]]),
        base.series,
    )
    result = calibrate_table(table, method='direct', statistics=False)
    _note('channel', result.report)
    channel = [e for e in result.report['effects'] if e['name'] == 'channel']
    assert channel and channel[0]['channel'] == 'JAW' and 'FZ' in channel[0]['components']
    assert all(t.startswith('dJAW') for t in channel[0]['terms'])
    assert result.report['requires'] == ['JAW']
    path = tmp_path / 'calibration.yaml'
    save_calibration(path, result.calibration)
    with pytest.raises(ConfigError, match='JAW.*no topic provides'):
        activate(load_calibration(path), source=str(path))
    activate(load_calibration(path), model='direct')  # the base model needs no channel
    # what balance_calibrator does at start-up: one line naming the file and the channel
    from balance_calib.live.parameters import PARAMETERS
    from balance_calib.live.session import CalibratorSession

    values = {name: spec.default for name, spec in PARAMETERS.items()}
    values.update(calibration_file=str(path), tare_file=str(tmp_path / 'tare.yaml'))
    with pytest.raises(ConfigError) as refused:
        CalibratorSession(lambda name: values[name], 'test', lambda level, line: None)
    message = str(refused.value)
    assert len(message.splitlines()) == 1 and str(path) in message and 'JAW' in message


def test_a_channel_that_tracks_a_load_is_not_an_effect():
    """A deflection in mm that follows FZ (and a little MY) with its own noise: its terms would
    fit the target; not examined, nothing adopted, and said.
    """
    rng = np.random.default_rng(11)
    probe = _balance(np.random.default_rng(11))
    relative = probe.applied_loads / CAPACITY_LBS
    deflection_mm = (
        0.8 * relative[:, 2] + 0.1 * relative[:, 4] + rng.normal(0, 0.002, len(relative))
    )
    table = _balance(np.random.default_rng(11), extra=[('DEFL', 'mm', deflection_mm)])
    report = calibrate_table(table, method='direct', statistics=False).report
    assert [e for e in report['effects'] if e.get('adopted')] == []
    assert 'requires' not in report
    assert any('DEFL follows the applied loads' in w for w in report['warnings'])
    assert report['sigma_pct_fs']['before'] == report['sigma_pct_fs']['after']


@pytest.mark.parametrize('seed', [3, 4])
def test_an_extra_channel_without_effect_adopts_nothing(seed):
    """Relative humidity wandering during the campaign, no effect on the balance."""
    rng = np.random.default_rng(seed)
    n = 6 * 41 + 6 * 30
    humidity = 45 + np.cumsum(rng.normal(0, 0.4, n))
    table = _balance(np.random.default_rng(seed), extra=[('RH', '%RH', humidity)])
    report = calibrate_table(table, method='direct', statistics=False).report
    assert [e for e in report['effects'] if e.get('adopted')] == [], report['effects']
    assert report['sigma_pct_fs_crossval']['before'] == report['sigma_pct_fs_crossval']['after']
    assert 'requires' not in report and report['unexplained'] == []


def _per_series(values_by_series, series):
    return np.array([values_by_series[s] for s in series], float)


def test_a_channel_constant_within_each_series_is_never_an_effect_alone():
    """Each series at its own bench temperature; the balance's zero moves with it (a per-series
    offset: what the series tares carry). Nothing is adopted: dTEMP alone is not offered.
    """
    rng = np.random.default_rng(5)
    probe = _balance(np.random.default_rng(5))
    labels = np.unique(probe.series)
    bench_f = dict(zip(labels, rng.uniform(60, 86, len(labels))))
    temperature = _per_series(bench_f, probe.series)
    table = _balance(
        np.random.default_rng(5),
        temperature_f=temperature,
        zero_per_k2=np.array([3e-4, -2e-4, 2e-4, 1e-4, -3e-4, 2e-4]),
    )
    report = calibrate_table(table, method='direct', statistics=False).report
    assert [e for e in report['effects'] if e.get('adopted')] == [], report['effects']
    assert report['unexplained'] == []


def test_a_sensitivity_on_a_series_constant_temperature_is_judged_by_whole_series():
    """The schedule run three times, each series at its own bench temperature, the sensitivity
    changing with it: adopted, only as products dTEMP*V (never dTEMP alone), judged with whole
    series left out. Run once (12 series, a load carried by 4 of them: 4! orders of their
    temperatures cannot show p < 1e-3) the loads are rightly not all listed.
    """
    rng = np.random.default_rng(6)
    probe = _balance(np.random.default_rng(6), repeats=3)
    labels = np.unique(probe.series)
    bench_f = dict(zip(labels, rng.uniform(55, 95, len(labels))))
    table = _balance(
        np.random.default_rng(6),
        temperature_f=_per_series(bench_f, probe.series),
        sensitivity_per_k=np.array([1.5e-3, -1.2e-3, 1e-3, -1.5e-3, 1.2e-3, 1e-3]),
        repeats=3,
    )
    report = calibrate_table(table, method='direct', statistics=False).report
    _note('series-level temperature', report)
    effect = [e for e in report['effects'] if e['name'] == 'temperature']
    assert effect, report['effects']
    assert set(effect[0]['components']) == set(LOADS)
    assert all('*' in t for t in effect[0]['terms']), effect[0]['terms']
    assert 'whole series left out' in effect[0]['evidence']
    floor = 100 * NOISE_V / RATED_V
    assert max(report['sigma_pct_fs']['after'].values()) < 1.15 * floor


def test_the_generated_tables_of_the_fit_tests_adopt_nothing():
    """table_cases' balances (a knee, eight gauges, cross-talk and squares): no temperature, no
    channel, no direction or order effect in them, and none adopted (a knee is odd in the load,
    not a sign effect).
    """
    import table_cases as tc

    tables = [
        tc.three_component_cell(np.random.default_rng(11), series_per_axis=3)[0],
        tc.eight_channel_sensor(np.random.default_rng(2))[0],
        tc.six_component_balance(np.random.default_rng(3))[0],
    ]
    for table in tables:
        report = calibrate_table(table, statistics=False, force=True).report
        assert [e for e in report['effects'] if e.get('adopted')] == [], (
            table.source,
            report['effects'],
        )


def _rising(x, series):
    """(N, 6) +1 / -1: the generator's own history, per bridge: each load's last move within
    its series (up or down, kept through unchanged points), starting up.
    """
    direction = np.ones_like(x)
    for s in np.unique(series):
        index = np.flatnonzero(series == s)
        for previous, i in zip(index[:-1], index[1:]):
            step = x[i] - x[previous]
            direction[i] = np.where(np.abs(step) > 1e-9, np.sign(step), direction[previous])
    return direction


def _order(series):
    order = np.zeros(len(series))
    for s in np.unique(series):
        mask = series == s
        order[mask] = np.arange(mask.sum())
    return order


@pytest.mark.parametrize(
    'name, shape, loads',
    [
        # a friction loop widest at mid-range, closed at the ends: dir·h·(1 - x²) on FZ and MY
        (
            'hysteresis',
            lambda x, s: 2e-3 * _rising(x, s) * (1 - x**2) * np.array([0, 0, 1, 0, 1, 0]),
            {'FZ', 'MY'},
        ),
        # FZ's bridge stiffer in compression, smoothly: b·x·tanh(x / 0.1) ≈ b|x|
        (
            'bidirectional',
            lambda x, s: 4e-3 * x * np.tanh(x / 0.1) * np.array([0, 0, 1, 0, 0, 0]),
            {'FZ'},
        ),
        # FX's zero creeping away from its series' start, 1 - exp(-i/12)
        (
            'zero_drift',
            lambda x, s: (
                2e-3 * (1 - np.exp(-_order(s) / 12.0))[:, None] * np.array([1, 0, 0, 0, 0, 0])
            ),
            {'FX'},
        ),
    ],
)
def test_a_loop_a_sign_step_and_a_creeping_zero_are_adopted(name, shape, loads):
    """Shapes the candidate terms hold only in part (dir, dir·V, |V|, order, order²): the
    family is named on the loads the data put it in, and their cross-validated σ comes down.
    """
    table = _balance(np.random.default_rng(21), shape=shape)
    report = calibrate_table(table, method='direct', statistics=False, force=True).report
    _note(name, report)
    adopted = [e for e in report['effects'] if e.get('adopted')]
    assert [e['name'] for e in adopted] == [name], report['effects']
    assert loads <= set(adopted[0]['components']), adopted[0]['components']
    before = report['sigma_pct_fs_crossval']['before']
    after = report['sigma_pct_fs_crossval']['after']
    for load in loads:
        assert after[load] < before[load], (load, before[load], after[load])
