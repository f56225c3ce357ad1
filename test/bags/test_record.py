"""The record a laboratory signs (interfaces.md, "A record a laboratory signs"): report.json
`record` of refit and fit, report.md's identification block and signature lines, the serial from
the balance config or --serial, inputs by SHA-256, the git commit (null outside a checkout), and
coefficients whose standard error exceeds their size marked in the coefficient tables.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import json
from pathlib import Path
import subprocess

import numpy as np
import pytest
import table_cases as tc

from balance_calib import __version__, record
from balance_calib.accuracy.tables import format_coefficient_tables, WEAK_MARK, WEAK_NOTE
from balance_calib.cli import main
from balance_calib.config import load_balance_config, resolve_config_path
from balance_calib.model.balance_model import BalanceModel
from balance_calib.model.tm663 import tm663_terms
from balance_calib.tables.balfit_writer import write_table

RECORD_KEYS = {
    'balance',
    'serial',
    'date',
    'operator',
    'software',
    'inputs',
    'expanded_uncertainty_pct_fs',
}


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _expected_commit() -> str | None:
    """HEAD of the checkout the imported package lives in, None when it is not one's."""
    package = Path(record.__file__).resolve().parent
    done = subprocess.run(
        ['git', '-C', str(package), 'rev-parse', '--show-toplevel', 'HEAD'],
        capture_output=True,
        text=True,
    )
    if done.returncode != 0:
        return None
    top, head = done.stdout.split()
    return (
        head
        if (Path(top) / 'balance_calib' / 'record.py').resolve() == package / 'record.py'
        else None
    )


def _check_record(entry, balance, serial, operator, inputs):
    assert RECORD_KEYS <= set(entry)
    assert (entry['balance'], entry['serial'], entry['operator']) == (balance, serial, operator)
    date = dt.datetime.fromisoformat(entry['date'])
    assert date.tzinfo is not None
    assert abs((dt.datetime.now(dt.timezone.utc) - date).total_seconds()) < 600
    assert entry['software'] == {
        'name': 'balance_calib',
        'version': __version__,
        'commit': _expected_commit(),
    }
    assert entry['inputs'] == [{'file': str(p), 'sha256': _sha256(p)} for p in inputs]


def _signed_markdown(text: str, title: str):
    lines = text.rstrip().splitlines()
    assert lines[0].startswith(title)
    # the identification block right under the title
    assert lines[2:5] == ['| | |', '|---|---|', lines[4]] and lines[4].startswith('| balance |')
    assert any(line.startswith('Performed by:') for line in lines[-4:])
    assert lines[-1].startswith('Approved by:')


def test_refit_record_serial_operator_inputs_and_signature_lines(campaigns, tmp_path):
    bag = campaigns.bag(recipe='bag')
    out = tmp_path / 'refit'
    code = main(
        [
            'refit',
            str(bag),
            '--balance',
            'lmc6522',
            '--out',
            str(out),
            '--no-diagnosis',
            '--serial',
            'S-42',
            '--operator',
            'A. Lab',
        ]
    )
    assert code == 0
    report = json.loads((out / 'report.json').read_text())
    entry = report['record']
    files = sorted(p for p in Path(bag).rglob('*') if p.is_file())
    _check_record(entry, 'LMC6522', 'S-42', 'A. Lab', files)
    # U = 2u at the rated load, u = σ √(1 + leverage) >= σ: between 2σ and 2σ √(1 + 1.25)
    calibration = (out / 'calibration.yaml').read_text()
    assert 'serial: S-42' in calibration
    from balance_calib.calibration_file import load_calibration

    loaded = load_calibration(out / 'calibration.yaml')
    sigma = np.asarray(loaded.model().metadata['uncertainty']['residual_sigma'])
    sigma_pct = sigma / loaded.capacity * 100.0
    expanded = entry['expanded_uncertainty_pct_fs']
    assert expanded['k'] == 2
    for c, s in zip(loaded.components, sigma_pct):
        assert 2 * s <= expanded[c] <= 2 * s * 1.5
    text = (out / 'report.md').read_text()
    _signed_markdown(text, '# Calibration report: LMC6522')
    assert '| serial number | S-42 |' in text and '| operator | A. Lab |' in text
    # cubic coefficients the campaign does not determine are marked
    assert WEAK_NOTE in text
    cubic = text.split('### cubic\n', 1)[1].split('```', 2)[1]
    assert WEAK_MARK in cubic


def test_the_serial_comes_from_the_balance_config(campaigns, tmp_path):
    from balance_calib.calibrate.from_bags import RefitSettings, run_refit

    assert load_balance_config('lmc6522').serial is None
    config = tmp_path / 'lmc6522_s.yaml'
    config.write_text(resolve_config_path('lmc6522').read_text() + '\nserial: LMC-0042\n')
    assert load_balance_config(config).serial == 'LMC-0042'
    result = run_refit(
        [campaigns.bag(recipe='bag')],
        config,
        tmp_path / 'out',
        RefitSettings(diagnose=False, plots=False),
    )
    assert result.report['record']['serial'] == 'LMC-0042'
    assert result.report['record']['operator'] is None


def test_fit_record_and_weak_coefficients_marked(tmp_path):
    table, _ = tc.six_component_balance(np.random.default_rng(5))
    path = write_table(tmp_path / 'b6.csv', table)
    out = tmp_path / 'out'
    assert main(['fit', str(path), '--out', str(out), '--no-plots', '--operator', 'B. Lab']) == 0
    report = json.loads((out / 'report.json').read_text())
    _check_record(report['record'], 'balance6', None, 'B. Lab', [path])
    assert set(report['record']['expanded_uncertainty_pct_fs']) == {'k', *table.load_symbols}
    text = (out / 'report.md').read_text()
    _signed_markdown(text, '# Calibration from tables: balance6')
    coefficients = report['coefficients']
    targets = coefficients['targets']
    rows = {
        line.split('|')[1].strip(): [cell.strip() for cell in line.split('|')[2:-1]]
        for line in text.splitlines()
        if line.startswith('| ') and ' ± ' in line
    }
    marked = 0
    for j, term in enumerate(coefficients['terms']):
        for cell, target in zip(rows[term], targets):
            weak = abs(coefficients['standard_errors'][target][j]) > abs(
                coefficients['values'][target][j]
            )
            assert cell.endswith(WEAK_MARK) == weak, (term, target, cell)
            marked += weak
    assert marked > 0  # the knee and square the generator adds leave some terms undetermined


def test_weak_mark_in_the_memo_layout():
    terms = tm663_terms('linear')
    coefficients = np.zeros((6, len(terms)))
    coefficients[:, 1:] = np.eye(6) * 100.0
    coefficients[0, 2] = 0.5  # FX on FYV
    errors = np.full_like(coefficients, 0.1)
    errors[:, 0] = 0.0  # the constants: 0 ± 0, not marked
    errors[0, 2] = 0.6  # larger than its coefficient: marked
    model = BalanceModel('linear', terms, coefficients)
    lines = format_coefficient_tables(model, errors).splitlines()
    # FX on FYV 0.5 ± 0.6 is marked, and so is every zero interaction (0 ± 0.1); neither the
    # constants (0 ± 0) nor the diagonal (100 ± 0.1)
    assert lines[1].split()[3] == f'0.5000{WEAK_MARK}'
    for k, line in enumerate(lines[1:]):
        cells = line.split()[1:]
        assert [c.endswith(WEAK_MARK) for c in cells] == [False] + [j != k for j in range(6)]
    assert format_coefficient_tables(model) == format_coefficient_tables(model, None)
    assert WEAK_MARK not in format_coefficient_tables(model)


def test_no_commit_outside_a_checkout_and_never_an_error(monkeypatch):
    def no_git(*args, **kwargs):
        raise FileNotFoundError('git')

    monkeypatch.setattr(record.subprocess, 'run', no_git)
    assert record.software()['commit'] is None
    monkeypatch.setattr(record, '_git', lambda directory, *arguments: '/somewhere/else')
    assert record.software()['commit'] is None


@pytest.mark.parametrize('bad', [['a', 'b'], {'x': 1}])
def test_a_serial_that_is_no_text_is_refused(tmp_path, bad):
    import yaml

    from balance_calib.errors import ConfigError

    data = yaml.safe_load(resolve_config_path('lmc6522').read_text())
    data['serial'] = bad
    path = tmp_path / 'bad.yaml'
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match='serial'):
        load_balance_config(path)
