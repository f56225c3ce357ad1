"""--out of refit, fit and export-table (interfaces.md, "Command line"): a DIR holding a
calibration record is refused unless --overwrite, and then nothing of the earlier run stays;
never a file that is not the tool's own, never beside the shipped balance configs; files 0644.
"""

import shutil
import stat

import pytest

from balance_calib.benchmarks.refit_reliability import campaign_events, small_campaign, write_mcap
from balance_calib.cli import main
from balance_calib.config import CONFIG_DIR

RECORD = {'calibration.yaml', 'report.json', 'report.md'}


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    return write_mcap(
        campaign_events(small_campaign('lmc6522', seed=11)),
        tmp_path_factory.mktemp('bag') / 'campaign.mcap',
    )


def _refit(bag, out, *extra):
    return main(
        ['refit', str(bag), '--balance', 'lmc6522', '--out', str(out), '--no-diagnosis', *extra]
    )


def _snapshot(directory):
    return {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in directory.iterdir()}


def _names(directory):
    return {p.name for p in directory.iterdir()}


def _refused(capsys, status, *expected):
    error = capsys.readouterr().err.strip()
    assert status == 2 and '\n' not in error, error
    for text in expected:
        assert text in error, error
    return error


def _mode(path):
    return stat.S_IMODE(path.stat().st_mode)


def test_refit_refuses_an_earlier_record_and_replaces_it_whole(bag, tmp_path, capsys):
    out = tmp_path / 'out'
    assert _refit(bag, out) == 0
    capsys.readouterr()
    assert RECORD <= _names(out)
    # an earlier run's plots this run does not draw (with the diagnosis on, or another model)
    for stale in ('effect_temperature.png', 'residuals_adopted.png'):
        (out / stale).write_bytes(b'\x89PNG stale')
    before = _snapshot(out)
    _refused(capsys, _refit(bag, out), str(out), 'calibration record', '--overwrite')
    assert _snapshot(out) == before  # nothing touched
    # a file that is not ours: --overwrite refuses rather than delete it
    (out / 'notes.txt').write_text("the crew's notes")
    with_notes = _snapshot(out)
    _refused(capsys, _refit(bag, out, '--overwrite'), 'notes.txt', 'move them away')
    assert _snapshot(out) == with_notes
    (out / 'notes.txt').unlink()
    # mark the earlier calibration: two refits within one second have the same fitted_at
    earlier = out / 'calibration.yaml'
    earlier.write_bytes(earlier.read_bytes() + b'# the earlier run\n')
    assert _refit(bag, out, '--overwrite') == 0
    written = _names(out)
    assert 'effect_temperature.png' not in written and 'residuals_adopted.png' not in written
    assert RECORD <= written
    # the new calibration, not the old one left in place
    assert b'# the earlier run' not in (out / 'calibration.yaml').read_bytes()
    modes = {p.name: oct(_mode(p)) for p in out.iterdir()}
    assert set(modes.values()) == {'0o644'}, modes
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith('.')] == []  # no staging


def test_refit_into_a_directory_without_a_record_keeps_other_files(bag, tmp_path, capsys):
    out = tmp_path / 'shared'
    out.mkdir()
    (out / 'notes.txt').write_text('kept')
    (out / 'photo.png').write_bytes(b"\x89PNG the crew's")  # a name like a plot's, not ours
    assert _refit(bag, out, '--overwrite') == 0
    assert (out / 'notes.txt').read_text() == 'kept' and (out / 'calibration.yaml').exists()
    assert (out / 'photo.png').read_bytes() == b"\x89PNG the crew's"


def test_nothing_is_written_beside_the_balance_configs(bag, tmp_path, capsys):
    for out in (CONFIG_DIR, CONFIG_DIR / 'fits'):
        _refused(capsys, _refit(bag, out, '--overwrite'), 'balance configs')
    assert not (CONFIG_DIR / 'calibration.yaml').exists() and not (CONFIG_DIR / 'fits').exists()
    # a copy of the configs elsewhere (an installed share/balance_calib/config) is recognised too
    copy = tmp_path / 'config'
    copy.mkdir()
    shutil.copy(CONFIG_DIR / 'lmc6522.yaml', copy / 'lmc6522.yaml')
    _refused(capsys, _refit(bag, copy), 'lmc6522.yaml')
    export = [
        'export-table',
        str(bag),
        '--balance',
        'lmc6522',
        '--out',
        str(copy / 'lmc6522.yaml'),
    ]
    _refused(capsys, main(export + ['--overwrite']), 'balance configs')
    assert _names(copy) == {'lmc6522.yaml'}


def test_export_table_and_fit_follow_the_same_rule(bag, tmp_path, capsys):
    table = tmp_path / 'campaign.csv'
    export = ['export-table', str(bag), '--balance', 'lmc6522', '--out', str(table)]
    assert main(export) == 0
    assert _mode(table) == 0o644
    first = table.read_bytes()
    capsys.readouterr()
    table.write_text('edited by hand\n')
    _refused(capsys, main(export), str(table), '--overwrite')
    assert table.read_text() == 'edited by hand\n'
    assert main(export + ['--overwrite']) == 0 and table.read_bytes() == first
    _refused(capsys, main(export[:-1] + [str(tmp_path)]), 'is a directory')

    out = tmp_path / 'fit'
    fit = [
        'fit',
        str(table),
        '--out',
        str(out),
        '--method',
        'direct',
        '--terms',
        'tm663-cubic',
        '--no-plots',
    ]
    assert main(fit) == 0
    capsys.readouterr()
    # fit wrote calibration.yaml 0600 before: the same 0644 as refit now
    files = RECORD | {'point_uncertainty.csv'}
    assert {p.name: _mode(p) for p in out.iterdir()} == dict.fromkeys(files, 420)
    (out / 'residuals_iterative.png').write_bytes(b'stale')
    before = _snapshot(out)
    _refused(capsys, main(fit), str(out), 'calibration record')
    assert _snapshot(out) == before
    assert main(fit + ['--overwrite']) == 0
    assert _names(out) == files


def test_staged_inside_out_stale_files_go_and_calibration_yaml_comes_last(tmp_path, monkeypatch):
    # the path taken when only DIR (not its parent) is writable: staging inside DIR, file by file
    from balance_calib import output_dir

    out = tmp_path / 'out'
    out.mkdir()
    for name in RECORD | {'effect_creep.png', 'unexplained_MZ.png'}:
        (out / name).write_text('old')
    staging = output_dir.make_staging(out, out, 'refit')
    for name in RECORD | {'residuals_cubic.png'}:
        (staging / name).write_text('new')
    moved = []
    replace = type(staging).replace

    def recording_replace(self, target):
        moved.append(self.name)
        return replace(self, target)

    monkeypatch.setattr(type(staging), 'replace', recording_replace)
    output_dir.install_outputs(staging, out, overwrite=True)
    assert _names(out) == RECORD | {'residuals_cubic.png'}
    assert all(p.read_text() == 'new' and _mode(p) == 0o644 for p in out.iterdir())
    assert moved[-1] == 'calibration.yaml'
