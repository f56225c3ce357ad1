"""`balance-calib simulate` as a user runs it: bad options refused with one line before any
work, and --bag (the campaign also written as a calibration bag) leaves the fitted numbers as
they are.
"""

import pytest

from balance_calib.cli import main


@pytest.mark.parametrize(
    'option, problem',
    [
        (['--seed', '-1'], '--seed -1'),
        (['--samples-per-point', '-3'], '--samples-per-point -3'),
        (['--samples-per-point', '0'], '--samples-per-point 0'),
    ],
)
def test_bad_options_are_one_line_and_status_2(option, problem, capsys):
    assert main(['simulate', '--balance', 'lmc6522', '--no-diagnosis'] + option) == 2
    captured = capsys.readouterr()
    assert captured.out == '' and captured.err.count('\n') == 1, captured.err
    assert problem in captured.err


def test_a_bag_that_exists_is_refused_before_the_campaign_is_simulated(tmp_path, capsys):
    existing = tmp_path / 'campaign'
    existing.mkdir()
    (existing / 'metadata.yaml').write_text('kept')
    assert (
        main(['simulate', '--balance', 'lmc6522', '--no-diagnosis', '--bag', str(existing)]) == 2
    )
    captured = capsys.readouterr()
    assert captured.out == ''  # no results printed, then a traceback
    assert captured.err.count('\n') == 1 and f'--bag {existing}: exists already' in captured.err
    assert (existing / 'metadata.yaml').read_text() == 'kept'
    # with two balances, one bag each inside --bag: the second's existing is found before the
    # first is made
    (tmp_path / 'both' / 'b660h').mkdir(parents=True)
    assert main(['simulate', '--no-diagnosis', '--bag', str(tmp_path / 'both')]) == 2
    assert 'b660h: exists already' in capsys.readouterr().err
    assert not (tmp_path / 'both' / 'lmc6522').exists()


def test_writing_the_bag_does_not_change_the_fitted_numbers(tmp_path, capsys):
    args = [
        'simulate',
        '--balance',
        'lmc6522',
        '--no-diagnosis',
        '--seed',
        '7',
        '--samples-per-point',
        '3',
    ]
    assert main(args) == 0
    without = capsys.readouterr().out
    assert main(args + ['--bag', str(tmp_path / 'campaign')]) == 0
    captured = capsys.readouterr()
    assert captured.out == without and 'balance_calib    cubic' in without
    assert (tmp_path / 'campaign' / 'metadata.yaml').exists()
    # the seed matters (the comparison above is not of two constant outputs)
    assert main(args[:-4] + ['--seed', '8', '--samples-per-point', '3']) == 0
    assert capsys.readouterr().out != without
