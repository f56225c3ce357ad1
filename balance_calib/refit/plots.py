"""Residual plots in the style of TM-663 Figs. 4-9: residual (% FS, eqs. (38)-(43)) against point
number, six panels per model, residuals beyond ±0.5 % drawn at ±0.5 % as the memo does."""
from __future__ import annotations

from pathlib import Path

import numpy as np

CLIP_PCT = 0.5


def residual_panels(residuals_pct: np.ndarray, labels, components, title: str, path: Path,
                    after_pct: np.ndarray | None = None) -> Path:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 2, figsize=(11, 8.5), sharex=True)
    for k, (ax, component) in enumerate(zip(axes.T.reshape(-1), components)):
        series = [('before' if after_pct is not None else None, residuals_pct[:, k], 'tab:blue')]
        if after_pct is not None:
            series.append(('after', after_pct[:, k], 'tab:red'))
        for name, values, colour in series:
            clipped = np.clip(values, -CLIP_PCT, CLIP_PCT)
            sigma = float(np.sqrt(np.mean(values ** 2)))
            ax.plot(labels, clipped, '.', ms=3, color=colour,
                    label=f'{name + ": " if name else ""}σ = {sigma:.3f} %')
        ax.axhline(0.0, color='k', lw=0.5)
        ax.set_ylim(-CLIP_PCT * 1.05, CLIP_PCT * 1.05)
        ax.set_ylabel(f'Δ{component}/FS (%)')
        ax.legend(loc='upper right', fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel('load point number')
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def residual_figures(result, directory: Path) -> list[Path]:
    """One figure per model (linear, quadratic, cubic), and before/after for an adopted model."""
    config = result.config
    labels = result.points.label
    capacity = np.asarray(config.capacity)
    figures = []
    for order, model_fit in result.fits.items():
        pct = model_fit.fit.residuals / capacity * 100.0
        figures.append(residual_panels(pct, labels, config.components,
                                       f'{config.name}: {order} model residuals (cf. TM-663 Figs. 4-9)',
                                       directory / f'residuals_{order}.png'))
    if result.diagnosis is not None and result.diagnosis.effects:
        from ..diagnosis.plots import plot_effect, plot_residuals
        diagnosis = result.diagnosis        # 'before' is the base model's figure above
        figures.append(plot_residuals(diagnosis, directory / 'residuals_adopted.png', which='after'))
        figures.extend(plot_effect(diagnosis, effect, directory / f'effect_{effect.name}.png')
                       for effect in diagnosis.effects)
    return figures
