"""`fit` on tables whose outputs are not the loads' own bridges: an 8-channel sensor with a term
file of its outputs, with --validate and --axes, and --excitation-v on outputs it cannot convert
(the gaps found after the units and 8-output reader landed).
"""

from dataclasses import replace
import json

import numpy as np
import pytest
import table_cases as tc

from balance_calib.cli import main
from balance_calib.tables.balfit_writer import write_table


def _halves(table):
    """The calibration table split by points into two tables of the same series."""
    keep = np.arange(table.points) % 4 != 0

    def part(mask):
        return replace(
            table,
            point_id=tuple(np.array(table.point_id)[mask]),
            series=table.series[mask],
            point_zero_set=tuple(np.array(table.point_zero_set)[mask]),
            applied_loads=table.applied_loads[mask],
            outputs=table.outputs[mask],
        )

    return part(keep), part(~keep)


def test_a_term_file_of_eight_outputs_fits_direct_with_validation_and_axes(tmp_path, capsys):
    table, _ = tc.eight_channel_sensor(np.random.default_rng(3), poses=80)
    cal, val = _halves(replace(table, load_symbols=('A1', 'A2', 'A3', 'B1', 'B2', 'B3')))
    paths = [write_table(tmp_path / f'{n}.csv', t) for n, t in (('cal', cal), ('val', val))]
    terms = tmp_path / 'bridges.txt'
    names = list(table.output_symbols) + [f'{g}^3' for g in table.output_symbols]
    terms.write_text('# the eight bridges and their cubes\n' + ', '.join(names) + '\n')
    for method in ('direct', 'auto'):
        out = tmp_path / method
        code = main(
            [
                'fit',
                str(paths[0]),
                '--validate',
                str(paths[1]),
                '--method',
                method,
                '--terms',
                str(terms),
                '--axes',
                'FX,FY,FZ,MX,MY,MZ',
                '--out',
                str(out),
                '--no-plots',
            ]
        )
        assert code == 0, capsys.readouterr().err
        report = json.loads((out / 'report.json').read_text())
        assert report['method'] == 'direct' and report['terms'] == names
        assert report['load_symbols'] == ['FX', 'FY', 'FZ', 'MX', 'MY', 'MZ']
        assert report['output_symbols'] == list(table.output_symbols)
        assert set(report['sigma_pct_capacity']['validation']) == set(report['load_symbols'])


@pytest.mark.parametrize('unit', ['counts', '-', 'mV'])
def test_an_excitation_on_outputs_that_are_not_ratios_is_refused(tmp_path, capsys, unit):
    table, _ = tc.six_component_balance(np.random.default_rng(4))
    path = write_table(
        tmp_path / 'daq.csv',
        replace(table, output_units=(unit,) * 6, output_capacity=np.full(6, np.nan)),
    )
    out = tmp_path / 'out'
    assert main(['fit', str(path), '--excitation-v', '5', '--out', str(out), '--no-plots']) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and 'daq.csv' in err and unit in err, err
    assert '--excitation-v' in err and 'leave' in err and not out.exists()
    # without the option the same table fits, in its own output unit
    assert main(['fit', str(path), '--out', str(out), '--no-plots']) == 0
