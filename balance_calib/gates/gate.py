"""The Gate value every acceptance gate returns, the order refusals are named in, and the one
report function: report.json's `acceptance` entry of a refit and the `gates`/`forced` keys of a
table calibration's report (interfaces.md, report.json: one entry per gate, `name`, `passed`,
`reason` and the gate's details).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np


@dataclass(frozen=True)
class Gate:
    name: str
    passed: bool
    reason: str  # one line
    details: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class ModelResiduals:
    """The model the σ and outlier gates judge: its σ (% FS) per component, its residuals and
    leave-one-out residuals (P, k) in N, N·m, and its name in the gates' lines.
    """

    sigma_pct_fs: Mapping[str, float]
    residuals: np.ndarray
    press: np.ndarray
    what: str = 'base model'


def failed(gates: Sequence[Gate]) -> list[Gate]:
    return [g for g in gates if not g.passed]


def gates_report(gates: Sequence[Gate], *, forced: bool) -> dict:
    """report.json's `acceptance` entry."""
    return {
        'passed': not failed(gates),
        'forced': bool(forced and failed(gates)),
        'gates': [
            {'name': g.name, 'passed': g.passed, 'reason': g.reason, **_plain(g.details)}
            for g in gates
        ],
    }


def _plain(value):
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, (np.floating, float)):
        return round(float(value), 6) if np.isfinite(value) else None
    if isinstance(value, (np.integer,)):
        return int(value)
    return value


# the order a refusal names failed gates in, the most specific cause first: a unit error also
# spoils σ, not the other way round (a bag calibration's gates, then a table calibration's)
BAG_PRIORITY = (
    'marker_order',
    'clipping',
    'output_range',
    'sensitivity',
    'active_calibration',
    'capacity',
    'body_weight',
    'zero_points',
    'schedule',
    'outliers',
    'sigma',
)
TABLE_PRIORITY = ('channels', 'sensitivity', 'outliers', 'overfit', 'condition')


def refusal(
    where: str, gates: Sequence[Gate], priority: Sequence[str], names_others: bool
) -> str | None:
    """The one line refusing a calibration for its failed `gates` (None when all passed): the
    source, the first failure by `priority` and its reason, and with names_others the other
    failed gates.
    """
    bad = _by_priority(gates, priority)
    if not bad:
        return None
    also = (
        f' (also failed: {", ".join(g.name for g in bad[1:])})'
        if names_others and len(bad) > 1
        else ''
    )
    return (
        f'{where}: refused by acceptance gate {bad[0].name}: {bad[0].reason}{also}; '
        'nothing written (--force writes it anyway)'
    )


def _by_priority(gates: Sequence[Gate], priority: Sequence[str]) -> list[Gate]:
    """The failed gates, those `priority` names first in its order (a stable sort)."""
    return sorted(
        failed(gates),
        key=lambda g: priority.index(g.name) if g.name in priority else len(priority),
    )
