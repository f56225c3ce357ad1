"""Balances with more bridges than loads (an 8-channel six-component sensor): the table reader
tells the 6 loads from the 8 outputs (by the natural zeros' blank cells, and by the units when a
file has neither natural zeros nor blank output capacities), the calibration file carries the 8
outputs, and balance_calibrator, which reads six raw channels, refuses it in one line.
"""

import dataclasses

from live_cases import CHANNELS, eight_output_calibration
import numpy as np
import pytest

from balance_calib.calibration_file import (
    Calibration,
    ConfigError,
    load_calibration,
    save_calibration,
)
from balance_calib.model.active_calibration import activate
from balance_calib.model.balance_model import BalanceModel
from balance_calib.model.terms import parse_terms
from balance_calib.tables import synthetic as sy
from balance_calib.tables.balfit_reader import CalibrationTable, read_table, TableError
from balance_calib.tables.balfit_writer import table_text, write_table


def eight_channel_table(rng, *, natural_zeros: bool, output_capacity: bool) -> CalibrationTable:
    """6 loads (lbs, in-lbs) and 8 bridge outputs (mV/V), outputs = A·(applied + tare) + noise."""
    schedule = sy.support_schedule(rng, 5, 6)
    n = len(schedule.series)
    tares = sy.tares_for(rng, np.unique(schedule.series))
    totals = schedule.applied_si + np.array([tares[int(s)] for s in schedule.series])
    sensitivity = rng.normal(0.0, 1.0, (8, 6)) * 2.0 / sy.capacity_si()  # mV/V at capacity ~ 2
    zero = rng.uniform(-0.05, 0.05, 8)
    outputs = totals @ sensitivity.T + rng.normal(0.0, 1e-4, (n, 8)) + zero
    factor = sy.capacity_si() / sy.CAPACITY_FILE
    return CalibrationTable(
        'eight.csv',
        'DATA_FOR_ITERATIVE_REGRESSION_ANALYSIS',
        'sensor-8',
        'eight channels',
        sy.LOADS,
        CHANNELS,
        sy.UNITS,
        ('mV/V',) * 8,
        sy.CAPACITY_FILE.copy(),
        np.full(8, 2.5) if output_capacity else np.full(8, np.nan),
        ('NZ1', 'NZ2') if natural_zeros else (),
        ('Z',) * (2 if natural_zeros else 0),
        np.array([0.0, 180.0])[: 2 if natural_zeros else 0],
        np.array([zero, zero]) if natural_zeros else np.zeros((0, 8)),
        tuple(f'P{i + 1}' for i in range(n)),
        schedule.series,
        ('Z' if natural_zeros else '',) * n,
        schedule.applied_si / factor,
        outputs,
    )


@pytest.mark.parametrize(
    'natural_zeros, output_capacity', [(True, False), (True, True), (False, True), (False, False)]
)
def test_six_loads_and_eight_outputs_are_read_as_such(tmp_path, natural_zeros, output_capacity):
    table = eight_channel_table(
        np.random.default_rng(3), natural_zeros=natural_zeros, output_capacity=output_capacity
    )
    path = write_table(tmp_path / 'eight.csv', table)
    read = read_table(path)
    assert read.load_symbols == sy.LOADS and read.output_symbols == CHANNELS
    assert read.bridge_columns == tuple(range(8)) and read.output_internal_unit == 'mV/V'
    np.testing.assert_array_equal(read.applied_loads, table.applied_loads)
    np.testing.assert_array_equal(read.outputs, table.outputs)
    if natural_zeros:  # outputs less the natural zero, the same for all points here
        np.testing.assert_allclose(
            read.bridge_outputs, table.outputs - table.zero_outputs[0], atol=1e-15
        )
    if output_capacity:
        np.testing.assert_array_equal(read.output_capacity, np.full(8, 2.5))
    assert table_text(read) == path.read_text()  # the writer gives the file back


def test_units_that_do_not_tell_loads_from_outputs_fall_back_to_half_the_symbols(tmp_path):
    # a load unit among the outputs: the units do not tell, half of 14 symbols is 7 loads
    table = eight_channel_table(
        np.random.default_rng(4), natural_zeros=False, output_capacity=True
    )
    odd = dataclasses.replace(table, output_units=('mV/V', 'N') + ('mV/V',) * 6)
    path = write_table(tmp_path / 'odd.csv', odd)
    with pytest.raises(TableError, match=r"load E1 has unit 'mV/V', not a force or moment unit"):
        read_table(path)


def test_a_calibration_of_eight_outputs_is_carried_and_refused_live_in_one_line(tmp_path):
    calibration = eight_output_calibration()
    model = calibration.model()
    save_calibration(tmp_path / 'calibration.yaml', calibration)
    loaded = load_calibration(tmp_path / 'calibration.yaml')
    assert loaded.bridge_outputs == CHANNELS and loaded.model().inputs == CHANNELS
    np.testing.assert_array_equal(loaded.model().coefficients, model.coefficients)
    np.testing.assert_array_equal(loaded.rated_output_mv, np.full(8, 2.5))
    with pytest.raises(ConfigError) as refused:
        activate(loaded, source=str(tmp_path / 'calibration.yaml'))
    message = str(refused.value)
    assert len(message.splitlines()) == 1 and str(tmp_path / 'calibration.yaml') in message
    assert 'bridge outputs E1, E2, E3, E4, E5, E6, E7, E8' in message
    assert '6 components from 8 bridge outputs' in message and 'cannot run live' in message


def test_a_calibration_under_a_tables_own_load_symbols_is_refused_live_in_one_line(tmp_path):
    loads, outputs = ('N', 'RM', 'PM'), ('FZV', 'MXV', 'MYV')
    model = BalanceModel('linear', parse_terms(list(outputs)), np.eye(3), loads, outputs)
    calibration = Calibration(
        'cell', {'linear': model}, 'linear', 'linear', np.ones(3), np.ones(3), loads, outputs
    )
    with pytest.raises(
        ConfigError,
        match=r'^cell: components N, RM, PM: balance_calibrator '
        r'publishes only FX, FY, FZ, MX, MY, MZ, each once',
    ):
        activate(calibration)
