"""Fuzz of the refit: a few hundred deterministic damaged or mislabelled campaigns (generated here
by balance_calib.benchmarks.refit_reliability) give zero tracebacks, zero hangs and zero wrong
calibrations accepted; a refit killed with SIGKILL leaves nothing half-written.
"""

import os
import signal
import subprocess
import sys

import pytest

from balance_calib.benchmarks.refit_reliability import (
    campaign_events,
    Clean,
    judge_cli,
    mutants,
    run_mutants,
    small_campaign,
    write_mcap,
)

KINDS = {
    'clean',
    'truncate',
    'flip_crc',
    'flip_nocrc',
    'drop_raw',
    'drop_marker',
    'drop_gravity',
    'swap_marker_stamps',
    'reorder_raw',
    'duplicate',
    'kgf',
    'lbf',
    'volts',
    'clip',
    'wrong_weight',
    'wrong_balance',
    'negative_body',
    'reversed_gravity',
    'time_jump',
    'split_pause',
    'tiny',
    'flip_summary',
    'raw_clock_jump',
    'lz4_flip_nocrc',
    'clock_back',
    'zero_stamps',
}


@pytest.mark.slow  # ~45 s on 2 cores: a refit of each of 240 mutant bags
def test_hundreds_of_mutants_give_no_traceback_and_no_wrong_calibration(tmp_path):
    summary = run_mutants(240, 0, tmp_path, seeds=(0, 1, 2))
    counts = summary['counts']
    assert summary['failures'] == [], summary['failures'][:5]
    assert counts['tried'] == 240 and counts['traceback'] == 0 and counts['silent_wrong'] == 0
    assert counts['unnamed'] == 0  # every refusal names the file
    assert set(summary['by_kind']) == KINDS
    # what must be refused was (unit errors, wrong balance, bad body, unreadable files) and what is
    # only inconvenient (pauses, jumps, reordering, duplicates) was accepted, correct
    for kind in (
        'truncate',
        'tiny',
        'kgf',
        'lbf',
        'volts',
        'wrong_balance',
        'negative_body',
        'reversed_gravity',
        'clip',
        'swap_marker_stamps',
        'drop_gravity',
        'clock_back',
    ):
        assert set(summary['by_kind'][kind]) == {'refused'}, (kind, summary['by_kind'][kind])
    for kind in ('clean', 'split_pause', 'time_jump', 'reorder_raw', 'duplicate', 'drop_raw'):
        assert set(summary['by_kind'][kind]) == {'accepted'}, (kind, summary['by_kind'][kind])


@pytest.fixture(scope='module')
def cli_mutants(tmp_path_factory):
    workdir = tmp_path_factory.mktemp('cli')
    campaign = small_campaign('b660h', 7)
    clean = Clean('b660h', campaign, tuple(campaign_events(campaign)))
    return {m.kind: m for m in mutants(clean, workdir, 7, 24)}, workdir


@pytest.mark.parametrize(
    'kind, verdict',
    [
        ('clean', 'accepted'),
        ('tiny', 'refused'),
        ('truncate', 'refused'),
        ('flip_nocrc', 'refused'),
        ('kgf', 'refused'),
        ('split_pause', 'accepted'),
    ],
)
def test_mutants_through_the_command_line(cli_mutants, kind, verdict):
    by_kind, workdir = cli_mutants
    got, detail = judge_cli(by_kind[kind], workdir / f'out-{kind}', timeout_s=300)
    assert (got, kind) == (verdict, kind), detail


def _start_refit(bag, out, *extra):
    return subprocess.Popen(
        [
            sys.executable,
            '-m',
            'balance_calib.cli',
            'refit',
            str(bag),
            '--balance',
            'lmc6522',
            '--out',
            str(out),
            '--progress',
            *extra,
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )


@pytest.mark.parametrize('kill_at', ['zero points and tare', 'writing calibration.yaml'])
def test_a_refit_killed_with_sigkill_leaves_nothing_half_written(tmp_path, kill_at):
    bag = write_mcap(campaign_events(small_campaign('lmc6522', 5)), tmp_path / 'campaign.mcap')
    out = tmp_path / 'calibration'
    process = _start_refit(bag, out)
    seen = []
    for line in process.stderr:  # bounded: the refit ends, and with it stderr
        seen.append(line)
        if kill_at in line:
            os.kill(process.pid, signal.SIGKILL)
            break
    process.wait(timeout=120)
    assert process.returncode == -signal.SIGKILL, ''.join(seen)[-500:]
    # nothing half-written: DIR appears whole with one rename, or not at all
    if out.exists():
        assert {p.name for p in out.iterdir()} >= {'calibration.yaml', 'report.json', 'report.md'}
    # a second refit removes the killed one's staging directory and writes everything (over the
    # first one's calibration record, if the kill came after its rename: --overwrite)
    again = _start_refit(bag, out, '--no-diagnosis', '--overwrite')
    _, stderr = again.communicate(timeout=300)
    assert again.returncode == 0, stderr
    assert {'calibration.yaml', 'report.json', 'report.md'} <= {p.name for p in out.iterdir()}
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith('.refit-staging-')] == []
