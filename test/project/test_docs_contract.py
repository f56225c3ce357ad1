"""The project carries its own copy of the public contract: docs/ must equal ../shared/docs/.

A clone of this repository alone holds the interfaces it promises (docs/interfaces.md and the table
format it cites, docs/field_data_format.md); beside the steering copy, the two must not drift.
"""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / 'shared' / 'docs'
CONTRACT = ('interfaces.md', 'field_data_format.md')


@pytest.mark.parametrize('name', CONTRACT)
def test_the_project_carries_its_contract(name):
    own = ROOT / 'docs' / name
    assert own.is_file(), f'docs/{name} is missing: the repository must carry its own contract'
    assert 'balance_calib' in own.read_text(encoding='utf-8') or name != 'interfaces.md'


@pytest.mark.parametrize('name', CONTRACT)
def test_the_copy_equals_the_steering_contract(name):
    shared = SHARED / name
    if not shared.is_file():
        pytest.skip(f'no {shared} beside this checkout (a clone on its own)')
    own = ROOT / 'docs' / name
    assert own.read_bytes() == shared.read_bytes(), (
        f'docs/{name} differs from {shared}: copy the shared one (it is the contract)'
    )
