"""Units real acquisition systems write in calibration tables: ADC counts and dimensionless outputs
(the fit then works in those units), gram-force, ounce-force, kN·m, N·mm loads; an unknown unit
is one line naming the file, row, column and the unit, listing the known ones.
"""

import dataclasses

import numpy as np
import pytest

from balance_calib.calibration_file import load_calibration
from balance_calib.cli import main
from balance_calib.live.calibrator_core import compute_wrench
from balance_calib.live.stream import wrench_uncertainty
from balance_calib.model.active_calibration import activate
from balance_calib.tables import synthetic as sy
from balance_calib.tables.balfit_reader import read_table
from balance_calib.tables.balfit_writer import write_table
from balance_calib.tables.units import unit_factor

# First principles, written out here rather than taken from the package: 1 lb = 0.45359237 kg,
# g_n = 9.80665 m/s², 1 in = 0.0254 m, 1 oz = 1/16 lb (avoirdupois), 1 gf = 1 g × g_n.
KG_PER_LB, G_N, M_PER_IN = 0.45359237, 9.80665, 0.0254
N_PER_LBF = KG_PER_LB * G_N
N_PER_OZF = KG_PER_LB * G_N / 16


@pytest.mark.parametrize(
    'unit, factor, internal, kind',
    [
        ('gf', 1e-3 * G_N, 'N', 'force'),
        ('g', 1e-3 * G_N, 'N', 'force'),
        ('GF', 1e-3 * G_N, 'N', 'force'),
        ('ozf', N_PER_OZF, 'N', 'force'),
        ('lbs', N_PER_LBF, 'N', 'force'),
        ('kgf', G_N, 'N', 'force'),
        ('kN', 1e3, 'N', 'force'),
        ('in-ozf', N_PER_OZF * M_PER_IN, 'N·m', 'moment'),
        ('in-lbs', N_PER_LBF * M_PER_IN, 'N·m', 'moment'),
        ('kN-m', 1e3, 'N·m', 'moment'),
        ('N-mm', 1e-3, 'N·m', 'moment'),
        ('N mm', 1e-3, 'N·m', 'moment'),
        ('counts', 1.0, 'counts', 'output'),
        ('-', 1.0, '-', 'output'),
        ('microV/V', 1e-3, 'mV/V', 'output'),
    ],
)
def test_unit_factors_are_the_first_principles_values(unit, factor, internal, kind):
    found = unit_factor(unit)
    assert found is not None, unit
    assert found[0] == pytest.approx(factor, rel=1e-15)
    assert found[1:] == (internal, kind)


def test_ounce_force_values_of_the_issue():
    # the issue's figures, to their written digits
    assert abs(unit_factor('ozf')[0] - 0.27801385) < 5e-9
    assert abs(unit_factor('in-ozf')[0] - 0.0070615518) < 5e-11
    assert unit_factor('gf')[0] == pytest.approx(9.80665e-3, rel=1e-15)


def _table_in(table, load_units, output_unit, per_mv):
    """The same campaign written in other units: loads converted exactly, outputs x per_mv."""
    old = np.array([unit_factor(u)[0] for u in table.load_units])
    new = np.array([unit_factor(u)[0] for u in load_units])
    return dataclasses.replace(
        table,
        load_units=tuple(load_units),
        output_units=(output_unit,) * len(table.output_units),
        load_capacity=table.load_capacity * old / new,
        applied_loads=table.applied_loads * old / new,
        output_capacity=table.output_capacity * per_mv,
        zero_outputs=table.zero_outputs * per_mv,
        outputs=table.outputs * per_mv,
    )


@pytest.fixture(scope='module')
def campaign(tmp_path_factory):
    rng = np.random.default_rng(31)
    truth = sy.direct_truth(rng, nonlinear_fraction=0.008)
    schedule = sy.support_schedule(rng, 11, 16)
    tares = sy.tares_for(rng, np.unique(schedule.series))
    noise = 0.0003 * sy.capacity_si()
    applied, outputs_mv = sy.direct_campaign(rng, truth, schedule, tares, noise)
    table = sy.make_table(
        applied, outputs_mv, schedule.series, natural_zero_mv=[0.05, -0.1, 0.2, 0.0, 0.1, -0.3]
    )
    # the reference in N, N-m and mV
    reference = _table_in(table, ('N',) * 3 + ('N-m',) * 3, 'mV', 1.0)
    directory = tmp_path_factory.mktemp('units')
    write_table(directory / 'si.csv', reference)
    assert (
        main(
            [
                'fit',
                str(directory / 'si.csv'),
                '--out',
                str(directory / 'si'),
                '--method',
                'direct',
                '--terms',
                'tm663-cubic',
                '--no-plots',
            ]
        )
        == 0
    )
    return table, outputs_mv, directory


@pytest.mark.parametrize(
    'load_units, output_unit, per_mv',
    [
        (('gf',) * 3 + ('in-ozf',) * 3, 'counts', 8388.608),  # a 24-bit ADC: 2^23 counts per V
        (('ozf',) * 3 + ('N-mm',) * 3, '-', 2.0e-4),  # dimensionless ratio, 1/5000 per mV
        (('g',) * 3 + ('kN-m',) * 3, 'counts', 131.072),
    ],
)
def test_a_table_in_lab_units_fits_the_same_calibration_as_in_si(
    campaign, load_units, output_unit, per_mv
):
    table, outputs_mv, directory = campaign
    name = f'{load_units[0]}-{output_unit}'
    lab = _table_in(table, load_units, output_unit, per_mv)
    write_table(directory / f'{name}.csv', lab)
    read_back = read_table(directory / f'{name}.csv')
    np.testing.assert_allclose(
        read_back.applied_loads_si, table.applied_loads_si, rtol=1e-12, atol=1e-9
    )
    assert read_back.bridge_columns == tuple(range(6))
    assert read_back.output_internal_unit == output_unit
    assert (
        main(
            [
                'fit',
                str(directory / f'{name}.csv'),
                '--out',
                str(directory / name),
                '--method',
                'direct',
                '--terms',
                'tm663-cubic',
                '--no-plots',
            ]
        )
        == 0
    )

    si = load_calibration(directory / 'si' / 'calibration.yaml')
    in_lab = load_calibration(directory / name / 'calibration.yaml')
    assert in_lab.extra['output_unit'] == output_unit and si.extra['output_unit'] == 'mV'
    assert in_lab.extra['load_units_si'] == ['N'] * 3 + ['N·m'] * 3
    header = (directory / name / 'calibration.yaml').read_text().splitlines()[0]
    assert header.endswith(f'from outputs in {output_unit}.'), header
    # the same loads (SI) from the same physical outputs, written in the other unit
    samples_mv = outputs_mv[::7]
    expected = si.model().loads(samples_mv)
    np.testing.assert_allclose(
        in_lab.model().loads(samples_mv * per_mv),
        expected,
        rtol=1e-7,
        atol=1e-9 * sy.capacity_si().max(),
    )
    np.testing.assert_allclose(in_lab.capacity, si.capacity, rtol=1e-12)
    for key in ('series_tares_si', 'series_tares_sigma_si'):
        for series, values in si.extra[key].items():
            np.testing.assert_allclose(in_lab.extra[key][series], values, rtol=1e-6, atol=1e-9)
    assert in_lab.sigma_pct_fs == pytest.approx(si.sigma_pct_fs, rel=1e-6)
    np.testing.assert_allclose(in_lab.rated_output_mv, si.rated_output_mv * per_mv, rtol=1e-12)

    # the live core takes the raw outputs in the calibration's own unit: same wrench, same
    # uncertainty, no sample taken for saturated (the output range is in that unit too)
    live_si, live_lab = activate(si), activate(in_lab)
    raw_mv = np.zeros((len(samples_mv), 6))
    raw_mv[:] = samples_mv
    batch_si = compute_wrench(live_si, raw_mv)
    batch_lab = compute_wrench(live_lab, raw_mv * per_mv)
    assert batch_lab.accepted.all() and batch_si.accepted.all()
    np.testing.assert_allclose(
        batch_lab.wrench_tunnel,
        batch_si.wrench_tunnel,
        rtol=1e-7,
        atol=1e-9 * sy.capacity_si().max(),
    )
    one = compute_wrench(live_lab, raw_mv[:1] * per_mv)  # the one-sample path
    np.testing.assert_allclose(
        one.wrench_tunnel,
        batch_si.wrench_tunnel[:1],
        rtol=1e-7,
        atol=1e-9 * sy.capacity_si().max(),
    )
    np.testing.assert_allclose(
        wrench_uncertainty(live_lab, raw_mv * per_mv, None),
        wrench_uncertainty(live_si, raw_mv, None),
        rtol=1e-5,
    )

    # the zero's reply states the outputs in the calibration's unit, not in mV
    from live_cases import take

    from balance_calib.live.stream import LiveCalibrator

    zero = take(LiveCalibrator(live_lab), 'zero', np.tile(raw_mv[0] * per_mv, (10, 1)))
    assert zero.ok, zero.message
    assert f' {output_unit}' in zero.message and ' mV' not in zero.message, zero.message

    # the tares in the report are in the file's own units: SI tare / the unit's factor
    import json

    report_si = json.loads((directory / 'si' / 'report.json').read_text())
    report_lab = json.loads((directory / name / 'report.json').read_text())
    factors = np.array([unit_factor(u)[0] for u in load_units])
    for series, tares in report_si['series_tares'].items():
        np.testing.assert_allclose(
            [report_lab['series_tares'][series][s] for s in sy.LOADS],
            np.array([tares[s] for s in sy.LOADS]) / factors,
            rtol=1e-5,
            atol=1e-9,
        )
    assert report_lab['output_units'] == [output_unit] * 6


@pytest.mark.parametrize('column, unit', [(4, 'slug'), (11, 'mV/mA')])
def test_an_unknown_unit_is_one_line_naming_file_row_column_and_the_known_units(
    tmp_path, capsys, column, unit
):
    rng = np.random.default_rng(2)
    schedule = sy.support_schedule(rng, 5, 6)
    outputs = np.zeros((len(schedule.series), 6))
    table = sy.make_table(schedule.applied_si, outputs, schedule.series)
    units = list(table.load_units + table.output_units)
    units[column - 4] = unit
    path = tmp_path / 'bad.csv'
    write_table(
        path,
        dataclasses.replace(table, load_units=tuple(units[:6]), output_units=tuple(units[6:])),
    )
    lines = path.read_text().splitlines()
    row = [i for i, line in enumerate(lines, 1) if line.startswith('; units')][0] + 1
    out = tmp_path / 'out'
    assert main(['fit', str(path), '--out', str(out), '--method', 'direct']) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    letter = 'ABCDEFGHIJKLMNOP'[column]
    symbol = (sy.LOADS + sy.OUTPUTS)[column - 4]
    expected = f'{path}: row {row}, column {letter}: unit {unit!r} of {symbol} is not known'
    assert expected in err, err
    for known in ('counts', 'gf', 'ozf', 'in-ozf', 'kN-m', 'N-mm', 'mV/V', 'lbs'):
        assert known in err
    assert not out.exists()


def test_the_live_session_takes_a_counts_calibration_only_with_unconverted_input(campaign):
    """balance_calibrator's input_units turn balance/raw into mV: for a calibration in counts the
    raw outputs must pass as they are (input_units mV); a ratiometric setting is refused in one
    line, at start-up and at runtime, since every load would be off by the excitation.
    """
    from balance_calib.calibration_file import ConfigError
    from balance_calib.live.parameters import PARAMETERS
    from balance_calib.live.session import CalibratorSession

    table, _, directory = campaign
    write_table(
        directory / 'live-counts.csv',
        _table_in(table, ('gf',) * 3 + ('in-ozf',) * 3, 'counts', 8388.608),
    )
    assert (
        main(
            [
                'fit',
                str(directory / 'live-counts.csv'),
                '--out',
                str(directory / 'live-counts'),
                '--method',
                'direct',
                '--terms',
                'tm663-cubic',
                '--no-plots',
            ]
        )
        == 0
    )
    path = directory / 'live-counts' / 'calibration.yaml'
    values = {name: spec.default for name, spec in PARAMETERS.items()}
    values.update(calibration_file=str(path), tare_file=str(directory / 'tare.yaml'))
    lines = []
    session = CalibratorSession(
        lambda name: values[name], 'test', lambda level, line: lines.append(line)
    )
    assert any('balance/raw carries bridge outputs in counts' in line for line in lines), lines
    with pytest.raises(
        ValueError,
        match=r'input_units = mV/V turns balance/raw into mV, '
        r'but .* takes bridge outputs in counts: '
        r'set input_units mV',
    ):
        session.validate({'input_units': 'mV/V', 'excitation_v': 5.0})
    values.update(input_units='microV/V', excitation_v=5.0)
    with pytest.raises(ConfigError) as refused:
        CalibratorSession(lambda name: values[name], 'test', lambda level, line: None)
    assert len(str(refused.value).splitlines()) == 1 and str(path) in str(refused.value)
