"""Balance description files (config/lmc6522.yaml, config/b660h.yaml, ...) as typed objects, SI."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import yaml

from .array_types import FloatArray
from .errors import ConfigError as ConfigError  # re-exported: readers import it from here
from .model.balance_model import BalanceModel
from .units import BRIDGE_OUTPUTS, COMPONENTS, STANDARD_GRAVITY_M_S2

CONFIG_DIR = Path(__file__).resolve().parent.parent / 'config'


@dataclass(frozen=True)
class CalibrationBody:
    """The calibration body (キャリボディ) and its loading jig, TM-663 §6-7."""

    weight_n: float
    cg_m: tuple[float, float, float]  # centre of gravity from the balance centre, balance axes
    axial_jig_weight_n: float = 0.0


@dataclass(frozen=True)
class LoadSchedule:
    """The load instruction sheet (Appendix A / B): one row per executed point, SI."""

    point: np.ndarray  # (N,) point numbers as printed
    orientation: np.ndarray  # (N,) I_g
    loads: np.ndarray  # (N, 6) N and N·m, balance axes, excluding the body's weight
    byproduct: tuple[str, ...]  # columns printed in parentheses, per row ('' if none)

    def __len__(self) -> int:
        return len(self.point)

    @property
    def is_zero_point(self) -> np.ndarray:
        zero_point: np.ndarray = np.all(self.loads == 0.0, axis=1)
        return zero_point


@dataclass(frozen=True)
class BalanceConfig:
    name: str
    components: tuple[str, ...]
    bridge_outputs: tuple[str, ...]
    capacity: np.ndarray  # full scale per component (N, N·m), σ is in % of it
    rated_output_mv: np.ndarray  # per bridge output
    calibration_body: CalibrationBody
    gravity_directions: Mapping[int, np.ndarray]  # I_g -> unit vector in balance axes
    matrices: Mapping[str, BalanceModel]  # 'linear', 'quadratic', 'cubic' (Tables 10-16)
    schedule: LoadSchedule | None
    table17_sigma_pct_fs: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    raw: Mapping[str, Any] = field(default_factory=dict, repr=False)
    path: Path | None = None

    @property
    def serial(self) -> str | None:
        """The balance's serial number (optional key `serial`), None when the config has none."""
        value = (self.raw or {}).get('serial')
        return None if value is None or str(value).strip() == '' else str(value).strip()

    @property
    def rated_outputs_by_name(self) -> dict[str, float]:
        return dict(zip(self.bridge_outputs, self.rated_output_mv.tolist()))

    def gravity(self, orientation: int) -> np.ndarray:
        try:
            return self.gravity_directions[int(orientation)]
        except KeyError:
            raise ConfigError(
                f'{self.path or self.name}: no gravity direction for I_g = {orientation}'
            ) from None


def shipped_config_dirs() -> list[Path]:
    """Where the shipped configs are: the source tree's config/ and, installed with colcon (the
    package in site-packages, no config/ beside it), share/balance_calib/config.
    """
    dirs = [CONFIG_DIR]
    try:
        from ament_index_python.packages import get_package_share_directory

        dirs.append(Path(get_package_share_directory('balance_calib')) / 'config')
    except Exception:  # not installed as a ROS package (or ament_index not importable)
        pass
    return dirs


def resolve_config_path(name_or_path: str | Path) -> Path:
    """A path, or the name of a shipped config ('lmc6522', 'b660h', 'thrust_stand')."""
    path = Path(name_or_path)
    if path.exists():
        return path
    dirs = shipped_config_dirs()
    for directory in dirs:
        for name in dict.fromkeys((f'{name_or_path}.yaml', f'{str(name_or_path).lower()}.yaml')):
            if (directory / name).exists():
                return directory / name
    raise ConfigError(
        f'balance config {name_or_path!r} not found (looked for the file and in '
        f'{", ".join(map(str, dirs))})'
    )


def load_balance_config(name_or_path: str | Path) -> BalanceConfig:
    path = resolve_config_path(name_or_path)
    try:
        # libyaml's safe loader when built in: 20x faster on the schedules (same result)
        data = yaml.load(path.read_text(), Loader=getattr(yaml, 'CSafeLoader', yaml.SafeLoader))
    except (OSError, yaml.YAMLError) as err:
        raise ConfigError(f'{path}: cannot read balance config: {err}') from None
    if not isinstance(data, dict):
        raise ConfigError(f'{path}: not a balance config (expected a mapping at the top level)')
    return balance_config_from_dict(data, path)


def _vector(data: Mapping[str, Any], names: Sequence[str], where: str) -> FloatArray:
    try:
        return np.array([float(data[n]) for n in names])
    except KeyError as err:
        raise ConfigError(f'{where}: missing {err.args[0]}') from None
    except (TypeError, ValueError) as err:
        raise ConfigError(f'{where}: {err}') from None


def balance_config_from_dict(data: Mapping[str, Any], path: Path | None = None) -> BalanceConfig:
    where = str(path or 'balance config')
    try:
        components = tuple(data.get('components', COMPONENTS))
        outputs = tuple(data.get('bridge_outputs', BRIDGE_OUTPUTS))
        capacity = _vector(data['capacity'], components, f'{where}: capacity')
        rated = _vector(data['rated_output_mv'], outputs, f'{where}: rated_output_mv')
        body_data = data.get('calibration_body') or {}
        body = CalibrationBody(
            weight_n=float(body_data.get('weight_n', 0.0)),
            cg_m=(
                float(body_data.get('cg_x_m', 0.0)),
                float(body_data.get('cg_y_m', 0.0)),
                float(body_data.get('cg_z_m', 0.0)),
            ),
            axial_jig_weight_n=float(body_data.get('axial_jig_weight_n', 0.0)),
        )
        gravity = {
            int(k): np.asarray(v, dtype=float)
            for k, v in (data.get('gravity_directions') or {}).items()
        }
        matrices = {
            order: BalanceModel.from_dict(
                {'name': order, 'components': components, 'inputs': outputs, **m},
                where=f'{where}: matrices.{order}',
            )
            for order, m in (data.get('matrices') or {}).items()
        }
        serial = data.get('serial')
        if serial is not None and not isinstance(serial, (str, int)):
            raise ConfigError(
                f'{where}: serial: expected a text or a number, not {type(serial).__name__}'
            )
        schedule = None
        if data.get('schedule'):
            schedule = _schedule(
                data['schedule'],
                components,
                float(data.get('units', {}).get('kgf_to_n', STANDARD_GRAVITY_M_S2)),
                where,
            )
    except KeyError as err:
        raise ConfigError(f'{where}: missing key {err.args[0]!r}') from None
    except (TypeError, ValueError) as err:
        if isinstance(err, ConfigError):
            raise
        raise ConfigError(f'{where}: {err}') from None
    return BalanceConfig(
        str(data.get('balance', 'balance')),
        components,
        outputs,
        capacity,
        rated,
        body,
        gravity,
        matrices,
        schedule,
        data.get('table17_sigma_pct_fs', {}) or {},
        data,
        path,
    )


def _schedule(
    data: Mapping[str, Any], components: Sequence[str], kgf_to_n: float, where: str
) -> LoadSchedule:
    columns = list(data['columns'])
    rows = data['rows']
    load_cols = columns[2 : 2 + len(components)]
    units = np.array([kgf_to_n if c.endswith(('_kgf', '_kgfm')) else 1.0 for c in load_cols])
    point = np.array([int(r[0]) for r in rows])
    orientation = np.array([int(r[1]) for r in rows])
    loads = np.array([[float(x) for x in r[2 : 2 + len(components)]] for r in rows]) * units
    byproduct = tuple(
        str(r[2 + len(components)]) if len(r) > 2 + len(components) else '' for r in rows
    )
    return LoadSchedule(point, orientation, loads, byproduct)
