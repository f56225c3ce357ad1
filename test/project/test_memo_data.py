"""The memo's table extracts travel with the repository, and the shipped configs are theirs.

data/tm663 is a copy of the steering ../shared/data; tools/make_balance_configs.py turns it into
config/lmc6522.yaml and config/b660h.yaml. A clone on its own must regenerate the configs byte for
byte, so that the configs' provenance is in the repository, not beside it.
"""

from pathlib import Path
import subprocess
import sys

import pytest

ROOT = Path(__file__).resolve().parents[2]
OWN = ROOT / 'data' / 'tm663'
SHARED = ROOT.parent / 'shared' / 'data'
NAMES = ('README.md', 'b660h_schedule.csv', 'lmc6522_schedule.csv', 'seed_matrices.json')


@pytest.mark.parametrize('name', NAMES)
def test_the_copy_equals_the_steering_data(name):
    own = OWN / name
    assert own.is_file(), f'data/tm663/{name} is missing'
    shared = SHARED / name
    if not shared.is_file():
        pytest.skip(f'no {shared} beside this checkout (a clone on its own)')
    assert own.read_bytes() == shared.read_bytes(), f'data/tm663/{name} differs from {shared}'


def test_the_shipped_configs_regenerate_from_the_repository_alone(tmp_path):
    done = subprocess.run(
        [
            sys.executable,
            str(ROOT / 'tools' / 'make_balance_configs.py'),
            '--data',
            str(OWN),
            '--out-dir',
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    for name in ('lmc6522.yaml', 'b660h.yaml'):
        assert (tmp_path / name).read_bytes() == (ROOT / 'config' / name).read_bytes(), (
            f'config/{name} is not what tools/make_balance_configs.py makes of data/tm663'
        )
