"""pyproject.toml's [project] says what setup.py and package.xml say (colcon builds with setup.py,
pip reads pyproject.toml: the two must not drift apart), and its lint settings keep ament_flake8's
limits.
"""

import importlib.util
import json
from pathlib import Path
import runpy
import subprocess
import sys
import tomllib
import xml.etree.ElementTree as ElementTree

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _pyproject() -> dict:
    return tomllib.loads((ROOT / 'pyproject.toml').read_text(encoding='utf-8'))


def _setup_keywords(monkeypatch) -> dict:
    import setuptools

    captured = {}
    monkeypatch.setattr(setuptools, 'setup', lambda **kwargs: captured.update(kwargs))
    monkeypatch.chdir(ROOT)
    runpy.run_path(str(ROOT / 'setup.py'))
    return captured


def test_project_metadata_is_the_one_of_setup_py_and_package_xml(monkeypatch):
    project = _pyproject()['project']
    setup = _setup_keywords(monkeypatch)
    package = ElementTree.parse(ROOT / 'package.xml').getroot()
    assert project['name'] == setup['name'] == package.findtext('name')
    assert project['version'] == setup['version'] == package.findtext('version')
    assert project['description'] == setup['description']
    assert project['license'] == {'text': setup['license']}
    assert setup['license'] == package.findtext('license')
    maintainer = package.find('maintainer')
    assert project['maintainers'] == [
        {'name': setup['maintainer'], 'email': setup['maintainer_email']}
    ]
    assert (maintainer.text, maintainer.get('email')) == (
        setup['maintainer'],
        setup['maintainer_email'],
    )
    # what setup.py alone gives must be declared dynamic, or setuptools drops it with a warning
    assert set(project['dynamic']) == {'dependencies', 'scripts'}
    assert setup['install_requires'] and setup['entry_points']['console_scripts']


def test_ruff_keeps_ament_flake8s_line_length_and_checks_what_it_checks():
    ruff = _pyproject()['tool']['ruff']
    assert ruff['line-length'] == 99  # ament_flake8.ini max-line-length
    selected = set(ruff['lint']['select'])
    # pycodestyle, pyflakes, builtins, comprehensions, docstrings, import order, quotes
    assert {'E', 'W', 'F', 'A', 'C4', 'D', 'I', 'Q'} <= selected
    assert ruff['lint']['flake8-quotes']['inline-quotes'] == 'single'


def test_colcon_reads_setup_py_with_this_pyproject_toml():
    """Colcon reads setup.py's arguments back through repr() and ast.literal_eval.

    colcon-python-setup-py does, for the ament_python build: a [project] key such as
    requires-python, which setuptools turns into a SpecifierSet, makes `colcon build` fail
    before it builds anything. Run in a child interpreter, as colcon runs it (colcon is the
    build tool, present wherever `colcon test` runs, not a dependency package.xml names).
    """
    code = (
        'import json, sys\nfrom pathlib import Path\n'
        'from colcon_python_setup_py.package_identification.python_setup_py import (\n'
        '    get_setup_information)\n'
        'info = get_setup_information(Path(sys.argv[1]))\n'
        "print(json.dumps([info['metadata']['name'], info['entry_points']['console_scripts']]))\n"
    )
    done = subprocess.run(
        [sys.executable, '-c', code, str(ROOT / 'setup.py')],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    name, scripts = json.loads(done.stdout.splitlines()[-1])
    assert name == 'balance_calib'
    assert 'balance_calibrator = balance_calib.nodes.balance_calibrator:main' in scripts


def test_the_strict_core_gets_every_flag_of_mypy_strict():
    """The [[tool.mypy.overrides]] block of the strict core sets what `mypy --strict` sets.

    launchless_scripts/lint runs mypy once; the strict core is strict through that block, so a
    flag a newer mypy adds to --strict must be added there too (or to [tool.mypy] when it is not
    a per-module flag), and every module it names must exist. mypy is the lint step's tool
    (requirements-test.txt), not a package.xml dependency: asked in a child interpreter, and the
    test is skipped where it is not installed.
    """
    if importlib.util.find_spec('mypy') is None:
        pytest.skip('mypy is not installed here (the lint step has it: requirements-test.txt)')
    code = (
        'import json\nfrom mypy.main import define_options\n'
        'from mypy.options import PER_MODULE_OPTIONS\n'
        'print(json.dumps([[o, v, o in PER_MODULE_OPTIONS] for o, v in define_options()[2]]))\n'
    )
    done = subprocess.run(
        [sys.executable, '-c', code], capture_output=True, text=True, timeout=60, check=True
    )
    strict_assignments = json.loads(done.stdout)  # [option, value, per module] that --strict sets
    assert strict_assignments, 'mypy no longer lists what --strict sets'
    mypy = _pyproject()['tool']['mypy']
    blocks = [o for o in mypy['overrides'] if o.get('disallow_untyped_defs') is True]
    assert len(blocks) == 1, 'one block lists the strict core'
    strict = blocks[0]
    for option, value, per_module in strict_assignments:
        where = strict if per_module else mypy
        assert where.get(option, mypy.get(option)) == value, option
    for module in strict['module']:
        parts = module.removesuffix('.*').split('.')
        path = ROOT.joinpath(*parts)
        found = path.is_dir() if module.endswith('.*') else path.with_suffix('.py').is_file()
        assert found, module
