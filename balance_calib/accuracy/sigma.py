"""Calibration accuracy, TM-663 §9: residuals (eqs. (38)-(43)) and σ (eqs. (44)-(49)) in % FS."""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..array_types import FloatArray
from ..units import COMPONENTS


def residuals_pct_fs(
    loads_measured: ArrayLike, loads_fitted: ArrayLike, full_scale: ArrayLike
) -> FloatArray:
    """(exp - th) / F.S. x 100 for every point and component, eqs. (38)-(43). Shape (N, 6)."""
    return (
        (np.asarray(loads_measured, np.float64) - np.asarray(loads_fitted, np.float64))
        / np.asarray(full_scale, np.float64)
        * 100.0
    )


def sigma_pct_fs(residual_loads: ArrayLike, full_scale: ArrayLike) -> FloatArray | float:
    """The memo's σ, TM-663 eqs. (44)-(49): sqrt(Σ residual² / N_max) / F.S. x 100.

    The root mean square of the residuals about zero, divided by the number of points N_max
    (not N - 1, not N - p); compare `sample_std_pct_fs`.

    Parameters
    ----------
    residual_loads : array_like, shape (N, n_components) or (N,)
        exp - th per point and component, N or N·m.
    full_scale : array_like, shape (n_components,) or scalar
        Full scale (capacity) of each component, in the residuals' units.

    Returns
    -------
    ndarray, shape (n_components,), or float for a 1-D residual
        σ in % of full scale.
    """
    residual_loads = np.asarray(residual_loads, dtype=float)
    sigma = np.sqrt(np.mean(residual_loads**2, axis=0)) / np.asarray(full_scale, float) * 100.0
    return float(sigma) if residual_loads.ndim == 1 else sigma


def sample_std_pct_fs(residual_loads: ArrayLike, full_scale: ArrayLike) -> FloatArray:
    """Sample standard deviation of the residuals in % of full scale (about their mean, N - 1).

    What a table calibration's report.json calls σ (interfaces.md, "Calibration data tables");
    not the memo's σ of eq. (44) (`sigma_pct_fs`: about zero, divided by N_max).

    Parameters
    ----------
    residual_loads : array_like, shape (N, n_components)
        applied - predicted per point and component, N or N·m (N ≥ 2).
    full_scale : array_like, shape (n_components,)
        Capacity of each component, in the residuals' units.

    Returns
    -------
    ndarray, shape (n_components,)
    """
    std: FloatArray = np.std(np.asarray(residual_loads, np.float64), axis=0, ddof=1)
    return std / np.asarray(full_scale, np.float64) * 100.0


def sigma_by_component(
    residual_loads: ArrayLike, full_scale: ArrayLike, components: Sequence[str] = COMPONENTS
) -> dict[str, float]:
    return {
        c: float(s)
        for c, s in zip(components, np.atleast_1d(sigma_pct_fs(residual_loads, full_scale)))
    }


def format_sigma_table(
    rows: Mapping[str, Mapping[str, float]],
    components: Sequence[str] = COMPONENTS,
    digits: int = 3,
) -> str:
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
