"""pyproject.toml's [project] says what setup.py and package.xml say (colcon builds with setup.py,
pip reads pyproject.toml: the two must not drift apart), and its lint settings keep ament_flake8's
limits."""

import runpy
import tomllib
import xml.etree.ElementTree as ElementTree
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


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
    assert project['maintainers'] == [{'name': setup['maintainer'], 'email': setup['maintainer_email']}]
    assert (maintainer.text, maintainer.get('email')) == (setup['maintainer'], setup['maintainer_email'])
    # what setup.py alone gives must be declared dynamic, or setuptools drops it with a warning
    assert set(project['dynamic']) == {'dependencies', 'scripts'}
    assert setup['install_requires'] and setup['entry_points']['console_scripts']


def test_ruff_keeps_ament_flake8s_line_length_and_checks_what_it_checks():
    ruff = _pyproject()['tool']['ruff']
    assert ruff['line-length'] == 99      # ament_flake8.ini max-line-length
    selected = set(ruff['lint']['select'])
    # pycodestyle, pyflakes, builtins, comprehensions, docstrings, import order, quotes
    assert {'E', 'W', 'F', 'A', 'C4', 'D', 'I', 'Q'} <= selected
    assert ruff['lint']['flake8-quotes']['inline-quotes'] == 'single'
