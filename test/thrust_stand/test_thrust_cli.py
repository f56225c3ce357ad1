"""`balance-calib nozzle` and `balance-calib line-fit`, run as a user runs them."""

import json
import shutil
import subprocess
import sys

import pytest

from balance_calib.thrust_stand.nozzle import Nozzle


def balance_calib(*args, timeout=60):
    executable = shutil.which('balance-calib')
    command = [executable] if executable else [sys.executable, '-m', 'balance_calib.cli']
    return subprocess.run(
        command + [str(a) for a in args], capture_output=True, text=True, timeout=timeout
    )


def test_nozzle_prints_the_manual_nozzle_as_json():
    done = balance_calib(
        'nozzle',
        '--throat-mm',
        2.5,
        '--exit-mm',
        3.3,
        '--chamber-pa',
        601325,
        '--ambient-pa',
        101325,
    )
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    expected = Nozzle().performance(601325.0, 101325.0)
    assert result['area_ratio'] == pytest.approx(1.7424)
    assert result['pe_over_pc'] == pytest.approx(expected.pe_over_pc, rel=1e-12)
    assert result['cf'] == pytest.approx(1.13664, abs=1e-5)
    assert result['thrust_n'] == pytest.approx(expected.thrust_n, rel=1e-12)
    for key in ('mass_flow_kg_s', 'exit_velocity_m_s', 'c_star_m_s', 'isp_s'):
        assert result[key] == pytest.approx(getattr(expected, key), rel=1e-12)

    subsonic = json.loads(
        balance_calib(
            'nozzle', '--chamber-pa', 601325, '--ambient-pa', 101325, '--subsonic'
        ).stdout
    )
    assert subsonic['pe_over_pc'] > result['critical_pressure_ratio'] > result['pe_over_pc']


def test_line_fit_prints_a_b_and_sigma(tmp_path):
    data = tmp_path / 'calibration.csv'
    # the hand-worked example of test_thrust_line_fit: a = 1.9, b = 0.9, σ_a = sqrt(0.0155)
    data.write_text('x,y,sx,sy\n0,1,0.1,0.2\n1,3,0.1,0.2\n2,4,0.1,0.2\n3,7,0.1,0.2\n')
    done = balance_calib('line-fit', data)
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result['a'] == pytest.approx(1.9) and result['b'] == pytest.approx(0.9)
    assert result['sigma_a'] == pytest.approx(0.0155**0.5)
    assert result['n'] == 4 and result['sigma_source'] == 'eq27'
    assert result['formatted'] == 'a = 1.90 ± 0.12'
    # printed as a person reads it, not JSON-escaped (and still JSON)
    assert '"a = 1.90 ± 0.12"' in done.stdout and '\\u00b1' not in done.stdout


@pytest.mark.parametrize(
    'content, problem',
    [
        (None, 'no such file'),
        ('u,v\n1,2\n2,3\n3,5\n', 'missing column(s) x, y'),
        ('x,y\n1,2\n2,oops\n3,4\n', "line 3: column y is 'oops'"),
        ('x,y\n1,2\n2,3\n', '2 point(s)'),
    ],
)
def test_line_fit_bad_input_is_one_stderr_line_and_status_2(tmp_path, content, problem):
    path = tmp_path / 'points.csv'
    if content is not None:
        path.write_text(content)
    done = balance_calib('line-fit', path)
    assert done.returncode == 2
    assert done.stdout == ''
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and problem in lines[0]


def test_nozzle_rejects_a_gauge_pressure_given_as_chamber_pressure():
    done = balance_calib('nozzle', '--chamber-pa', 90000, '--ambient-pa', 101325)
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1
    assert 'absolute' in done.stderr
