"""The figure of a run's coverage: predicted u (k = 1) of each component along the run, % FS, with
the calibration's σ and the samples outside the schedule's support marked (PNG, Agg canvas).
"""

from __future__ import annotations

from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
import numpy as np

from .run import RunCoverage


def coverage_figure(
    coverage: RunCoverage, path: str | Path, time_s: np.ndarray | None = None
) -> Path:
    """Six panels, u in % FS against the sample (or time) along the run."""
    n = len(coverage.components)
    x = np.arange(len(coverage.loads)) if time_s is None else np.asarray(time_s, float)
    u = coverage.uncertainty_pct_fs
    figure = Figure(figsize=(9.0, 1.7 * n + 0.8))
    axes_list = figure.subplots(n, 1, sharex=True)
    for k, (axes, component) in enumerate(zip(np.atleast_1d(axes_list), coverage.components)):
        axes.plot(x, u[:, k], color='C0', linewidth=0.9, label='predicted u')
        if coverage.outside is not None and coverage.outside[:, k].any():
            out = coverage.outside[:, k]
            axes.plot(
                x[out],
                u[out, k],
                linestyle='none',
                marker='.',
                markersize=3,
                color='C3',
                label=f"outside the schedule's support ({100 * out.mean():.0f} %)",
            )
        sigma = coverage.sigma_pct_fs.get(component)
        if sigma is not None:
            axes.axhline(
                float(sigma),
                color='0.3',
                linestyle='--',
                linewidth=0.8,
                label=f'σ {float(sigma):.3g}',
            )
        axes.set_ylabel(f'{component}\n% FS')
        axes.set_ylim(bottom=0.0)
        axes.legend(loc='upper right', fontsize=7, frameon=False)
    np.atleast_1d(axes_list)[-1].set_xlabel('time, s' if time_s is not None else 'load of the run')
    figure.suptitle(
        f'Predicted standard uncertainty (k = 1) along the run, model {coverage.model_name}',
        fontsize=10,
    )
    figure.tight_layout()
    path = Path(path)
    FigureCanvasAgg(figure)
    figure.savefig(path, dpi=100)
    return path
