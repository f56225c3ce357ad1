"""calibrate/write_record.py: one writer for the record of every calibration. It writes
calibration.yaml, report.json, report.md and the figures the same way for a bag calibration and a
table calibration, and a write that fails leaves the previous record as it was.
"""

from dataclasses import replace
import json
import math

import numpy as np
import pytest

from balance_calib.calibrate.path import calibrate
from balance_calib.calibrate.records import bag_record, table_record
from balance_calib.calibrate.write_record import write_record
from balance_calib.calibration_file import save_calibration
from balance_calib.calibration_settings import CalibrationSettings, RecordOptions
from balance_calib.refit.pipeline import calibrate_points
from balance_calib.tables import synthetic as sy
from balance_calib.tables.table_points import table_calibration_points

RECORD = ('calibration.yaml', 'report.json', 'report.md')


def _table():
    rng = np.random.default_rng(3)
    truth = sy.direct_truth(np.random.default_rng(1))
    schedule = sy.support_schedule(rng, 15, 25)
    tares = sy.tares_for(np.random.default_rng(2), range(1, 100))
    applied, outputs = sy.direct_campaign(rng, truth, schedule, tares, 0.0002 * sy.capacity_si())
    return sy.make_table(applied, outputs, schedule.series)


def _check_record(out, result):
    report = json.loads((out / 'report.json').read_text())
    assert report == json.loads(json.dumps(result.report))
    assert report['plots'] and all(name.startswith('residuals_') for name in report['plots'])
    for name in RECORD + tuple(report['plots']):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
        assert (out / name).stat().st_mode & 0o777 == 0o644
    markdown = (out / 'report.md').read_text()
    assert all(f'![{name}]({name})' in markdown for name in report['plots'])
    save_calibration(out.parent / 'expected.yaml', result.calibration)
    assert (out / 'calibration.yaml').read_bytes() == (out.parent / 'expected.yaml').read_bytes()
    assert not [p for p in out.iterdir() if p.name.startswith('.')]  # no staging left


def test_one_writer_for_a_bag_and_a_table_calibration(tmp_path, campaigns, lmc6522):
    told = []
    bag = calibrate_points(
        campaigns.points(seed=5), lmc6522, settings=CalibrationSettings(diagnose=False)
    )
    out = write_record(
        bag_record(bag),
        RecordOptions(tmp_path / 'bag', written=lambda result, out: told.append((result, out))),
    )
    assert len(told) == 1 and told[0][0] is bag and told[0][1] == out
    _check_record(out, bag)

    settings = CalibrationSettings(out=RecordOptions(tmp_path / 'table'))
    table = calibrate(table_calibration_points(_table()), settings)
    _check_record(tmp_path / 'table', table)
    assert (tmp_path / 'table' / 'point_uncertainty.csv').is_file()
    # the same record once more through the writer itself: the same bytes
    write_record(table_record(table), RecordOptions(tmp_path / 'again'))
    for name in ('report.json', 'report.md', 'point_uncertainty.csv'):
        assert (tmp_path / 'again' / name).read_bytes() == (tmp_path / 'table' / name).read_bytes()


def test_a_failed_write_leaves_the_previous_calibration(tmp_path, campaigns, lmc6522):
    result = calibrate_points(
        campaigns.points(seed=5), lmc6522, settings=CalibrationSettings(diagnose=False)
    )
    out = tmp_path / 'out'
    write_record(bag_record(result), RecordOptions(out, plots=False))
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    # a report that cannot be written (NaN is no JSON) fails after calibration.yaml is staged
    broken = replace(bag_record(result), report={**result.report, 'broken': math.nan})
    with pytest.raises(ValueError):
        write_record(broken, RecordOptions(out, plots=False))
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before

    def fails(report):
        raise OSError('disk full')

    with pytest.raises(OSError, match='disk full'):
        write_record(replace(bag_record(result), markdown=fails), RecordOptions(out))
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
