"""The task guides of docs/guide/ name only what exists: every `balance-calib` sub-command and its
options, every launchless script, every node executable and the `-p NAME:=` parameters given it.

The guides are prose around command lines; this keeps the command lines true when a command or a
parameter is renamed. (What the commands then print is tested where each command is.)
"""

import functools
from pathlib import Path
import re
import subprocess

import pytest

from balance_calib.cli import build_parser

ROOT = Path(__file__).resolve().parents[2]
GUIDES = sorted((ROOT / 'docs' / 'guide').glob('*.md'))
SCRIPTS = ROOT / 'launchless_scripts'
NODES = (
    'bridge_publisher',
    'balance_calibrator',
    'balance_recorder',
    'thrust_analyzer',
    'aero_coefficients',
)


def _options(sub: str) -> set[str]:
    parser = build_parser()
    choices = next(a for a in parser._actions if hasattr(a, 'choices') and a.choices).choices
    assert sub in choices, f'no balance-calib {sub}'
    return {flag for action in choices[sub]._actions for flag in action.option_strings}


@functools.cache
def _node_help(node: str) -> str:
    done = subprocess.run([node, '--help'], capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert done.returncode == 0, (node, done.stderr)
    return done.stdout


def _command_lines(text: str) -> list[str]:
    """Code spans and fenced lines, continuation lines joined."""
    fenced = re.findall(r'```bash\n(.*?)```', text, re.S)
    lines = [line for block in fenced for line in block.replace('\\\n', ' ').splitlines()]
    return lines + re.findall(r'`([^`\n]+)`', re.sub(r'```.*?```', '', text, flags=re.S))


def test_the_five_task_guides_are_there():
    names = {p.name for p in GUIDES}
    assert names >= {
        'calibrate-from-bags.md',
        'calibrate-from-tables.md',
        'run-live.md',
        'reduce-windon.md',
        'thrust-stand.md',
    }, names


@pytest.mark.parametrize('guide', GUIDES, ids=lambda p: p.name)
def test_every_command_line_of_a_guide_names_what_exists(guide):
    checked = 0
    for line in _command_lines(guide.read_text(encoding='utf-8')):
        line = line.split('#')[0]
        for sub, rest in re.findall(r'balance-calib ([a-z][a-z-]+)(.*)', line):
            known = _options(sub)
            for flag in re.findall(r'(?<![\w-])(--[a-z][a-z-]*)', rest):
                assert flag in known, f'{guide.name}: balance-calib {sub} has no {flag}'
            checked += 1
        for name in re.findall(r'launchless_scripts/([a-z][a-z_]*)', line):
            assert (SCRIPTS / name).is_file(), f'{guide.name}: no launchless_scripts/{name}'
            checked += 1
        for node in NODES:
            if re.search(rf'(^|\s){node}\s', line + ' '):
                for parameter in re.findall(r'-p ([a-z_]+):=', line):
                    assert re.search(rf'\b{parameter}\b', _node_help(node)), (
                        f'{guide.name}: {node} --help names no parameter {parameter}'
                    )
                checked += 1
    assert checked > 0, f'{guide.name} names no command'
