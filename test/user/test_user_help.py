"""The new user's path: every command the README lists explains itself with --help and returns at
once (nothing started: no venv setup, no DDS campaign), and sourcing _env.sh leaves the shell as it
was.
"""

import argparse
import os
from pathlib import Path
import re
import subprocess

import pytest

from balance_calib.cli import build_parser
from balance_calib.nodes import _help
from ros_cli.cli import build_parser as ros_parser

ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = ROOT / 'launchless_scripts'
NODES = [
    'bridge_publisher',
    'balance_calibrator',
    'balance_recorder',
    'thrust_analyzer',
    'aero_coefficients',
    'balance_daq',
]
# scripts whose options another guide documents (diagnosis_rates: docs/results.md)
OPTIONS_DOCUMENTED_ELSEWHERE = {'diagnosis_rates'}


def run(command, **kwargs):
    return subprocess.run(command, capture_output=True, text=True, timeout=60, cwd=ROOT, **kwargs)


def parsers(parser, name):
    yield name, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub_name, sub in action.choices.items():
                yield from parsers(sub, f'{name} {sub_name}')


@pytest.mark.parametrize('top', [build_parser(), ros_parser()], ids=['balance-calib', 'ros'])
def test_every_command_and_option_has_a_complete_help_text(top):
    for name, parser in parsers(top, top.prog):
        description = (parser.description or '').strip()
        assert len(description) > 30 and description[-1] in '.)', (
            f'{name}: description {description!r}'
        )
        for action in parser._actions:
            if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
                continue
            assert action.help and len(action.help) > 8, (
                f'{name} {action.option_strings or action.dest}: no help'
            )


def _options_without_help(text: str) -> list[str]:
    """Option lines of an argparse help with nothing after them, neither beside nor on the next
    line.
    """
    lines = text.splitlines()
    missing = []
    for i, line in enumerate(lines):
        if re.match(r'^  (-\S+|[a-z_]+)( [A-Z_.\[\] ]+)?(, -\S+( [A-Z_]+)?)?$', line):
            following = lines[i + 1] if i + 1 < len(lines) else ''
            if not following.startswith(' ' * 8) or re.match(r'^  \S', following):
                missing.append(line.strip())
    return missing


@pytest.mark.parametrize(
    'script',
    sorted(
        p.name
        for p in SCRIPTS.iterdir()
        if p.is_file() and os.access(p, os.X_OK) and not p.name.startswith('_')
    ),
)
def test_every_launchless_script_explains_itself(script):
    done = run([str(SCRIPTS / script), '--help'])
    assert done.returncode == 0, done.stderr
    text = done.stdout
    assert (
        len(text) > 150 and f'launchless_scripts/{script}' in text or text.startswith('usage:')
    ), text
    if script not in OPTIONS_DOCUMENTED_ELSEWHERE:
        assert _options_without_help(text) == [], text


@pytest.mark.parametrize('node', NODES)
def test_node_help_prints_its_parameters_and_starts_nothing(node):
    done = run([node, '--help'], env=dict(os.environ, ROS_DOMAIN_ID='0'))
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith(f'usage: {node} [--ros-args ...]')
    assert '--ros-args -p NAME:=VALUE' in done.stdout
    assert '[INFO]' not in done.stdout + done.stderr  # no node came up and logged


def test_node_parameters_are_all_described():
    import importlib

    for node in ('bridge_publisher', 'balance_calibrator'):
        module = importlib.import_module(f'balance_calib.nodes.{node}')
        rows = _help.parameter_table(module)
        assert len(rows) > 10
        undocumented = [name for name, _, description in rows if not description]
        assert undocumented == [], (node, undocumented)
    # a --help after --ros-args belongs to ROS, not to us
    assert _help.wants_help(['bridge_publisher', '--help'])
    assert not _help.wants_help(['bridge_publisher', '--ros-args', '-p', 'x:=--help'])


def test_sourcing_env_leaves_the_interactive_shell_options_alone():
    probe = (
        'source launchless_scripts/_env.sh; echo "status=$?"; set -o | grep -E '
        '"^(errexit|nounset|pipefail)"; command -v balance-calib'
    )
    interactive = run(['bash', '--norc', '-i', '-c', probe])
    assert 'status=0' in interactive.stdout, interactive.stderr
    assert re.findall(r'^(errexit|nounset|pipefail)\s+(\w+)', interactive.stdout, re.M) == [
        ('errexit', 'off'),
        ('nounset', 'off'),
        ('pipefail', 'off'),
    ]
    assert interactive.stdout.strip().endswith('balance-calib')
    # inside a script (non-interactive) the same file turns fail-fast on
    script = run(['bash', '-c', 'source launchless_scripts/_env.sh; false; echo "not reached"'])
    assert script.returncode == 1 and 'not reached' not in script.stdout


def test_every_command_the_readme_lists_exists_and_explains_itself():
    readme = (ROOT / 'README.md').read_text()
    subcommands = sorted(set(re.findall(r'`balance-calib ([a-z][a-z-]+)', readme)))
    scripts = sorted(set(re.findall(r'launchless_scripts/([a-z_]+)', readme)) - {'_env'})
    assert {'refit', 'simulate'} <= set(subcommands) and {'demo', 'test'} <= set(scripts)
    for name in subcommands:
        done = run(['balance-calib', name, '--help'])
        assert done.returncode == 0 and done.stdout.startswith(f'usage: balance-calib {name}'), (
            name,
            done.stderr,
        )
    for name in scripts:
        assert (SCRIPTS / name).is_file(), (
            f'README lists launchless_scripts/{name}, which does not exist'
        )
        done = run([str(SCRIPTS / name), '--help'])
        assert done.returncode == 0 and len(done.stdout) > 100, (name, done.stderr)
