"""calibration.yaml: reading and writing the fitted calibration (model/calibration.py) that
`balance_calibrator` loads and `refit` writes.

A balance config (config/lmc6522.yaml) is accepted as a calibration too: its memo matrices
(Tables 10-16) become the linear, quadratic and cubic models, the cubic adopted.
Files are replaced atomically (write to a temporary file in the same directory, fsync, rename),
so a reader never sees half a calibration and a failed write leaves the old one in place.
"""

from __future__ import annotations

import datetime as _dt
import os
from pathlib import Path
import re
import stat
import tempfile
from typing import Any, Mapping

import numpy as np
import yaml

from .config import balance_config_from_dict, ConfigError
from .model.balance_model import BalanceModel
from .model.calibration import Calibration
from .units import BRIDGE_OUTPUTS, COMPONENTS

MAX_CALIBRATION_BYTES = 16 << 20
# What a calibration.yaml must say, each for a reason: a default would be a silent guess.
# adopted_model: the first model is not the adopted one (a file without the line used to run as
# 'linear'); capacity and rated_output_mv: the envelope, % FS and the bridges' range; models.
REQUIRED_KEYS = {
    'adopted_model': 'the model the calibration adopted, e.g. cubic',
    'capacity': 'the full scale per component, N and N·m',
    'rated_output_mv': 'the rated output per bridge, mV',
    'models': 'the fitted models',
}
TEMPERATURE_VARIABLES = ('dT', 'dT2')  # terms in the temperature's difference from the reference


def calibration_from_dict(data: Mapping[str, Any], where: str = 'calibration') -> Calibration:
    if not isinstance(data, Mapping):
        raise ConfigError(f'{where}: not a calibration file (expected a mapping at the top level)')
    if 'matrices' in data and 'models' not in data:  # a balance config with the memo's matrices
        config = balance_config_from_dict(data, Path(where))
        if not config.matrices:
            raise ConfigError(f'{where}: balance config has no matrices')
        adopted = 'cubic' if 'cubic' in config.matrices else list(config.matrices)[-1]
        return Calibration(
            config.name,
            dict(config.matrices),
            adopted,
            adopted,
            config.capacity,
            config.rated_output_mv,
            config.components,
            config.bridge_outputs,
            {k: float(v) for k, v in (config.table17_sigma_pct_fs.get(adopted) or {}).items()},
            '',
            None,
            {'source': 'memo matrices (TM-663 Tables 10-16)'},
        )
    _require_keys(data, where)
    try:
        components = tuple(data.get('components', COMPONENTS))
        outputs = tuple(data.get('bridge_outputs', BRIDGE_OUTPUTS))
        given = data['models'] or {}
        if not isinstance(given, Mapping):
            raise ConfigError(
                f'{where}: models: expected a mapping of model names, not {type(given).__name__}'
            )
        models = {}
        for name, m in given.items():
            if not isinstance(m, Mapping):
                raise ConfigError(
                    f'{where}: models.{name}: expected a mapping (form, terms, '
                    f'coefficients), not {type(m).__name__} {m!r:.40}'
                )
            models[name] = _model_from_dict(
                {'name': name, 'components': components, 'inputs': outputs, **m},
                where=f'{where}: models.{name}',
            )
        if not models:
            raise ConfigError(f'{where}: no models')
        capacity = _per_name(data, 'capacity', components, where)
        rated = _per_name(data, 'rated_output_mv', outputs, where)
        adopted = str(data['adopted_model'])
        if adopted not in models:
            raise ConfigError(
                f'{where}: adopted_model {adopted!r} is not among the models ({", ".join(models)})'
            )
        ref = data.get('reference_temperature_c')
        needs_reference = [
            n for n, m in models.items() if set(m.extra_variables) & set(TEMPERATURE_VARIABLES)
        ]
        if ref is None and needs_reference:
            raise ConfigError(
                f'{where}: missing key reference_temperature_c (model {needs_reference[0]} has '
                'terms in the temperature difference from it)'
            )
        return Calibration(
            str(data.get('balance', 'balance')),
            models,
            adopted,
            str(data.get('base_model', adopted)),
            capacity,
            rated,
            components,
            outputs,
            {str(k): float(v) for k, v in (data.get('sigma_pct_fs') or {}).items()},
            str(data.get('fitted_at', '')),
            None if ref is None else float(ref),
            {**dict(data.get('extra') or {}), **_channels_from_dict(data, where)},
        )
    except ConfigError:
        raise
    except KeyError as err:
        raise ConfigError(f'{where}: missing key {err.args[0]!r}') from None
    except (TypeError, ValueError, AttributeError) as err:
        text = ' '.join(str(err).split())  # the model's errors name the file already
        raise ConfigError(text if text.startswith(f'{where}: ') else f'{where}: {text}') from None


def _require_keys(data: Mapping[str, Any], where: str) -> None:
    """ConfigError naming every required key the file lacks (REQUIRED_KEYS), before any is used."""
    missing = [key for key in REQUIRED_KEYS if data.get(key) in (None, '')]
    if missing:
        raise ConfigError(
            f'{where}: missing key {missing[0]} ({REQUIRED_KEYS[missing[0]]})'
            + (f'; also missing: {", ".join(missing[1:])}' if missing[1:] else '')
            + '; a calibration file is written by refit or fit'
        )


def _per_name(data: Mapping[str, Any], key: str, names: tuple[str, ...], where: str) -> np.ndarray:
    """The mapping data[key] as an array in `names` order; ConfigError naming key.name missing."""
    given = data[key]
    if not isinstance(given, Mapping):
        raise ConfigError(f'{where}: {key}: expected a mapping of {", ".join(names)}')
    lacking = [n for n in names if n not in given]
    if lacking:
        raise ConfigError(f'{where}: {key}: missing key {lacking[0]} (needs {", ".join(names)})')
    return np.array([float(given[n]) for n in names])


def _channels_from_dict(data: Mapping[str, Any], where: str) -> dict:
    """calibration.yaml's `requires` (the extra channels the models read) and `channels` (each
    one's kind, unit and the reference its d<SYMBOL> is taken from), kept in Calibration.extra.
    """
    requires = data.get('requires')
    if requires is None:
        return {}
    channels = data.get('channels') or {}
    if not isinstance(requires, list) or not all(isinstance(r, str) for r in requires):
        raise ConfigError(f'{where}: requires: expected a list of channel symbols')
    if not isinstance(channels, Mapping) or set(requires) - set(channels):
        missing = sorted(set(requires) - set(channels or {}))
        raise ConfigError(f'{where}: channels: no reference for {", ".join(missing)}')
    return {'requires': list(requires), 'channels': {k: dict(v) for k, v in channels.items()}}


def _channel_keys_to_top(content: dict) -> dict:
    """The calibration's dict with `requires` and `channels` moved from `extra` to the top,
    beside the models that read them (interfaces.md, "Effects found in table calibrations").
    """
    extra = dict(content.get('extra') or {})
    if 'requires' not in extra:
        return content
    moved = {key: extra.pop(key) for key in ('requires', 'channels') if key in extra}
    result = {k: v for k, v in content.items() if k != 'extra'}
    if extra:
        result['extra'] = extra
    return {**result, **moved}


def _model_from_dict(data: Mapping[str, Any], where: str):
    """A direct (TM-663) model, or with `form: iterative` an AIAA R-091 model (outputs from loads,
    inverted per sample by Newton iteration; same `loads(outputs, extra)` interface).
    """
    if data.get('form', 'direct') == 'iterative':
        from .model.r091 import IterativeModel

        return IterativeModel.from_dict(data, where=where)
    return BalanceModel.from_dict(data, where=where)


def load_calibration(path: str | Path) -> Calibration:
    """Read calibration.yaml (or a balance config, also by name: 'lmc6522', 'thrust_stand').

    ConfigError names the file and the problem.
    """
    path = Path(path)
    if not path.exists() and path.suffix == '' and '/' not in str(path):
        from .config import resolve_config_path

        try:
            path = resolve_config_path(str(path))
        except ConfigError:
            pass
    try:
        info = os.stat(path)
        if not stat.S_ISREG(info.st_mode) or info.st_size > MAX_CALIBRATION_BYTES:
            # a FIFO would block the reader, /dev/zero never ends
            raise ConfigError(
                f'{path}: not a calibration file (not a regular file of at most '
                f'{MAX_CALIBRATION_BYTES >> 20} MB)'
            )
        text = path.read_text()
    except OSError as err:
        raise ConfigError(f'{path}: cannot read calibration file: {err.strerror or err}') from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise ConfigError(_yaml_error_line(path, err)) from None
    try:
        return calibration_from_dict(data, str(path))
    except ConfigError as err:
        raise ConfigError(_with_line_number(str(err), str(path), text)) from None


def _yaml_error_line(path: Path, err: yaml.YAMLError) -> str:
    """'FILE, line N: not valid YAML: what' from PyYAML's several-line message."""
    mark = getattr(err, 'problem_mark', None)
    problem = getattr(err, 'problem', None) or str(err).splitlines()[0]
    context = getattr(err, 'context', None)
    where = f'{path}, line {mark.line + 1}' if mark is not None else str(path)
    return f'{where}: not valid YAML: {problem}{f" ({context})" if context else ""}'


_KEY_PATH = re.compile(r'([A-Za-z_][\w+\-]*(?:\.[A-Za-z_0-9][\w+\-]*)*): ')
_QUOTED = re.compile(r"'([^']{1,80})'")


def _with_line_number(message: str, where: str, text: str) -> str:
    """'FILE, line N: key: what' for 'FILE: key: what': N is the line of the offending value when
    the message quotes it, else of the key.
    """
    rest = message[len(where) + 2 :] if message.startswith(f'{where}: ') else message
    key = _KEY_PATH.match(rest)
    line = _line_of_key(text, key.group(1).split('.')) if key else None
    if line is None or key is None:
        return f'{where}: {rest}'
    quoted = _QUOTED.search(rest[key.end() :])
    if quoted:
        lines = text.splitlines()
        line = next(
            (i + 1 for i in range(line - 1, len(lines)) if quoted.group(1) in lines[i]), line
        )
    return f'{where}, line {line}: {rest}'


def _line_of_key(text: str, keys: list[str]) -> int | None:
    """1-based line of the nested mapping key `keys` in a YAML text, None if not found."""
    try:
        node = yaml.compose(text, Loader=getattr(yaml, 'CSafeLoader', yaml.SafeLoader))
    except yaml.YAMLError:
        return None
    line = None
    for key in keys:
        if not isinstance(node, yaml.MappingNode):
            return line
        # the last of repeated keys: the one the loader keeps
        match = next(
            ((k, v) for k, v in reversed(node.value) if getattr(k, 'value', None) == key), None
        )
        if match is None:
            return line
        line, node = match[0].start_mark.line + 1, match[1]
    return line


def write_text_atomically(path: str | Path, text: str, mode: int = 0o644) -> None:
    """Write a file so that readers see the old or the new content, never a mix; `mode` 0644
    (as refit's outputs, whichever command writes the file).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', suffix='.tmp', dir=path.parent)
    try:
        os.fchmod(fd, mode)  # mkstemp makes 0600; a calibration is read by other users' nodes
        with os.fdopen(fd, 'w') as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def save_calibration(path: str | Path, calibration: Calibration) -> None:
    header = (
        f'# {calibration.balance} calibration written by balance_calib; loads in N, N·m from '
        f'outputs in {calibration.output_unit}.\n'
    )
    data = _channel_keys_to_top(calibration.to_dict())
    # libyaml's safe dumper when built in (4-5x faster on a campaign's calibration) where it writes
    # the same text: it wraps a long double-quoted string (one with a character beyond printable
    # ASCII, e.g. a σ) without the pure-Python emitter's escaped line end
    c_dumper = getattr(yaml, 'CSafeDumper', None)
    dumper = c_dumper if c_dumper is not None and _printable_ascii(data) else yaml.SafeDumper
    write_text_atomically(
        path, header + yaml.dump(data, Dumper=dumper, sort_keys=False, width=160)
    )


def _printable_ascii(data: Any) -> bool:
    """True when every text (key or value) in data's dicts and lists is printable ASCII."""
    if isinstance(data, str):
        return data.isascii() and data.isprintable()
    if isinstance(data, dict):
        return all(_printable_ascii(k) and _printable_ascii(v) for k, v in data.items())
    if isinstance(data, (list, tuple)):
        return all(_printable_ascii(v) for v in data)
    return True


def now_iso() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec='seconds')
