"""balance-calib fit options: explicit methods, a term file, mV/V tables with an excitation, and a
validation file whose series the calibration never saw (refused: its tare is unknown).
"""

import json

import numpy as np
import yaml

from balance_calib.calibration_file import load_calibration
from balance_calib.cli import main
from balance_calib.tables import synthetic as sy
from balance_calib.tables.balfit_writer import write_table


def _table(rng, path, pair_points=25, noise_mv=0.0006, first_series=1):
    truth = sy.direct_truth(np.random.default_rng(1))
    schedule = sy.support_schedule(rng, 15, pair_points, first_series=first_series)
    tares = sy.tares_for(np.random.default_rng(2), range(1, 100))
    applied, outputs = sy.direct_campaign(rng, truth, schedule, tares, 0.0002 * sy.capacity_si())
    write_table(path, sy.make_table(applied, outputs, schedule.series))
    return truth, tares


def test_term_file_and_explicit_method(tmp_path, capsys):
    rng = np.random.default_rng(3)
    _table(rng, tmp_path / 'cal.csv')
    terms = tmp_path / 'terms.txt'
    # written in the load symbols; the direct method maps them onto the outputs by column
    terms.write_text('# linear and squares\nFX, FY, FZ, MX, MY, MZ\nFX^2\nFZ*MY\n1\n')
    assert (
        main(
            [
                'fit',
                str(tmp_path / 'cal.csv'),
                '--out',
                str(tmp_path / 'out'),
                '--method',
                'direct',
                '--terms',
                str(terms),
                '--no-plots',
            ]
        )
        == 0
    )
    report = json.loads((tmp_path / 'out' / 'report.json').read_text())
    assert report['method'] == 'direct' and 'iterative' not in report['methods_compared']
    # constant dropped
    assert report['terms'] == ['FXV', 'FYV', 'FZV', 'MXV', 'MYV', 'MZV', 'FXV^2', 'FZV*MYV']
    assert set(report['term_statistics']['direct'][0]) >= {'term', 'vif', 'p_value', 'press_ratio'}
    calibration = load_calibration(tmp_path / 'out' / 'calibration.yaml')
    assert calibration.model().term_names == tuple(report['terms'])


def test_unknown_term_and_unknown_validation_series_are_refused(tmp_path, capsys):
    rng = np.random.default_rng(4)
    _table(rng, tmp_path / 'cal.csv')
    _table(rng, tmp_path / 'val.csv', pair_points=5, first_series=40)
    bad_terms = tmp_path / 'terms.txt'
    bad_terms.write_text('FX, QQ\n')
    assert (
        main(
            [
                'fit',
                str(tmp_path / 'cal.csv'),
                '--out',
                str(tmp_path / 'a'),
                '--terms',
                str(bad_terms),
            ]
        )
        != 0
    )
    assert 'QQ' in capsys.readouterr().err
    assert not (tmp_path / 'a').exists()
    # a validation series the calibration lacks (another setup) is not
    # refused; its tare is estimated from its own points with the model held fixed
    assert (
        main(
            [
                'fit',
                str(tmp_path / 'cal.csv'),
                '--out',
                str(tmp_path / 'b'),
                '--method',
                'direct',
                '--validate',
                str(tmp_path / 'val.csv'),
                '--no-plots',
            ]
        )
        == 0
    )
    report = json.loads((tmp_path / 'b' / 'report.json').read_text())
    assert (
        '40' in report['validation_series_tares']
        and '40' in report['validation_series_tares_sigma']
    )


def test_millivolt_per_volt_tables_with_an_excitation_give_millivolt_calibrations(
    tmp_path, capsys
):
    rng = np.random.default_rng(5)
    _table(rng, tmp_path / 'mv.csv')
    # the same table with outputs as mV/V at 5 V excitation
    text = (tmp_path / 'mv.csv').read_text().splitlines()
    from balance_calib.tables.balfit_reader import read_table

    table = read_table(tmp_path / 'mv.csv')
    from dataclasses import replace

    ratio = replace(
        table,
        output_units=('microV/V',) * 6,
        outputs=table.outputs / 5.0 * 1000.0,
        zero_outputs=table.zero_outputs / 5.0 * 1000.0,
        output_capacity=table.output_capacity / 5 * 1000,
    )
    write_table(tmp_path / 'ratio.csv', ratio)
    assert text
    for name, extra in (('mv', []), ('ratio', ['--excitation-v', '5'])):
        assert (
            main(
                [
                    'fit',
                    str(tmp_path / f'{name}.csv'),
                    '--out',
                    str(tmp_path / name),
                    '--method',
                    'direct',
                    '--no-plots',
                ]
                + extra
            )
            == 0
        )
    a = load_calibration(tmp_path / 'mv' / 'calibration.yaml').model()
    b = load_calibration(tmp_path / 'ratio' / 'calibration.yaml').model()
    np.testing.assert_allclose(
        a.loads(table.bridge_outputs),
        b.loads(table.bridge_outputs),
        atol=1e-9 * sy.capacity_si().max(),
    )
    assert (
        yaml.safe_load((tmp_path / 'ratio' / 'calibration.yaml').read_text())['extra'][
            'output_unit'
        ]
        == 'mV'
    )


def test_axes_option_names_balfit_symbols_for_the_live_node(tmp_path, capsys):
    from dataclasses import replace

    from balance_calib.tables.balfit_reader import read_table

    rng = np.random.default_rng(6)
    _table(rng, tmp_path / 'tm.csv')
    table = read_table(tmp_path / 'tm.csv')
    write_table(
        tmp_path / 'balfit.csv',
        replace(
            table,
            load_symbols=('AF', 'S1', 'N1', 'RM', 'N2', 'S2'),
            output_symbols=('rAF', 'rS1', 'rN1', 'rRM', 'rN2', 'rS2'),
        ),
    )
    assert (
        main(
            [
                'fit',
                str(tmp_path / 'balfit.csv'),
                '--out',
                str(tmp_path / 'plain'),
                '--method',
                'direct',
                '--no-plots',
            ]
        )
        == 0
    )
    report = json.loads((tmp_path / 'plain' / 'report.json').read_text())
    assert any('balance_calibrator cannot run' in w for w in report['warnings'])
    assert (
        main(
            [
                'fit',
                str(tmp_path / 'balfit.csv'),
                '--out',
                str(tmp_path / 'named'),
                '--method',
                'direct',
                '--no-plots',
                '--axes',
                'FX,FY,FZ,MX,MY,MZ',
            ]
        )
        == 0
    )
    calibration = load_calibration(tmp_path / 'named' / 'calibration.yaml')
    assert calibration.components == sy.LOADS and calibration.bridge_outputs == sy.OUTPUTS
    np.testing.assert_allclose(
        calibration.model().loads(table.bridge_outputs),
        load_calibration(tmp_path / 'plain' / 'calibration.yaml')
        .model()
        .loads(table.bridge_outputs),
        rtol=1e-12,
        atol=1e-9,
    )
    assert (
        main(
            [
                'fit',
                str(tmp_path / 'balfit.csv'),
                '--out',
                str(tmp_path / 'bad'),
                '--axes',
                'FX,FY',
            ]
        )
        != 0
    )
    assert '--axes' in capsys.readouterr().err and not (tmp_path / 'bad').exists()


def test_auto_choice_lower_crossvalidated_sigma_unless_nearly_equal_and_structured():
    from types import SimpleNamespace

    from balance_calib.tables.calibrate import _choose

    rng = np.random.default_rng(9)
    normal = rng.normal(0, 1, (2000, 2))
    # two bumps: structure
    bimodal = np.sign(rng.normal(size=(2000, 2))) + rng.normal(0, 0.2, (2000, 2))
    bimodal /= bimodal.std(axis=0)
    capacity = np.array([100.0, 100.0])

    def fit(residuals, scale):
        return SimpleNamespace(
            load_residuals=residuals * scale, press_load_residuals=residuals * scale
        )

    close = {'direct': fit(bimodal, 1.00), 'iterative': fit(normal / normal.std(axis=0), 1.01)}
    chosen, why = _choose(close, capacity, ('A', 'B'))
    assert (
        chosen == 'iterative'
        and 'fewer non-normal' in why
        and 'direct residuals non-normal on A' in why
    )
    apart = {'direct': fit(bimodal, 1.00), 'iterative': fit(normal / normal.std(axis=0), 1.10)}
    chosen, why = _choose(apart, capacity, ('A', 'B'))
    assert chosen == 'direct' and 'fewer non-normal' not in why


def test_a_campaign_split_over_two_files_fits_as_one_and_the_report_has_the_promised_keys(
    tmp_path, capsys
):
    from dataclasses import replace

    from balance_calib.tables.balfit_reader import read_table

    rng = np.random.default_rng(7)
    _table(rng, tmp_path / 'whole.csv')
    whole = read_table(tmp_path / 'whole.csv')
    half = whole.points // 2
    for name, part in (('a', slice(0, half)), ('b', slice(half, None))):
        write_table(
            tmp_path / f'{name}.csv',
            replace(
                whole,
                point_id=whole.point_id[part],
                series=whole.series[part],
                point_zero_set=whole.point_zero_set[part],
                applied_loads=whole.applied_loads[part],
                outputs=whole.outputs[part],
            ),
        )
    for name, files in (('one', ['whole.csv']), ('two', ['a.csv', 'b.csv'])):
        assert (
            main(
                [
                    'fit',
                    *[str(tmp_path / f) for f in files],
                    '--out',
                    str(tmp_path / name),
                    '--method',
                    'direct',
                    '--no-plots',
                ]
            )
            == 0
        )
    one, two = (json.loads((tmp_path / n / 'report.json').read_text()) for n in ('one', 'two'))
    assert (
        one['series_tares'] == two['series_tares']
        and one['sigma_pct_capacity'] == two['sigma_pct_capacity']
    )
    promised = {
        'balance',
        'points',
        'base_model',
        'sigma_pct_fs',
        'sigma_pct_fs_crossval',
        'effects',
        'adopted',
        'unexplained',
        'warnings',
        'format',
        'method',
        'terms',
        'load_symbols',
        'load_units',
        'capacities',
        'sigma_pct_capacity',
        'series_tares',
        'series_tares_sigma',
        'prediction_interval_95_pct_capacity',
        'methods_compared',
    }
    assert promised <= set(one) and one['format'] == 'balfit'
    assert one['load_units'] == ['lbs'] * 3 + ['in-lbs'] * 3 and one['capacities']['FZ'] == 800.0
    assert set(one['points']) == {'calibration', 'validation'}
    assert (tmp_path / 'one' / 'report.md').read_text().startswith('# Calibration from tables')
