"""The acceptance limits of the gates: the balance config's `acceptance:` mapping over defaults.

interfaces.md (balance config, `acceptance:`): σ per component (default 0.25 % FS, or 3x the
memo's Table 17 σ of the base model, TM-663 Table 17, where larger), the outlier rule's k robust σ
and floor, the sensitivity tolerances, the body weight, capacity, zero-point and schedule limits.
A key the mapping does not know, or a value that is not a positive number, is a ConfigError
naming it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ..config import BalanceConfig, ConfigError

DEFAULT_SIGMA_LIMIT_PCT_FS = 0.25  # per component, or 3x the memo's Table 17 σ if larger
DEFAULT_OUTLIER_ROBUST_SIGMAS = 7.0  # leave-one-out residual / (1.4826 MAD)
DEFAULT_OUTLIER_FLOOR_PCT_FS = 0.05  # and at least this far off
DEFAULT_SENSITIVITY_NOMINAL_TOLERANCE = 0.15
DEFAULT_SENSITIVITY_ACTIVE_TOLERANCE = 0.05
DEFAULT_BODY_WEIGHT_TOLERANCE = 0.10
DEFAULT_CAPACITY_MARGIN = 0.05
DEFAULT_ZERO_SHIFT_PCT_FS = 2.0  # between consecutive zero points of one block
DEFAULT_MISSING_POINTS_SHARE = 0.10  # of the schedule's points, at most
DEFAULT_MISSING_COMPONENT_SHARE = 0.20  # of the scheduled points loading one component, at most


@dataclass(frozen=True)
class AcceptanceLimits:
    sigma_limit_pct_fs: Mapping[str, float]
    outlier_robust_sigmas: float = DEFAULT_OUTLIER_ROBUST_SIGMAS
    outlier_floor_pct_fs: float = DEFAULT_OUTLIER_FLOOR_PCT_FS
    sensitivity_nominal_tolerance: float = DEFAULT_SENSITIVITY_NOMINAL_TOLERANCE
    sensitivity_active_tolerance: float = DEFAULT_SENSITIVITY_ACTIVE_TOLERANCE
    body_weight_tolerance: float = DEFAULT_BODY_WEIGHT_TOLERANCE
    capacity_margin: float = DEFAULT_CAPACITY_MARGIN
    zero_shift_pct_fs: float = DEFAULT_ZERO_SHIFT_PCT_FS
    missing_points_share: float = DEFAULT_MISSING_POINTS_SHARE
    missing_component_share: float = DEFAULT_MISSING_COMPONENT_SHARE


def acceptance_limits(config: BalanceConfig, base_model: str = 'cubic') -> AcceptanceLimits:
    """The config's `acceptance:` limits over the defaults; ConfigError naming a bad key."""
    where = f'{config.path or config.name}: acceptance'
    data = config.raw.get('acceptance') or {}
    if not isinstance(data, Mapping):
        raise ConfigError(f'{where}: expected a mapping')
    memo = config.table17_sigma_pct_fs.get(base_model, {}) if config.table17_sigma_pct_fs else {}
    sigma = {
        c: max(DEFAULT_SIGMA_LIMIT_PCT_FS, 3.0 * float(memo.get(c, 0.0)))
        for c in config.components
    }
    given = data.get('sigma_limit_pct_fs', {})
    if isinstance(given, (int, float)):
        given = dict.fromkeys(config.components, given)
    if not isinstance(given, Mapping):
        raise ConfigError(
            f'{where}.sigma_limit_pct_fs: expected a number or a mapping per component'
        )
    for component, value in given.items():
        if component not in config.components:
            raise ConfigError(f'{where}.sigma_limit_pct_fs: unknown component {component!r}')
        sigma[component] = _positive(value, f'{where}.sigma_limit_pct_fs.{component}')
    numbers = {}
    for key in (
        'outlier_robust_sigmas',
        'outlier_floor_pct_fs',
        'sensitivity_nominal_tolerance',
        'sensitivity_active_tolerance',
        'body_weight_tolerance',
        'capacity_margin',
        'zero_shift_pct_fs',
        'missing_points_share',
        'missing_component_share',
    ):
        if key in data:
            numbers[key] = _positive(data[key], f'{where}.{key}')
    unknown = set(data) - {'sigma_limit_pct_fs', *AcceptanceLimits.__dataclass_fields__}
    if unknown:
        raise ConfigError(f'{where}: unknown key(s) {", ".join(sorted(unknown))}')
    return AcceptanceLimits(sigma, **numbers)


def _positive(value, where: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f'{where}: {value!r} is not a number') from None
    if not np.isfinite(number) or number <= 0:
        raise ConfigError(f'{where}: must be a positive finite number, not {value!r}')
    return number
