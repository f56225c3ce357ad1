"""The two CSV readers (schedule_file.py, coverage/run_inputs.py) on unreadable files and
non-finite rows: one line naming the file (and the row), each in its reader's own error type.
"""

import re

import pytest

from balance_calib.config import ConfigError
from balance_calib.coverage.run_inputs import read_loads_csv, RunInputError
from balance_calib.schedule_file import read_schedule_csv

SCHEDULE_HEADER = 'point,executed,Ig,FX_kgf,FY_kgf,FZ_kgf,MX_kgfm,MY_kgfm,MZ_kgfm,paren_cols\n'
COMPONENTS = ('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ')


def read_schedule(path):
    return read_schedule_csv(path)


def read_loads(path):
    return read_loads_csv(path, COMPONENTS)


@pytest.mark.parametrize(
    'reader, error, what',
    [(read_schedule, ConfigError, 'schedule'), (read_loads, RunInputError, 'loads')],
)
def test_a_missing_or_undecodable_file_is_named_in_one_line(tmp_path, reader, error, what):
    missing = tmp_path / 'missing.csv'
    with pytest.raises(error, match=re.escape(f'{missing}: cannot read the {what}: ')) as caught:
        reader(missing)
    assert 'No such file' in str(caught.value) and '\n' not in str(caught.value)
    latin = tmp_path / 'latin.csv'
    latin.write_bytes('FX,FY\n1,2 \xb5\n'.encode('latin-1'))  # µ: not UTF-8
    with pytest.raises(error, match=re.escape(f'{latin}: cannot read the {what}: ')):
        reader(latin)


def test_a_non_finite_row_is_named_with_its_number(tmp_path):
    schedule = tmp_path / 's.csv'
    schedule.write_text(SCHEDULE_HEADER + '1,1,2,0,0,0,0,0,0,\n2,1,2,0,inf,0,0,0,0,\n')
    with pytest.raises(ConfigError, match=re.escape(f'{schedule}: row 2: loads must be finite')):
        read_schedule_csv(schedule)
    loads = tmp_path / 'loads.csv'
    loads.write_text('FX,FY,FZ,MX,MY,MZ\n1,2,3,4,5,6\n1,2,3,4,5,6\n1,2,nan,4,5,6\n')
    with pytest.raises(RunInputError, match=re.escape(f'{loads}: row 3: loads must be finite')):
        read_loads_csv(loads, COMPONENTS)


@pytest.mark.parametrize(
    'reader, error, header',
    [
        (read_schedule, ConfigError, SCHEDULE_HEADER),
        (read_loads, RunInputError, 'FX,FY,FZ,MX,MY,MZ\n'),
    ],
)
def test_what_the_csv_module_cannot_parse_is_one_line_naming_the_file(
    tmp_path, reader, error, header
):
    huge = tmp_path / 'huge.csv'  # one quoted field beyond the csv module's 128 KiB limit
    huge.write_text(header + '"' + 'a' * 200_000 + '",1,2,3,4,5\n')
    with pytest.raises(error, match=re.escape(f'{huge}: not readable as CSV: ')) as caught:
        reader(huge)
    assert 'field larger than field limit' in str(caught.value)
