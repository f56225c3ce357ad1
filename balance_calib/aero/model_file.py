"""config/models/NAME.yaml: the wind-tunnel model as the data reduction needs it (interfaces.md).

Lengths in m, weight in N, deflection in rad per N and rad per N·m. `weight_n` and
`centre_of_gravity_m` are numbers, or `estimate` (from the run's wind-off attitude sweep).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import yaml

from ..config import CONFIG_DIR, ConfigError, shipped_config_dirs
from .deflection import Deflection

MODELS_DIR = CONFIG_DIR / 'models'
ESTIMATE = 'estimate'


@dataclass(frozen=True)
class ModelDescription:
    name: str
    reference_area_m2: float  # S
    reference_chord_m: float  # c, for C_m
    reference_span_m: float  # b, for C_l and C_n
    # (3,) body axes (x forward, y starboard, z down) from the balance centre
    moment_reference_centre_m: np.ndarray
    weight_n: float | None  # None: estimate from the wind-off sweep
    # (3,) body axes from the balance centre; None: estimate
    centre_of_gravity_m: np.ndarray | None
    deflection: Deflection
    path: Path | None = None

    @property
    def weight_declared(self) -> bool:
        return self.weight_n is not None and self.centre_of_gravity_m is not None

    def with_estimated_weight(self) -> 'ModelDescription':
        return replace(self, weight_n=None, centre_of_gravity_m=None)

    @property
    def reference_lengths_m(self) -> np.ndarray:
        """(6,) the length dividing each load after q∞·S: 1 for forces, b, c, b for l, m, n."""
        b, c = self.reference_span_m, self.reference_chord_m
        return np.array([1.0, 1.0, 1.0, b, c, b])


def resolve_model_path(name_or_path: str | Path) -> Path:
    path = Path(name_or_path)
    if path.exists():
        return path
    dirs = [directory / 'models' for directory in shipped_config_dirs()]  # MODELS_DIR first
    for directory in dirs:
        if (directory / f'{name_or_path}.yaml').exists():
            return directory / f'{name_or_path}.yaml'
    shipped = ', '.join(sorted({p.stem for d in dirs for p in d.glob('*.yaml')})) or 'none'
    raise ConfigError(f'{name_or_path}: no such model file (shipped models: {shipped})')


def load_model(name_or_path: str | Path) -> ModelDescription:
    """Read a model file (a path, or the name of one in config/models). ConfigError names file
    and key.
    """
    path = resolve_model_path(name_or_path)
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as err:
        raise ConfigError(f'{path}: cannot read model file: {err.strerror or err}') from None
    except yaml.YAMLError as err:
        raise ConfigError(f'{path}: not valid YAML: {str(err).splitlines()[0]}') from None
    return model_from_dict(data, path)


def _positive(data: Mapping, key: str, where: str) -> float:
    value = _number(data, key, where)
    if value <= 0:
        raise ConfigError(f'{where}: {key} must be positive, not {value}')
    return value


def _number(data: Mapping, key: str, where: str, default=None) -> float:
    if key not in data:
        if default is not None:
            return default
        raise ConfigError(f'{where}: missing key {key!r}')
    try:
        value = float(data[key])
    except (TypeError, ValueError):
        raise ConfigError(f'{where}: {key} must be a number, not {data[key]!r}') from None
    if not np.isfinite(value):
        raise ConfigError(f'{where}: {key} must be finite, not {value}')
    return value


def _vector3(data: Mapping, key: str, where: str, allow_estimate: bool = False):
    value: Any = data.get(key)  # what the YAML holds: checked below
    if allow_estimate and value == ESTIMATE:
        return None
    try:
        vector = np.array([float(v) for v in value], dtype=float)
    except (TypeError, ValueError):
        vector = np.zeros(0)
    if vector.shape != (3,) or not np.all(np.isfinite(vector)):
        what = 'three numbers [x, y, z] in m' + (f' or {ESTIMATE}' if allow_estimate else '')
        raise ConfigError(f'{where}: {key} must be {what}, not {value!r}')
    return vector


def model_from_dict(data: Any, path: Path | None = None) -> ModelDescription:
    where = str(path) if path else 'model'
    if not isinstance(data, Mapping):
        raise ConfigError(f'{where}: not a model file (expected a mapping at the top level)')
    weight = data.get('weight_n')
    if weight == ESTIMATE:
        weight = None
    else:
        weight = _positive(data, 'weight_n', where)
    cg = _vector3(data, 'centre_of_gravity_m', where, allow_estimate=True)
    deflection_data = data.get('deflection') or {}
    if not isinstance(deflection_data, Mapping):
        raise ConfigError(f'{where}: deflection must be a mapping of coefficients')
    unknown = set(deflection_data) - set(Deflection.KEYS)
    if unknown:
        raise ConfigError(
            f'{where}: deflection.{sorted(unknown)[0]} is not a known coefficient '
            f'({", ".join(Deflection.KEYS)})'
        )
    deflection = Deflection(
        *(_number(deflection_data, k, f'{where}: deflection', 0.0) for k in Deflection.KEYS)
    )
    return ModelDescription(
        str(data.get('name') or (path.stem if path else 'model')),
        _positive(data, 'reference_area_m2', where),
        _positive(data, 'reference_chord_m', where),
        _positive(data, 'reference_span_m', where),
        _vector3(data, 'moment_reference_centre_m', where),
        weight,
        cg,
        deflection,
        path,
    )
