"""Figures of check loads (error against limit per component) and of two calibrations compared
(difference against its uncertainty per component): PNG, Agg canvas, the style of
coverage/plots.py.
"""

from __future__ import annotations

from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
import numpy as np


def _panels(n: int):
    figure = Figure(figsize=(9.0, 1.7 * n + 0.8))
    return figure, np.atleast_1d(figure.subplots(n, 1, sharex=True))


def _save(figure: Figure, path: str | Path) -> Path:
    figure.tight_layout()
    path = Path(path)
    FigureCanvasAgg(figure)
    figure.savefig(path, dpi=100)
    return path


def check_figure(result, path: str | Path) -> Path:
    """Per component: each check point's error (% FS) and its limit ±k·u; failures in red,
    points outside the calibrated range hollow.
    """
    readings = result.readings
    error = readings.error / readings.capacity * 100.0
    limit = result.k * readings.uncertainty / readings.capacity * 100.0
    x = np.arange(1, len(error) + 1)
    figure, axes_list = _panels(len(readings.components))
    for j, (axes, component) in enumerate(zip(axes_list, readings.components)):
        axes.fill_between(
            x,
            -limit[:, j],
            limit[:, j],
            step='mid',
            color='C0',
            alpha=0.2,
            label=f'±{result.k:g}·u',
        )
        inside = ~readings.outside[:, j]
        for mask, face, label in (
            (inside & ~result.failed[:, j], 'C0', 'pass'),
            (inside & result.failed[:, j], 'C3', 'fail'),
            (~inside, 'none', 'outside the calibrated range'),
        ):
            if mask.any():
                axes.plot(
                    x[mask],
                    error[mask, j],
                    linestyle='none',
                    marker='o',
                    markersize=3,
                    markerfacecolor=face,
                    markeredgecolor='C3' if face == 'C3' else 'C0',
                    label=label,
                )
        axes.axhline(0.0, color='0.3', linewidth=0.6)
        axes.set_ylabel(f'{component} error\n% FS')
        axes.legend(loc='upper right', fontsize=7, frameon=False)
    axes_list[-1].set_xlabel('check point (in order)')
    figure.suptitle(
        f'Check loads: error of each reading against its limit, verdict {result.verdict}',
        fontsize=10,
    )
    return _save(figure, path)


def compare_figure(comparison, path: str | Path) -> Path:
    """Per component: B − A (% FS) at each compared load, with ±2·√(u_A² + u_B²)."""
    difference = comparison.difference_pct_fs
    band = 2.0 * comparison.combined_u_pct_fs
    x = np.arange(1, len(difference) + 1)
    figure, axes_list = _panels(len(comparison.components))
    changed = comparison.changed
    for j, (axes, component) in enumerate(zip(axes_list, comparison.components)):
        axes.fill_between(
            x,
            -band[:, j],
            band[:, j],
            step='mid',
            color='0.6',
            alpha=0.3,
            label='±2·√(u_A² + u_B²)',
        )
        axes.plot(
            x,
            difference[:, j],
            linestyle='none',
            marker='.',
            markersize=3,
            color='C3' if component in changed else 'C0',
            label='B − A' + (' (changed)' if component in changed else ''),
        )
        axes.axhline(0.0, color='0.3', linewidth=0.6)
        axes.set_ylabel(f'{component}\n% FS')
        axes.legend(loc='upper right', fontsize=7, frameon=False)
    axes_list[-1].set_xlabel('compared load (in order)')
    figure.suptitle('Two calibrations of one balance: difference of the readings', fontsize=10)
    return _save(figure, path)
