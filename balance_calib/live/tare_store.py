"""The active zero and tare of a live calibrator, persisted beside its calibration and restored at
start-up.

The file (YAML, replaced atomically) holds the electrical zero (mV, with the temperature and load
direction at that moment, for models with such terms) and the tare load (N, N·m, balance
calibration axes) with the mean raw outputs, temperature and load direction it was read from (so
that a new calibration of the same installation re-reads it, `LiveCalibrator.set_active`), with
the balance name and when each was taken, and what they were taken for
(`TareOwner`): the calibration (SHA-256 of the calibration file's bytes), the installation, the
namespace and the node. A tare load in balance axes is not independent of the installation: the
model's weight loads the balance the other way once it is mounted inverted. The state is restored
only for the same owner (`restore_refusal`); a file of the first format records no owner and is
never restored.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
import datetime as _dt
import hashlib
import os
from pathlib import Path
import stat
from typing import Any, Sequence

import numpy as np
import yaml

from ..calibration_file import write_text_atomically
from ..tunnel_axes import Installation
from ..units import BRIDGE_OUTPUTS, COMPONENTS

FORMAT = 'balance_calib/tare 3'
# 'tare 2' is restored (it has an owner) but records no tare outputs: a later calibration clears
# its tare load instead of re-reading it; 'tare 1' is read, never restored: it records no owner
OLDER_FORMATS = ('balance_calib/tare 2', 'balance_calib/tare 1')
MAX_BYTES = 1 << 16


@dataclass(frozen=True)
class TareOwner:
    """What a zero and tare were taken for; restored only when all four are the same."""

    calibration_sha256: str  # of the calibration file's bytes ('' = unknown: never matches)
    installation: str  # signed permutation '-FX,FY,-FZ,MX,MY,MZ' (Installation.spec)
    namespace: str  # e.g. '/' or '/left'
    node: str  # e.g. 'balance_calibrator'
    installation_name: str = ''  # e.g. 'upright', for messages only

    @classmethod
    def of_node(
        cls, calibration_sha256: str, installation: Installation, fully_qualified_name: str
    ) -> TareOwner:
        """From an installation and a node's fully qualified name ('/left/balance_calibrator')."""
        namespace, _, node = fully_qualified_name.rpartition('/')
        return cls(
            calibration_sha256, installation.spec, namespace or '/', node, installation.name
        )

    def to_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


def calibration_sha256(path: str | Path) -> str:
    """SHA-256 (hex) of the calibration file's bytes; '' when it cannot be read (never matches)."""
    try:
        return hashlib.sha256(Path(path).expanduser().read_bytes()).hexdigest()
    except OSError:
        return ''


def restore_refusal(saved: TareOwner | None, current: TareOwner) -> str:
    """'' when a zero and tare taken for `saved` belong to `current`, else why not (';
    '-joined).
    """
    if saved is None:
        return (
            'the file records no calibration, installation, namespace or node (an older tare file)'
        )
    reasons = []
    if not saved.calibration_sha256 or saved.calibration_sha256 != current.calibration_sha256:
        reasons.append(
            f'taken with another calibration (file content sha256 '
            f'{saved.calibration_sha256[:12] or "unknown"}, '
            f'now {current.calibration_sha256[:12] or "unknown"})'
        )
    if saved.installation != current.installation:
        was = saved.installation_name or saved.installation
        now = current.installation_name or current.installation
        reasons.append(
            f'taken in the {was} installation ({saved.installation}), '
            f'now {now} ({current.installation})'
        )
    if saved.namespace != current.namespace or saved.node != current.node:
        reasons.append(f'taken by node {_qualified(saved)}, this is {_qualified(current)}')
    return '; '.join(reasons)


def _qualified(owner: TareOwner) -> str:
    return owner.namespace.rstrip('/') + '/' + owner.node


@dataclass(frozen=True)
class TareState:
    balance: str
    zero_mv: np.ndarray | None = None  # (6,) FXV..MZV
    zero_temperature_c: float | None = None
    zero_direction: np.ndarray | None = None  # (6,) +-1
    zero_taken_at: str = ''
    tare_load: np.ndarray | None = None  # (6,) FX..MZ, balance axes, N / N·m
    tare_taken_at: str = ''
    tare_sigma: np.ndarray | None = None  # (6,) standard uncertainty of the tare load, N / N·m
    # what the tare load was read from: mean raw outputs (6,) mV before the zero, the temperature
    # and the load direction (6,) +-1 then (None: not recorded, a 'tare 2' file)
    tare_outputs_mv: np.ndarray | None = None
    tare_temperature_c: float | None = None
    tare_direction: np.ndarray | None = None
    owner: TareOwner | None = None  # what they were taken for (None: not recorded)

    def to_dict(self) -> dict[str, Any]:
        def plain(values: np.ndarray | None, names: Sequence[str]) -> dict[str, float] | None:
            return None if values is None else {n: float(v) for n, v in zip(names, values)}

        return {
            'format': FORMAT,
            'balance': self.balance,
            'zero_mv': plain(self.zero_mv, BRIDGE_OUTPUTS),
            'zero_temperature_c': self.zero_temperature_c,
            'zero_direction': plain(self.zero_direction, COMPONENTS),
            'zero_taken_at': self.zero_taken_at,
            'tare_load_balance_axes': plain(self.tare_load, COMPONENTS),
            'tare_taken_at': self.tare_taken_at,
            'tare_sigma_balance_axes': plain(self.tare_sigma, COMPONENTS),
            'tare_outputs_mv': plain(self.tare_outputs_mv, BRIDGE_OUTPUTS),
            'tare_temperature_c': self.tare_temperature_c,
            'tare_direction': plain(self.tare_direction, COMPONENTS),
            'taken_for': None if self.owner is None else self.owner.to_dict(),
        }


def now_iso() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec='seconds')


def tare_file_for(
    calibration_source: str, node_name: str, calibration_is_config: bool
) -> Path | None:
    """Beside the calibration: calibration.yaml -> calibration.tare.yaml (another node name or
    namespace gets its own file). None for a shipped balance config: nothing is written into the
    package, and no hidden state in a home directory changes what a fresh node reads (set
    `tare_file` instead).
    """
    if calibration_is_config:
        return None
    suffix = (
        ''
        if node_name in ('', '/balance_calibrator')
        else '.' + node_name.strip('/').replace('/', '.')
    )
    source = Path(calibration_source)
    return source.with_name(f'{source.stem}{suffix}.tare.yaml')


def save_tare(path: Path, state: TareState) -> None:
    write_text_atomically(
        path,
        '# zero and tare of a balance_calibrator; written by the node\n'
        + yaml.safe_dump(state.to_dict(), sort_keys=False),
    )


def load_tare(path: Path, balance: str) -> TareState | None:
    """The persisted state, None if there is no file; ValueError naming the file if it is
    unusable.
    """
    try:
        info = os.stat(path)
    except FileNotFoundError:
        return None
    except OSError as err:
        raise ValueError(f'{path}: cannot read tare file: {err.strerror}') from None
    if not stat.S_ISREG(info.st_mode) or info.st_size > MAX_BYTES:
        raise ValueError(
            f'{path}: not a tare file (not a regular file of at most {MAX_BYTES} bytes)'
        )
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as err:
        raise ValueError(f'{path}: unreadable tare file: {str(err).splitlines()[0]}') from None
    if not isinstance(data, dict) or data.get('format') not in (FORMAT, *OLDER_FORMATS):
        raise ValueError(f'{path}: not a tare file (format is not {FORMAT!r})')
    if str(data.get('balance', '')).lower() != balance.lower():
        raise ValueError(f'{path}: tare of balance {data.get("balance")!r}, not of {balance!r}')

    def vector(key: str, names: Sequence[str]) -> np.ndarray | None:
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

    def number(key: str) -> float | None:
        value = data.get(key)
        if value is None:
            return None
        try:
            result = float(value)
        except (TypeError, ValueError):
            raise ValueError(f'{path}: {key} needs a number, not {value!r}') from None
        if not np.isfinite(result):
            raise ValueError(f'{path}: {key} is a NaN or infinite value')
        return result

    return TareState(
        balance,
        vector('zero_mv', BRIDGE_OUTPUTS),
        number('zero_temperature_c'),
        vector('zero_direction', COMPONENTS),
        str(data.get('zero_taken_at') or ''),
        vector('tare_load_balance_axes', COMPONENTS),
        str(data.get('tare_taken_at') or ''),
        vector('tare_sigma_balance_axes', COMPONENTS),
        vector('tare_outputs_mv', BRIDGE_OUTPUTS),
        number('tare_temperature_c'),
        vector('tare_direction', COMPONENTS),
        _owner(path, data.get('taken_for')),
    )


def _owner(path: Path, recorded: object) -> TareOwner | None:
    """`taken_for` of a tare file; None when absent (a file of the first format)."""
    if recorded is None:
        return None
    names = [f.name for f in fields(TareOwner)]
    if not isinstance(recorded, dict) or not all(
        isinstance(recorded.get(n, ''), str) for n in names
    ):
        raise ValueError(f'{path}: taken_for needs the strings {", ".join(names)}')
    return TareOwner(**{n: recorded.get(n, '') for n in names})
