"""BALFIT-style calibration tables: reading (units, natural zeros, series, switched-off points),
writing back identically, and one clear line for every malformed case (nothing written).
"""

import numpy as np
import pytest
from table_cases import fix_width, HAND_TABLE

from balance_calib.cli import main
from balance_calib.tables.balfit_reader import read_table, TableError
from balance_calib.tables.balfit_writer import table_text, write_table
from balance_calib.tables.synthetic import make_table, support_schedule

LBF_N = 4.4482216152605  # lbf in N (exact)
IN_LBF_NM = LBF_N * 0.0254


@pytest.fixture
def hand_table(tmp_path):
    path = tmp_path / 'hand.csv'
    path.write_text(fix_width(HAND_TABLE))
    return path


def test_hand_table_units_natural_zero_series_and_switched_off_point(hand_table):
    table = read_table(hand_table)
    assert table.balance_name == 'MK-1, sting 2'
    assert table.load_symbols == ('N1', 'RM') and table.output_symbols == ('rN1', 'rRM', 'TC')
    assert table.bridge_symbols == ('rN1', 'rRM')  # the temperature channel is not a bridge
    assert table.point_id == ('P1', 'P2', 'P4', 'P5') and table.disabled_points == 1
    assert table.series.tolist() == [1, 1, 2, 2]
    # SI: 100 lbs, 50 in-lbs
    np.testing.assert_allclose(table.load_capacity_si, [100 * LBF_N, 50 * IN_LBF_NM], rtol=1e-15)
    np.testing.assert_allclose(table.applied_loads_si[1], [50 * LBF_N, 0.0], rtol=1e-15)
    # natural zero: mean over roll angles (10+12+14+12)/4 = 12, (-4-6-8-6)/4 = -6 microV/V
    np.testing.assert_allclose(table.natural_zeros['A'][:2], [12.0, -6.0])
    # P5 names no set: the file has one, so that one; outputs in mV/V after the zero
    np.testing.assert_allclose(
        table.bridge_outputs, [[0, 0], [0.5, 0], [0, 0.5], [0, -0.5]], atol=1e-15
    )
    assert table.output_internal_unit == 'mV/V'


def test_writer_then_reader_gives_identical_tables(tmp_path, hand_table):
    rng = np.random.default_rng(3)
    schedule = support_schedule(rng, 5, 7)
    outputs = rng.normal(0, 2, (len(schedule.series), 6)) / 3.0  # digits that do not round nicely
    generated = make_table(
        schedule.applied_si * np.pi,
        outputs,
        schedule.series,
        natural_zero_mv=rng.normal(0, 0.3, 6),
    )
    for original in (generated, read_table(hand_table)):
        path = write_table(tmp_path / 'out.csv', original)
        again = read_table(path)
        for key in (
            'load_symbols',
            'output_symbols',
            'load_units',
            'output_units',
            'point_id',
            'point_zero_set',
            'zero_set',
            'zero_id',
            'balance_name',
            'description',
        ):
            assert getattr(again, key) == getattr(original, key), key
        for key in (
            'applied_loads',
            'outputs',
            'series',
            'zero_outputs',
            'zero_roll_deg',
            'load_capacity',
        ):
            assert np.array_equal(getattr(again, key), getattr(original, key)), key
        assert np.array_equal(np.isnan(again.output_capacity), np.isnan(original.output_capacity))
        assert table_text(again) == table_text(original)


def _malformed(text, row_text, replacement):
    lines = text.splitlines()
    index = [i for i, line in enumerate(lines) if line.startswith(row_text)][0]
    lines[index] = replacement
    return '\n'.join(lines) + '\n', index + 1


@pytest.mark.parametrize(
    'row_text, replacement, expected',
    [
        (',P2,1,A,50', ',P2,1,A,50,0,512,-6', 'row {row}: 8 fields where row 1 has 9'),  # ragged
        (
            ',,,,lbs',
            ',,,,lbs,in-lbs,microV/V,,degF',
            'row {row}, column H: symbol rRM has no unit',
        ),
        (',P2,1,A,50', ',P2,0,A,50,0,512,-6,70', "row {row}, column C: load series '0'"),
        (',P2,1,A,50', ',P2,1.5,A,50,0,512,-6,70', "row {row}, column C: load series '1.5'"),
        (',P2,1,A,50', ',P2,B,A,50,0,512,-6,70', "row {row}, column C: load series 'B'"),
        (
            ',P2,1,A,50',
            ',P2,1,A,fifty,0,512,-6,70',
            "row {row}, column E: load N1 'fifty' is not a number",
        ),
        (',P4,2,A', ',P4,2,A,0,25,12,4 94,71', 'row {row}, column H: output rRM'),
    ],
)
def test_malformed_tables_fail_with_one_line_naming_file_row_column(
    tmp_path, capsys, row_text, replacement, expected
):
    text, row = _malformed(fix_width(HAND_TABLE), row_text, replacement)
    path = tmp_path / 'bad.csv'
    path.write_text(text)
    out = tmp_path / 'out'
    status = main(
        ['fit', str(path), '--out', str(out), '--method', 'direct', '--terms', 'tm663-cubic']
    )
    err = capsys.readouterr().err.strip()
    assert status != 0
    assert len(err.splitlines()) == 1
    assert str(path) in err and expected.format(row=row) in err, err
    assert not out.exists()


def test_a_natural_zero_set_that_does_not_exist_is_named(tmp_path, capsys):
    text = fix_width(HAND_TABLE).replace(',NZ3,A,180', ',NZ3,B,180')  # two sets now: A and B
    text, row = _malformed(text, ',P4,2,A', ',P4,2,C,0,25,12,494,71')
    path = tmp_path / 'bad.csv'
    path.write_text(text)
    out = tmp_path / 'out'
    assert main(['fit', str(path), '--out', str(out)]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert f"row {row}, column D: natural-zero set 'C' does not exist" in err and str(path) in err
    assert not out.exists()


def test_reader_errors_are_table_errors_naming_the_file(tmp_path):
    path = tmp_path / 'empty.csv'
    path.write_text('')
    with pytest.raises(TableError, match='empty.csv'):
        read_table(path)
    with pytest.raises(TableError, match='cannot read'):
        read_table(tmp_path / 'missing.csv')


def test_a_validation_file_without_natural_zeros_uses_the_calibration_files(tmp_path, hand_table):
    calibration = read_table(hand_table)
    lines = fix_width(HAND_TABLE).splitlines()
    kept = [line for line in lines if not line.startswith(',NZ')]  # no natural-zero readings
    path = tmp_path / 'val.csv'
    path.write_text('\n'.join(kept) + '\n')
    with pytest.raises(
        TableError, match=r"column D: natural-zero set 'A' does not exist \(the file has none\)"
    ):
        read_table(path)
    validation = read_table(path, natural_zeros_from=calibration)
    np.testing.assert_array_equal(validation.bridge_outputs, calibration.bridge_outputs)
