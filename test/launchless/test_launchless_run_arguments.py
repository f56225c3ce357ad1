"""The stories (windon, campaign, aero_story) and balance-calib's commands share their option
groups (commands/run_arguments.py): an option is parsed the same everywhere it appears, and a
story's command line becomes one run description whose node parameters are the ones it names.
"""

from pathlib import Path

import pytest

from balance_calib.cli import build_parser as balance_calib_parser
from balance_calib.commands.run_arguments import SimulatedBalance, WindOnConditions
from balance_calib.launchless import aero_story, campaign, windon


def sub_parser(name):
    parser = balance_calib_parser()
    return next(
        action.choices[name]
        for action in parser._actions
        if hasattr(action, 'choices') and action.choices and name in action.choices
    )


def test_the_simulated_balance_options_parse_alike_in_simulate_campaign_and_windon():
    options = [
        '--balance',
        'b660h',
        '--seed',
        '4',
        '--effects',
        'temperature:sensitivity_per_k=1e-4',
    ]
    simulate = sub_parser('simulate').parse_args(options)
    story = campaign.build_parser().parse_args(options)
    run = windon.build_parser().parse_args(['out', *options])
    assert simulate.balance == ['b660h']  # repeatable in simulate: one balance each time
    for args in (story, run):
        assert (args.balance, args.seed, args.effects) == (
            'b660h',
            4,
            'temperature:sensitivity_per_k=1e-4',
        )
    # the defaults each keeps: simulate both balances and seed 1, campaign seed 1, windon seed 0
    assert sub_parser('simulate').parse_args([]).balance is None
    assert sub_parser('simulate').parse_args([]).seed == 1
    assert campaign.build_parser().parse_args([]).seed == 1
    assert windon.build_parser().parse_args(['out']).seed == 0


def test_model_and_installation_parse_alike_in_reduce_windon_and_aero_story():
    reduce = sub_parser('reduce')
    args = reduce.parse_args(
        ['bag', '--calibration', 'c', '--out', 'o', '--model', 'm', '--installation', 'inverted']
    )
    assert (args.model, args.installation) == ('m', 'inverted')
    with pytest.raises(SystemExit):  # reduce needs its model; windon has a default
        reduce.parse_args(['bag', '--calibration', 'c', '--out', 'o'])
    run = windon.build_parser().parse_args(['out', '--installation', 'inverted'])
    assert (run.model, run.installation) == ('euler_replica_lmc6522', 'inverted')
    aero = aero_story.build_parser().parse_args(['--installation', 'inverted', '--q-pa', '2e4'])
    assert not hasattr(aero, 'model') and (aero.installation, aero.q_pa) == ('inverted', 20000.0)
    assert aero.noise_pct_fs == 0.005 and run.noise_pct_fs == -1.0


@pytest.mark.parametrize('parser', [windon.build_parser, aero_story.build_parser])
@pytest.mark.parametrize('q', ['0', '-5', 'nan', 'inf', 'fast'])
def test_a_dynamic_pressure_that_is_not_positive_is_refused(parser, q, capsys):
    with pytest.raises(SystemExit) as caught:
        parser().parse_args(['out', '--q-pa', q])
    assert caught.value.code == 2 and 'is not a positive number' in capsys.readouterr().err


def test_a_windon_command_line_becomes_one_description_and_its_node_parameters():
    args = windon.build_parser().parse_args(
        [
            'runs/a',
            '--model',
            'm.yaml',
            '--balance',
            'b660h',
            '--seed',
            '7',
            '--effects',
            'E',
            '--q-pa',
            '1500',
            '--installation',
            'inverted',
            '--noise-pct-fs',
            '0.01',
            '--alpha-deg=-4,20,4',
            '--hold-s',
            '0.25',
            '--wind-off-hold-s',
            '0.125',
            '--rate-hz',
            '400',
            '--subscriber-timeout-s',
            '12',
        ]
    )
    run = windon.run_description(args)
    assert run == windon.RunDescription(
        SimulatedBalance('b660h', 'E', 7),
        WindOnConditions('m.yaml', 'inverted', 1500.0, 0.01),
        (-4.0, 20.0, 4.0),
        0.25,
        0.125,
        400.0,
        12.0,
    )
    assert windon.publisher_parameters(run) == {
        'mode': 'wind_on',
        'aero_model': 'm.yaml',
        'balance': 'b660h',
        'effects': 'E',
        'dynamic_pressure_pa': 1500.0,
        'installation': 'inverted',
        'alpha_start_deg': -4.0,
        'alpha_end_deg': 20.0,
        'alpha_step_deg': 4.0,
        'hold_s': 0.25,
        'wind_off_hold_s': 0.125,
        'rate_hz': 400.0,
        'seed': 7,
        'noise_sigma_pct_fs': 0.01,
        'exit_when_done': True,
        'wait_for_subscribers': 1,
        'wait_for_subscribers_timeout_s': 12.0,
    }
    calibrator = windon.calibrator_parameters(run, Path('/tmp/z.yaml'))
    assert calibrator == {
        'calibration_file': 'b660h',
        'installation': 'inverted',
        'tare_samples': windon.ZERO_SAMPLES,
        'tare_timeout_s': 12.0,
        'tare_file': '/tmp/z.yaml',
    }
    empty = windon.empty_balance_parameters(run, Path('/tmp/e.csv'))
    assert (empty['balance'], empty['seed'], empty['effects'], empty['profile_csv']) == (
        'b660h',
        7,
        'E',
        '/tmp/e.csv',
    )
    assert windon.reduce_command(Path('/r/a'), run) == [
        'balance-calib',
        'reduce',
        '/r/a',
        '--calibration',
        'b660h',
        '--model',
        'm.yaml',
        '--installation',
        'inverted',
        '--out',
        '/r/a_reduce',
    ]


def test_the_defaults_of_a_windon_run_are_those_it_had(tmp_path):
    run = windon.run_description(windon.build_parser().parse_args([str(tmp_path / 'x')]))
    assert run == windon.RunDescription()
    parameters = windon.publisher_parameters(run)
    assert parameters['aero_model'] == 'euler_replica_lmc6522' and parameters['seed'] == 0
    assert (parameters['dynamic_pressure_pa'], parameters['noise_sigma_pct_fs']) == (50000.0, -1.0)
    assert (parameters['alpha_start_deg'], parameters['alpha_end_deg']) == (-2.0, 22.0)
    assert (parameters['hold_s'], parameters['wind_off_hold_s'], parameters['rate_hz']) == (
        0.5,
        0.3,
        200.0,
    )
    assert run.run_timeout_s == 600.0 and parameters['effects'] == ''


@pytest.mark.parametrize('story', [windon, campaign])
def test_a_negative_seed_is_one_line_and_status_2_before_anything_starts(story, tmp_path, capsys):
    argv = ([str(tmp_path / 'out')] if story is windon else [str(tmp_path)]) + ['--seed', '-1']
    assert story.main(argv) == 2
    captured = capsys.readouterr()
    assert captured.err.count('\n') == 1 and '--seed -1: a seed is not negative' in captured.err
    assert list(tmp_path.iterdir()) == []


def test_a_campaign_command_line_becomes_its_story():
    args = campaign.build_parser().parse_args(
        ['o', '--effects', 'E', '--seed', '5', '--installations', 'inverted,', '--rate', '100']
    )
    assert campaign.campaign_story(args) == campaign.CampaignStory(
        SimulatedBalance('lmc6522', 'E', 5),
        ('inverted',),
        rate_hz=100.0,
        point_duration_s=0.1,
        transition_s=0.03,
        wind_on_temperature_c=20.0,
        compare_base=True,  # effects given: the base model is flown too
    )
    plain = campaign.campaign_story(campaign.build_parser().parse_args([]))
    assert plain == campaign.CampaignStory() and plain.balance == SimulatedBalance(
        'lmc6522', '', 1
    )
    assert plain.installations == ('upright', 'inverted') and plain.compare_base is False


def test_every_parameter_windon_gives_a_node_is_one_the_node_declares():
    from balance_calib.live.parameters import PARAMETERS as CALIBRATOR
    from balance_calib.simulation.publisher_parameters import PARAMETERS as PUBLISHER

    run = windon.RunDescription(SimulatedBalance('lmc6522', 'temperature:sensitivity_per_k=1e-4'))
    for parameters in (
        windon.publisher_parameters(run),
        windon.empty_balance_parameters(run, Path('e.csv')),
    ):
        assert set(parameters) <= set(PUBLISHER), sorted(set(parameters) - set(PUBLISHER))
    calibrator = windon.calibrator_parameters(run, Path('z.yaml'))
    assert set(calibrator) <= set(CALIBRATOR), sorted(set(calibrator) - set(CALIBRATOR))
