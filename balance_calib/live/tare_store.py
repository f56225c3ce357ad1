"""The active zero and tare of a live calibrator, persisted beside its calibration and restored at start-up.

The file (YAML, replaced atomically) holds the electrical zero (mV, with the temperature and load
direction at that moment, for models with such terms) and the tare load (N, N·m, balance
calibration axes: independent of the installation), with the balance name and when each was taken.
"""
from __future__ import annotations

import datetime as _dt
import os
import stat
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from ..calibration_file import write_text_atomically
from ..units import BRIDGE_OUTPUTS, COMPONENTS

FORMAT = 'balance_calib/tare 1'
MAX_BYTES = 1 << 16


@dataclass(frozen=True)
class TareState:
    balance: str
    zero_mv: np.ndarray | None = None             # (6,) FXV..MZV
    zero_temperature_c: float | None = None
    zero_direction: np.ndarray | None = None      # (6,) +-1
    zero_taken_at: str = ''
    tare_load: np.ndarray | None = None           # (6,) FX..MZ, balance axes, N / N·m
    tare_taken_at: str = ''
    tare_sigma: np.ndarray | None = None          # (6,) standard uncertainty of the tare load, N / N·m

    def to_dict(self) -> dict:
        def plain(values, names):
            return None if values is None else {n: float(v) for n, v in zip(names, values)}
        return {'format': FORMAT, 'balance': self.balance,
                'zero_mv': plain(self.zero_mv, BRIDGE_OUTPUTS), 'zero_temperature_c': self.zero_temperature_c,
                'zero_direction': plain(self.zero_direction, COMPONENTS), 'zero_taken_at': self.zero_taken_at,
                'tare_load_balance_axes': plain(self.tare_load, COMPONENTS), 'tare_taken_at': self.tare_taken_at,
                'tare_sigma_balance_axes': plain(self.tare_sigma, COMPONENTS)}


def now_iso() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec='seconds')


def tare_file_for(calibration_source: str, node_name: str, calibration_is_config: bool) -> Path | None:
    """Beside the calibration: calibration.yaml -> calibration.tare.yaml (another node name or namespace
    gets its own file). None for a shipped balance config: nothing is written into the package, and
    no hidden state in a home directory changes what a fresh node reads (set `tare_file` instead)."""
    if calibration_is_config:
        return None
    suffix = '' if node_name in ('', '/balance_calibrator') else '.' + node_name.strip('/').replace('/', '.')
    source = Path(calibration_source)
    return source.with_name(f'{source.stem}{suffix}.tare.yaml')


def save_tare(path: Path, state: TareState) -> None:
    write_text_atomically(path, '# zero and tare of a balance_calibrator; written by the node\n'
                          + yaml.safe_dump(state.to_dict(), sort_keys=False))


def load_tare(path: Path, balance: str) -> TareState | None:
    """The persisted state, None if there is no file; ValueError naming the file if it is unusable."""
    try:
        info = os.stat(path)
    except FileNotFoundError:
        return None
    except OSError as err:
        raise ValueError(f'{path}: cannot read tare file: {err.strerror}') from None
    if not stat.S_ISREG(info.st_mode) or info.st_size > MAX_BYTES:
        raise ValueError(f'{path}: not a tare file (not a regular file of at most {MAX_BYTES} bytes)')
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as err:
        raise ValueError(f'{path}: unreadable tare file: {str(err).splitlines()[0]}') from None
    if not isinstance(data, dict) or data.get('format') != FORMAT:
        raise ValueError(f'{path}: not a tare file (format is not {FORMAT!r})')
    if str(data.get('balance', '')).lower() != balance.lower():
        raise ValueError(f'{path}: tare of balance {data.get("balance")!r}, not of {balance!r}')

    def vector(key, names):
        values = data.get(key)
        if values is None:
            return None
        try:
            result = np.array([float(values[n]) for n in names])
        except (KeyError, TypeError, ValueError):
            raise ValueError(f'{path}: {key} needs numbers for {", ".join(names)}') from None
        if not np.all(np.isfinite(result)):
            raise ValueError(f'{path}: {key} holds a NaN or infinite value')
        return result
    temperature = data.get('zero_temperature_c')
    return TareState(balance, vector('zero_mv', BRIDGE_OUTPUTS), None if temperature is None else float(temperature),
                     vector('zero_direction', COMPONENTS), str(data.get('zero_taken_at') or ''),
                     vector('tare_load_balance_axes', COMPONENTS), str(data.get('tare_taken_at') or ''),
                     vector('tare_sigma_balance_axes', COMPONENTS))
