"""A new user's clumsy inputs: each answered in one clear line, never a traceback, never a silent
wrong answer.

The one list: misspelled parameters and names, wrong files, missing keys, NaN in a table, loads in
the wrong unit, a missing bag, a model file that is not the model that was run. Each case is a
command as the user types it; the answer is either a refusal (non-zero exit, one line naming the
file, key or parameter) or a one-line warning beside a result (exit 0). Commands of
`balance-calib` run in-process (main()); nodes and scripts as processes (ROS tests).
"""

from __future__ import annotations

from dataclasses import dataclass
import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import balance_calib
from balance_calib.cli import main

ROOT = Path(balance_calib.__file__).resolve().parent.parent
SCRIPTS = ROOT / 'launchless_scripts'
SIX = 'FX,FY,FZ,MX,MY,MZ'


@dataclass
class Answer:
    status: int
    out: str
    err: str

    @property
    def text(self) -> str:
        return self.out + self.err


def cli(capsys, *args) -> Answer:
    try:
        status = main([str(a) for a in args])
    except SystemExit as exit_:  # argparse
        status = exit_.code if isinstance(exit_.code, int) else 1
    captured = capsys.readouterr()
    return Answer(int(status or 0), captured.out, captured.err)


def _without_paths(line: str) -> str:
    """The line without its paths: a key must be named in the message, not in a test's tmp_path
    (.../test_coverage_refuses_a_calibration_without_adopted_model0/cal.yaml).
    """
    return re.sub(r'\S*/\S*', '', line)


def _names_all(line: str, names, paths) -> bool:
    bare = _without_paths(line)
    return all(n in bare for n in names) and all(str(p) in line for p in paths)


def refused(answer: Answer, *names: str, paths=()) -> None:
    """Non-zero exit and one line on stderr naming every one of `names` (outside its paths) and
    of `paths`.
    """
    assert 'Traceback' not in answer.text, answer.text
    assert answer.status != 0, f'accepted (exit 0):\n{answer.text[-2000:]}'
    lines = [line for line in answer.err.splitlines() if line.strip()]
    assert len(lines) == 1, answer.err
    assert _names_all(lines[0], names, paths), f'{names} {paths} not all in: {lines[0]}'


def warned(answer: Answer, *names: str) -> None:
    """Exit 0 and one warning line naming every one of `names` (outside its paths)."""
    assert 'Traceback' not in answer.text, answer.text
    assert answer.status == 0, answer.text[-2000:]
    lines = [line for line in answer.text.splitlines() if 'warn' in line.lower()]
    assert any(_names_all(line, names, ()) for line in lines), (
        f'no warning naming {names}:\n{answer.text[-2000:]}'
    )


# ---------------------------------------------------------------------------- files


@pytest.fixture(scope='module')
def fitted(tmp_path_factory) -> Path:
    """A calibration.yaml as refit writes it (with its covariance), of the LMC6522."""
    from balance_calib.calibration_file import save_calibration
    from balance_calib.calibration_settings import CalibrationSettings
    from balance_calib.config import load_balance_config
    from balance_calib.refit.pipeline import calibrate_points, campaign_points
    from balance_calib.simulation.balance_sim import simulate_campaign, SimulationSettings

    config = load_balance_config('lmc6522')
    campaign = simulate_campaign(config, settings=SimulationSettings(seed=5))
    calibration = calibrate_points(
        campaign_points(campaign), config, settings=CalibrationSettings(diagnose=False)
    ).calibration
    path = tmp_path_factory.mktemp('fitted') / 'calibration.yaml'
    save_calibration(path, calibration)
    return path


def without_line(source: Path, target: Path, start: str) -> Path:
    """The file with its line starting with `start` deleted, as a user's editor leaves it."""
    lines = source.read_text().splitlines(keepends=True)
    kept = [line for line in lines if not line.startswith(start)]
    assert len(kept) == len(lines) - 1
    target.write_text(''.join(kept))
    return target


def without_capacity_of(source: Path, target: Path, component: str) -> Path:
    text = source.read_text()
    start = text.index('\ncapacity:')
    line = text.index(f'\n  {component}:', start)
    target.write_text(text[:line] + text[text.index('\n', line + 1) :])
    return target


def loads_csv(path: Path, rows, header: str = SIX) -> Path:
    path.write_text(header + '\n' + '\n'.join(','.join(str(v) for v in r) for r in rows) + '\n')
    return path


@pytest.fixture(scope='module')
def run_bag(tmp_path_factory) -> Path:
    """A wind-on run of the euler_replica_lmc6522 (250 N) on the LMC6522, as a bag."""
    from aero_cases import run_bag as write

    path = tmp_path_factory.mktemp('run') / 'run'
    write(path)
    return path


LOADS = [[10.0, 20.0, -300.0, 1.0, 5.0, 2.0], [-20.0, 50.0, -500.0, 2.0, 8.0, -3.0]]

# ---------------------------------------------------------------------------- calibration files


def test_coverage_refuses_a_calibration_without_adopted_model(tmp_path, capsys, fitted):
    cal = without_line(fitted, tmp_path / 'cal.yaml', 'adopted_model:')
    refused(cli(capsys, 'coverage', cal, loads_csv(tmp_path / 'l.csv', LOADS)), 'adopted_model')


def test_reduce_refuses_a_calibration_without_adopted_model(tmp_path, capsys, fitted, run_bag):
    cal = without_line(fitted, tmp_path / 'cal.yaml', 'adopted_model:')
    answer = cli(
        capsys, 'reduce', run_bag, '--calibration', cal, '--model', 'euler_replica_lmc6522',
        '--out', tmp_path / 'out',
    )  # fmt: skip
    refused(answer, 'adopted_model', paths=[cal])


def test_design_refuses_a_calibration_without_adopted_model(tmp_path, capsys, fitted):
    cal = without_line(fitted, tmp_path / 'cal.yaml', 'adopted_model:')
    envelope = loads_csv(tmp_path / 'e.csv', LOADS)
    answer = cli(
        capsys, 'design', '--balance', 'lmc6522', '--envelope', envelope, '--points', 2,
        '--calibration', cal, '--out', tmp_path / 'out',
    )  # fmt: skip
    refused(answer, 'adopted_model')


def test_check_refuses_a_calibration_without_adopted_model(tmp_path, capsys, fitted):
    cal = without_line(fitted, tmp_path / 'cal.yaml', 'adopted_model:')
    answer = cli(capsys, 'check', cal, tmp_path / 'check_loads.csv', '--out', tmp_path / 'out')
    refused(answer, 'adopted_model')


def test_compare_refuses_a_calibration_without_adopted_model(tmp_path, capsys, fitted):
    cal = without_line(fitted, tmp_path / 'cal.yaml', 'adopted_model:')
    refused(cli(capsys, 'compare', fitted, cal, '--out', tmp_path / 'out'), 'adopted_model')


def test_a_deleted_full_scale_line_is_named_with_its_key(tmp_path, capsys, fitted):
    cal = without_capacity_of(fitted, tmp_path / 'cal.yaml', 'MZ')
    refused(cli(capsys, 'coverage', cal, loads_csv(tmp_path / 'l.csv', LOADS)), 'capacity:', 'MZ')


def test_a_calibration_that_is_not_yaml_is_named_with_its_line(tmp_path, capsys, fitted):
    cal = tmp_path / 'cal.yaml'
    cal.write_text(fitted.read_text().replace('adopted_model: cubic', 'adopted_model: [cubic'))
    refused(
        cli(capsys, 'coverage', cal, loads_csv(tmp_path / 'l.csv', LOADS)), 'line', paths=[cal]
    )


def test_a_misspelled_calibration_path_is_named(tmp_path, capsys):
    answer = cli(capsys, 'coverage', tmp_path / 'calibraton.yaml', tmp_path / 'l.csv')
    refused(answer, paths=['calibraton.yaml'])


def test_coverage_of_the_memo_matrices_says_they_carry_no_covariance(tmp_path, capsys):
    refused(cli(capsys, 'coverage', 'lmc6522', loads_csv(tmp_path / 'l.csv', LOADS)), 'covariance')


# ---------------------------------------------------------------------------- reduce


def test_reduce_with_another_models_file_warns_about_its_weight(tmp_path, capsys, run_bag):
    # the run flew euler_replica_lmc6522 (250 N); the user names euler_replica (40 N)
    answer = cli(
        capsys, 'reduce', run_bag, '--calibration', 'lmc6522', '--model', 'euler_replica',
        '--out', tmp_path / 'out',
    )  # fmt: skip
    warned(answer, 'euler_replica', 'weight', '40 N')


def test_reduce_with_a_misspelled_model_name_is_refused(tmp_path, capsys, run_bag):
    answer = cli(
        capsys, 'reduce', run_bag, '--calibration', 'lmc6522', '--model', 'euler_replika',
        '--out', tmp_path / 'out',
    )  # fmt: skip
    refused(answer, 'euler_replika')


def test_reduce_of_a_missing_bag_names_it(tmp_path, capsys):
    answer = cli(
        capsys, 'reduce', tmp_path / 'runn', '--calibration', 'lmc6522', '--model',
        'euler_replica_lmc6522', '--out', tmp_path / 'out',
    )  # fmt: skip
    refused(answer, paths=[tmp_path / 'runn'])


def test_reduce_with_an_unknown_installation_names_it(tmp_path, capsys, run_bag):
    answer = cli(
        capsys, 'reduce', run_bag, '--calibration', 'lmc6522', '--model',
        'euler_replica_lmc6522', '--installation', 'sideways', '--out', tmp_path / 'out',
    )  # fmt: skip
    refused(answer, 'sideways')


def test_a_model_file_without_its_reference_area_is_refused(tmp_path, capsys, run_bag):
    model = tmp_path / 'my_model.yaml'
    source = ROOT / 'config' / 'models' / 'euler_replica_lmc6522.yaml'
    without_line(source, model, 'reference_area_m2:')
    answer = cli(
        capsys, 'reduce', run_bag, '--calibration', 'lmc6522', '--model', model,
        '--out', tmp_path / 'out',
    )  # fmt: skip
    refused(answer, 'reference_area_m2')


# ---------------------------------------------------------------------------- nozzle


def test_nozzle_with_a_shock_inside_gives_no_isentropic_thrust(capsys):
    import json

    # p_c = 1.5 bar at sea level: the normal shock stands inside the diverging section
    answer = cli(capsys, 'nozzle', '--chamber-pa', 150000, '--ambient-pa', 101325)
    warned(answer, 'shock')
    result = json.loads(answer.out)
    assert result['flow_regime'] == 'shock in nozzle' and result['thrust_n'] is None


def test_nozzle_with_a_gauge_chamber_pressure_is_refused(capsys):
    refused(cli(capsys, 'nozzle', '--chamber-pa', 50000, '--ambient-pa', 101325), 'absolute')


# ---------------------------------------------------------------------------- names and tables


def test_refit_with_a_misspelled_balance_names_it(tmp_path, capsys):
    answer = cli(capsys, 'refit', tmp_path, '--balance', 'lmc6552', '--out', tmp_path / 'o')
    refused(answer, 'lmc6552')


def test_simulate_with_a_misspelled_effect_names_it(capsys):
    answer = cli(capsys, 'simulate', '--effects', 'temprature:sensitivity_per_k=1e-4')
    refused(answer, 'temprature')


def test_a_table_with_nan_names_its_row(tmp_path, capsys):
    from table_cases import fix_width, HAND_TABLE

    table = tmp_path / 'table.csv'
    table.write_text(
        fix_width(HAND_TABLE).replace(',P4,2,A,0,25,12,494,71', ',P4,2,A,0,25,12,nan,71')
    )
    answer = cli(capsys, 'fit', table, '--out', tmp_path / 'out', '--method', 'direct')
    refused(answer, 'row', paths=[table])


def test_fit_of_a_missing_table_names_it(tmp_path, capsys):
    refused(
        cli(capsys, 'fit', tmp_path / 'tabel.csv', '--out', tmp_path / 'o'), paths=['tabel.csv']
    )


def test_loads_with_nan_name_the_row(tmp_path, capsys, fitted):
    loads = loads_csv(tmp_path / 'l.csv', LOADS + [[1.0, 'nan', 2.0, 0.0, 0.0, 0.0]])
    refused(cli(capsys, 'coverage', fitted, loads), 'row 3')


def test_loads_with_a_lower_case_header_name_the_columns(tmp_path, capsys, fitted):
    loads = loads_csv(tmp_path / 'l.csv', LOADS, header='Fx,Fy,Fz,Mx,My,Mz')
    refused(cli(capsys, 'coverage', fitted, loads), 'FX')


def test_an_envelope_in_n_mm_is_beyond_capacity_and_named(tmp_path, capsys):
    # moments given in N·mm: 1000 times too large
    envelope = loads_csv(tmp_path / 'e.csv', [[10, 20, -300, 1000, 5000, 2000]])
    answer = cli(
        capsys, 'design', '--balance', 'lmc6522', '--envelope', envelope, '--points', 2,
        '--out', tmp_path / 'out',
    )  # fmt: skip
    refused(answer, 'row 1', 'capacity')


def test_line_fit_without_a_y_column_names_it(tmp_path, capsys):
    points = tmp_path / 'p.csv'
    points.write_text('x,Y\n1,2\n2,3\n3,5\n')
    refused(cli(capsys, 'line-fit', points), 'column(s) y')


def test_refit_into_a_directory_holding_a_calibration_asks_for_overwrite(tmp_path, capsys):
    out = tmp_path / 'out'
    out.mkdir()
    (out / 'calibration.yaml').write_text('balance: LMC6522\n')
    answer = cli(capsys, 'refit', tmp_path / 'bag', '--balance', 'lmc6522', '--out', out)
    refused(answer, '--overwrite')


def test_coverage_of_a_missing_bag_names_it(tmp_path, capsys, fitted):
    refused(cli(capsys, 'coverage', fitted, tmp_path / 'tour_run'), paths=[tmp_path / 'tour_run'])


# ---------------------------------------------------------------------------- nodes and scripts


def run_process(command, domain_id: int, timeout: float = 60.0, **env) -> Answer:
    done = subprocess.run(
        [str(c) for c in command],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=dict(os.environ, ROS_DOMAIN_ID=str(domain_id), **env),
    )
    return Answer(done.returncode, done.stdout, done.stderr)


def node_until(command, domain_id: int, needle: str, timeout: float = 60.0) -> Answer:
    """A node that keeps running: its output up to the line holding `needle` (or the timeout),
    then SIGINT; status 0 when it ran until stopped.
    """
    process = subprocess.Popen(
        [str(c) for c in command],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=dict(os.environ, ROS_DOMAIN_ID=str(domain_id)),
    )
    assert process.stdout is not None
    lines, deadline = [], time.monotonic() + timeout
    os.set_blocking(process.stdout.fileno(), False)
    while time.monotonic() < deadline and process.poll() is None:
        line = process.stdout.readline()
        if not line:
            time.sleep(0.05)
            continue
        lines.append(line)
        if needle in line:
            break
    running = process.poll() is None
    process.send_signal(signal.SIGINT)
    try:
        process.wait(timeout=10)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()
    os.set_blocking(process.stdout.fileno(), True)
    lines.append(process.stdout.read())
    return Answer(0 if running else process.returncode or 1, ''.join(lines), '')


@pytest.mark.ros
def test_a_misspelled_calibrator_parameter_is_warned_about(ros_domain, fitted):
    answer = node_until(
        ['balance_calibrator', '--ros-args', '-p', f'calibraton_file:={fitted}'],
        ros_domain,
        'does not declare',
    )
    warned(answer, 'calibraton_file', 'calibration_file')


@pytest.mark.ros
def test_a_misspelled_publisher_parameter_is_warned_about(ros_domain):
    answer = node_until(
        ['bridge_publisher', '--ros-args', '-p', 'rate:=100.0'], ros_domain, 'does not declare'
    )
    warned(answer, 'rate', 'rate_hz')


@pytest.mark.ros
def test_the_calibrator_refuses_a_calibration_without_adopted_model(tmp_path, ros_domain, fitted):
    cal = without_line(fitted, tmp_path / 'cal.yaml', 'adopted_model:')
    answer = run_process(
        ['balance_calibrator', '--ros-args', '-p', f'calibration_file:={cal}'], ros_domain
    )
    assert 'Traceback' not in answer.text and answer.status != 0, answer.text
    assert any('adopted_model' in line and 'ERROR' in line for line in answer.err.splitlines())


@pytest.mark.ros
def test_the_calibrator_names_a_misspelled_model(ros_domain):
    answer = run_process(['balance_calibrator', '--ros-args', '-p', 'model:=cubik'], ros_domain)
    assert 'Traceback' not in answer.text and answer.status != 0, answer.text
    assert any('cubik' in line and 'ERROR' in line for line in answer.err.splitlines())


@pytest.mark.ros
def test_the_publisher_names_a_misspelled_mode(ros_domain):
    answer = run_process(['bridge_publisher', '--ros-args', '-p', 'mode:=windon'], ros_domain)
    assert 'Traceback' not in answer.text and answer.status != 0, answer.text
    assert any('windon' in line and 'mode' in line for line in answer.err.splitlines())


@pytest.mark.ros
def test_trigger_says_at_once_that_no_node_serves_the_service(ros_domain):
    # nothing runs on this domain: said from the graph, not after a wait for an answer
    answer = run_process([SCRIPTS / 'trigger', '/balance_calibrator/tare'], ros_domain)
    refused(answer, 'not in the graph', paths=['/balance_calibrator/tare'])


@pytest.mark.ros
def test_ros_param_get_of_a_node_not_running_names_it(ros_domain):
    answer = run_process(
        [SCRIPTS / 'ros', 'param', 'get', '/balance_calibratr', 'model', '--timeout', '2'],
        ros_domain,
    )
    refused(answer, paths=['/balance_calibratr'])


@pytest.mark.ros
def test_windon_into_an_existing_directory_is_refused(tmp_path, ros_domain):
    refused(run_process([SCRIPTS / 'windon', tmp_path], ros_domain), paths=[tmp_path])


# ---------------------------------------------------------------------------- not user input


def test_node_logs_of_an_executable_given_by_path_stay_in_the_log_directory(tmp_path):
    # the demo's aero_coefficients by absolute path wrote its .out/.err into .venv/bin
    from balance_calib.launchless.processes import NodeProcess

    executable = Path(sys.executable).parent / 'balance-calib'
    process = NodeProcess(str(executable), 150, tmp_path / 'logs')
    process.stop()
    assert process.stdout_path.parent == tmp_path / 'logs'
    assert process.stdout_path.name == 'balance-calib.1.out'


def test_stories_take_the_shells_ros_domain_id(monkeypatch):
    from balance_calib.launchless.processes import story_domain_id

    monkeypatch.setenv('ROS_DOMAIN_ID', '173')
    assert story_domain_id() == 173
    monkeypatch.setenv('ROS_DOMAIN_ID', 'forty')
    with pytest.raises(ValueError, match='forty'):
        story_domain_id()
    monkeypatch.delenv('ROS_DOMAIN_ID')
    assert all(1 <= story_domain_id() <= 99 for _ in range(20))


def test_the_demo_ends_with_where_its_results_are():
    text = (SCRIPTS / 'demo').read_text()
    summary = text.split('Where the results are', 1)[1].splitlines()[1:]
    assert [line.split(':')[0] for line in summary if line.startswith('echo "')] == [
        'echo "refit of the DDS campaign',
        'echo "wind-on reduction (§10.3)',
        'echo "node logs',
    ]


def test_reduce_with_the_right_models_file_does_not_warn_about_its_weight(tmp_path, run_bag):
    from balance_calib.aero.pipeline import reduce_bags

    reduction = reduce_bags([run_bag], 'lmc6522', 'euler_replica_lmc6522')
    assert not [w for w in reduction.main.result.warnings if 'weight' in w], (
        reduction.main.result.warnings
    )
    assert np.isfinite(reduction.main.result.tares[0].weight_n)
