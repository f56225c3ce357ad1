"""Calibration accuracy, TM-663 §9: residuals (eqs. (38)-(43)) and σ (eqs. (44)-(49)) in % FS."""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from ..units import COMPONENTS


def residuals_pct_fs(loads_measured, loads_fitted, full_scale) -> np.ndarray:
    """(exp - th) / F.S. x 100 for every point and component, eqs. (38)-(43). Shape (N, 6)."""
    return (np.asarray(loads_measured, float) - np.asarray(loads_fitted, float)) / np.asarray(full_scale, float) * 100.0


def sigma_pct_fs(residual_loads, full_scale) -> np.ndarray:
    """sqrt(mean(residual²)) / F.S. x 100 per component, eqs. (44)-(49).

    residual_loads (N, n_components) in N / N·m. The memo divides by N_max, not N - p.
    """
    residual_loads = np.atleast_2d(np.asarray(residual_loads, dtype=float))
    return np.sqrt(np.mean(residual_loads ** 2, axis=0)) / np.asarray(full_scale, float) * 100.0


def sigma_by_component(residual_loads, full_scale, components: Sequence[str] = COMPONENTS) -> dict[str, float]:
    return {c: float(s) for c, s in zip(components, sigma_pct_fs(residual_loads, full_scale))}


def format_sigma_table(rows: Mapping[str, Mapping[str, float]], components: Sequence[str] = COMPONENTS,
                       digits: int = 3) -> str:
    """Table 17 layout: one row per label (e.g. 'LMC6522/linear'), σ in % FS per component."""
    width = max([len(label) for label in rows] + [12])
    header = f'{"":{width}}  ' + '  '.join(f'{"σ" + c + " (%)":>9}' for c in components)
    lines = [header]
    for label, values in rows.items():
        cells = []
        for c in components:
            value = values.get(c)
            cells.append(f'{value:9.{digits}f}' if value is not None else f'{"":9}')
        lines.append(f'{label:{width}}  ' + '  '.join(cells))
    return '\n'.join(lines)
