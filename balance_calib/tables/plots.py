"""Residual figures of a table calibration, in the style of TM-663 Figs. 4-9 (% of capacity)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

CLIP_PCT = 0.5


def residual_figure(residuals_pct: np.ndarray, symbols, title: str, path: Path) -> Path:
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    n = len(symbols)
    rows = (n + 1) // 2
    fig, axes = plt.subplots(rows, 2, figsize=(11, 2.8 * rows), sharex=True, squeeze=False)
    labels = np.arange(1, residuals_pct.shape[0] + 1)
    for k, ax in enumerate(axes.T.reshape(-1)):
        if k >= n:
            ax.set_visible(False)
            continue
        values = residuals_pct[:, k]
        sigma = float(np.std(values, ddof=1)) if len(values) > 1 else 0.0
        ax.plot(
            labels, np.clip(values, -CLIP_PCT, CLIP_PCT), '.', ms=2, label=f'σ = {sigma:.4f} %'
        )
        ax.axhline(0.0, color='k', lw=0.5)
        ax.set_ylabel(f'Δ{symbols[k]} (% cap.)')
        ax.legend(loc='upper right', fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel('point')
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path
