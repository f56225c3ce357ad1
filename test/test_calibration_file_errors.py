"""A calibration.yaml that is not one: one line naming the file once, the line and what is wrong
(balance_calib.calibration_file.load_calibration), as the commands and the node print it.
"""

import pytest

from balance_calib.calibration_file import load_calibration, save_calibration
from balance_calib.cli import main
from balance_calib.config import ConfigError


@pytest.fixture(scope='module')
def text(tmp_path_factory):
    path = tmp_path_factory.mktemp('cal') / 'calibration.yaml'
    save_calibration(path, load_calibration('lmc6522'))
    return path.read_text()


def _error(tmp_path, text):
    path = tmp_path / 'calibration.yaml'
    path.write_text(text)
    with pytest.raises(ConfigError) as error:
        load_calibration(path)
    message = str(error.value)
    assert '\n' not in message and message.count(str(path)) == 1, message
    return message, path


def _line_of(text, needle, after=0):
    return next(
        i + 1 for i, line in enumerate(text.splitlines()) if i + 1 > after and needle in line
    )


def test_a_typo_in_a_coefficient_names_its_line(tmp_path, text):
    models = _line_of(text, 'models:')
    quadratic = _line_of(text, '  quadratic:', after=models)
    coefficients = _line_of(text, 'coefficients:', after=quadratic)
    typo = _line_of(text, '- ', after=coefficients + 1)  # a number under FX:
    lines = text.splitlines()
    value = lines[typo - 1].split('- ')[1]
    lines[typo - 1] = lines[typo - 1].split('- ')[0] + f'- {value}x'
    message, path = _error(tmp_path, '\n'.join(lines) + '\n')
    assert message.startswith(f'{path}, line {typo}: models.quadratic: ')
    assert f"'{value}x'" in message


def test_a_truncated_file_names_the_model_and_its_line(tmp_path, text):
    cubic = _line_of(text, '  cubic:', after=_line_of(text, 'models:'))
    cut = '\n'.join(text.splitlines()[: cubic + 3]) + '\n'
    message, path = _error(tmp_path, cut)
    assert message.startswith(f'{path}, line {cubic}: models.cubic: '), message


def test_broken_yaml_names_the_line_of_the_problem(tmp_path, text):
    lines = text.splitlines()
    at = _line_of(text, 'capacity:') + 1
    lines[at - 1] = '  FX: [1, 2'
    message, path = _error(tmp_path, '\n'.join(lines) + '\n')
    assert message.startswith(f'{path}, line {at + 1}: not valid YAML: ')
    assert 'flow sequence' in message


def test_a_model_that_is_not_a_mapping(tmp_path, text, capsys):
    cubic = _line_of(text, '  cubic:', after=_line_of(text, 'models:'))
    lines = text.splitlines()
    lines[cubic - 1] = '  cubic: 3'
    message, path = _error(tmp_path, '\n'.join(lines[:cubic]) + '\n')
    assert message == (
        f'{path}, line {cubic}: models.cubic: expected a mapping (form, terms, '
        f'coefficients), not int 3'
    )
    # as a command prints it: the file once
    assert (
        main(
            [
                'reduce',
                str(tmp_path / 'none'),
                '--calibration',
                str(path),
                '--model',
                'euler_replica',
                '--out',
                str(tmp_path / 'out'),
            ]
        )
        == 2
    )
    error = capsys.readouterr().err
    assert error.count(str(path)) == 1 and error.count('\n') == 1, error


def test_refit_names_a_broken_active_calibration_once(tmp_path, text, capsys):
    cubic = _line_of(text, '  cubic:', after=_line_of(text, 'models:'))
    path = tmp_path / 'active.yaml'
    path.write_text('\n'.join(text.splitlines()[:cubic]) + '\n  cubic: 3\n')
    assert (
        main(
            [
                'refit',
                str(tmp_path / 'none.mcap'),
                '--balance',
                'lmc6522',
                '--out',
                str(tmp_path / 'out'),
                '--active',
                str(path),
            ]
        )
        == 2
    )
    error = capsys.readouterr().err
    assert error.count(str(path)) == 1 and error.count('\n') == 1, error
    assert f'active calibration {path}, line {cubic + 1}: models.cubic:' in error
