"""balance_calibrator's parameter table (parameter_table.Spec) and its checks, without rclpy.

The node declares each with its description and range (nodes/_parameters.py: rclpy's
FloatingPointRange / IntegerRange, so `ros2 param describe` shows them) and checks every value, at
start-up and at runtime, with `check_parameter`: the table's own check (check_value of
parameter_table.py, which also refuses NaN and inf) and a FIFO or a device as a file.
"""

from __future__ import annotations

import os
from pathlib import Path
import stat
from typing import TYPE_CHECKING

from ..parameter_table import check_value, Spec, STRING_ARRAY

if TYPE_CHECKING:  # for annotations only: the node's --help need not import numpy
    from ..model.calibration import Calibration

INPUT_UNITS = ('mV', 'mV/V', 'microV/V')

PARAMETERS: dict[str, Spec] = {
    'calibration_file': Spec(
        '',
        'calibration.yaml or balance config, also by name (default: the shipped '
        'config/lmc6522.yaml); a regular file of at most 16 MB',
    ),
    'model': Spec(
        'adopted', 'linear | quadratic | cubic | adopted (or any model name in the file)'
    ),
    'installation': Spec(
        'upright', 'upright (TM-663 §10.2.1) | inverted (§10.2.2) | e.g. "-FX,FY,-FZ,MX,MY,MZ"'
    ),
    'frame_id': Spec('tunnel', 'frame_id of balance/wrench'),
    'tare_samples': Spec(100, 'samples averaged by ~/tare and ~/zero', 10, 1_000_000),
    'tare_timeout_s': Spec(
        10.0,
        '~/tare and ~/zero fail if the samples do not arrive within this time, s',
        0.01,
        3600.0,
    ),
    'tare_max_scatter': Spec(
        4.0,
        '~/tare and ~/zero refuse a window whose scatter, or the difference of its '
        'halves, exceeds this many times its sample-to-sample noise',
        1.5,
        1000.0,
    ),
    'tare_file': Spec(
        '',
        'where the zero and tare persist ("" = beside calibration_file as <name>.tare.yaml; '
        'not persisted when calibration_file is a shipped balance config)',
    ),
    'calibration_bags': Spec(STRING_ARRAY, 'bags (directories or .mcap) that ~/refit fits'),
    'balance': Spec('lmc6522', 'balance config for the refit (schedule, body, capacity)'),
    'report_dir': Spec(
        '~/.balance_calib/reports', '~/refit writes each run into a new directory here'
    ),
    'refit_timeout_s': Spec(
        1800.0, '~/refit gives up (and kills its process) after this time, s', 1.0, 86400.0
    ),
    'input_reliability': Spec(
        'reliable',
        'QoS of the balance/raw subscription: reliable | best_effort '
        '(qos_overrides./balance/raw.subscription.* take precedence)',
        read_only=True,
    ),
    'input_depth': Spec(
        1000, 'queue depth of the balance/raw subscription', 1, 100_000, read_only=True
    ),
    'stale_after_s': Spec(1.0, 'an input silent this long is STALE, s', 0.001, 3600.0),
    'diagnostics_period_s': Spec(1.0, 'period of /diagnostics, s', 0.01, 3600.0),
    'envelope_margin': Spec(
        1.1, 'loads beyond this times capacity are flagged as outside the envelope', 0.5, 10.0
    ),
    'output_range_factor': Spec(
        2.0,
        'an output beyond this times its rated output is a saturated bridge '
        '(the sample is not published)',
        1.0,
        100.0,
    ),
    'overload_fraction': Spec(
        1.0, 'balance/overload is true while a load exceeds its rated load times this', 0.01, 10.0
    ),
    'overload_clear_s': Spec(
        1.0,
        'balance/overload returns to false after the loads stayed inside this long, s',
        0.0,
        3600.0,
    ),
    'publish_uncertainty': Spec(
        True,
        'publish balance/wrench_uncertainty (k = 1, N and N·m, tunnel axes) when the '
        'calibration carries its coefficient covariance',
    ),
    'input_units': Spec(
        'mV',
        'unit of the bridge outputs on balance/raw: mV | mV/V | microV/V '
        '(ratiometric outputs are multiplied by excitation_v); the wire '
        'format of the interface is mV',
        choices=INPUT_UNITS,
    ),
    'excitation_v': Spec(
        0.0,
        'bridge excitation voltage, V, for ratiometric input_units (0 = not given)',
        0.0,
        100.0,
    ),
    'lowpass_hz': Spec(
        0.0,
        'first-order low-pass cut-off on the published wrench, Hz (0 = off); reset by '
        '~/tare and ~/zero',
        0.0,
        100_000.0,
    ),
}

MAX_CALIBRATION_BYTES = 16 << 20


def check_parameter(name: str, value: object) -> object:
    """The value as the parameter holds it (5 for a double is 5.0); ValueError with one line
    naming the parameter, its range and the value, if `value` is not valid.
    """
    spec = PARAMETERS.get(name)
    if spec is None:
        return value
    held = check_value(name, spec, value)
    if name == 'calibration_file' and value:
        check_regular_file(value, 'calibration_file')
    return held


def input_scale_mv(input_units: str, excitation_v: float) -> float:
    """MV per unit of balance/raw: 1 for mV; for ratiometric outputs the excitation
    (units.ratiometric_to_mv).

    ValueError naming the parameters when a ratiometric unit has no positive excitation_v.
    """
    if input_units == 'mV':
        return 1.0
    from ..units import ratiometric_to_mv

    if not excitation_v > 0.0:
        raise ValueError(
            f'parameter input_units = {input_units} needs excitation_v > 0 (the bridge supply, '
            f'V), not {excitation_v:g}'
        )
    return float(ratiometric_to_mv(1.0, input_units, excitation_v))


def check_input_units(calibration: Calibration, input_units: str, where: str) -> None:
    """A calibration fitted from a table in counts, dimensionless or mV/V outputs (its
    `extra.output_unit`) takes balance/raw in that unit as it is: a ratiometric input_units would
    multiply the outputs by the excitation first and every load would be off by that factor.
    ValueError naming both; input_units mV (no conversion) passes.
    """
    unit = calibration.output_unit
    if unit != 'mV' and input_units != 'mV':
        raise ValueError(
            f'parameter input_units = {input_units} turns balance/raw into mV, but '
            f'{where} takes bridge outputs in {unit}: set input_units mV (balance/raw '
            f'passed as it is) and publish the outputs in {unit}'
        )


def check_regular_file(path: object, what: str, max_bytes: int = MAX_CALIBRATION_BYTES) -> None:
    """A path that names a missing file is left to the loader (which says so); a FIFO, a device or
    a huge file is refused here, before anything opens it (a FIFO would block, /dev/zero never
    ends).
    """
    try:
        info = os.stat(os.path.expanduser(str(path)))
    except OSError:
        return
    if not stat.S_ISREG(info.st_mode):
        kind = (
            'a FIFO'
            if stat.S_ISFIFO(info.st_mode)
            else 'a directory'
            if stat.S_ISDIR(info.st_mode)
            else 'a device'
            if stat.S_ISCHR(info.st_mode) or stat.S_ISBLK(info.st_mode)
            else 'not a regular file'
        )
        raise ValueError(f'{what} {path} is {kind}, not a calibration file')
    if info.st_size > max_bytes:
        raise ValueError(
            f'{what} {path} has {info.st_size} bytes, more than a calibration file '
            f'can have ({max_bytes})'
        )


def load_calibration_checked(path: str | Path, timeout_s: float = 10.0) -> Calibration:
    """load_calibration bounded in size (a regular file of at most 16 MB) and in time (read in a
    helper thread; a file system that does not answer within timeout_s is an error, not a hung
    node).
    """
    import threading

    from ..calibration_file import ConfigError, load_calibration

    try:
        check_regular_file(path, 'calibration_file')
    except ValueError as err:
        raise ConfigError(str(err)) from None
    result: list[Calibration | BaseException] = []

    def read() -> None:
        try:
            result.append(load_calibration(path))
        except BaseException as err:  # handed to the caller below
            result.append(err)

    reader = threading.Thread(target=read, name='calibration reader', daemon=True)
    reader.start()
    reader.join(timeout_s)
    if not result:
        raise ConfigError(
            f'{path}: reading the calibration file did not finish within {timeout_s:g} s'
        )
    if isinstance(result[0], BaseException):
        raise result[0]
    return result[0]
