"""Residual plots of a diagnosis, in the style of TM-663 Figs. 4-9 (PNG, matplotlib Agg).

- `plot_residuals`: one figure per model, six panels (F_X ... M_Z), residual in % FS against point
  number, the vertical axis fixed at ±0.5 % FS as in the memo; points beyond it are drawn on the
  edge as open triangles so that nothing disappears silently.
- `plot_effect`: per effect found, the residual with that effect put back (partial residual)
  against the variable that explains it, with the fitted contribution (`draw_partial_residual`,
  which refit/plots.py's effect figure also draws with).
- `plot_unexplained`: per unexplained leftover, the residual against what it tracks and against
  point number, with the repeatability in the title.

Figures are built on `matplotlib.figure.Figure` with the Agg canvas (no pyplot state), so plotting
is safe inside a node's callback thread.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..figure_png import fixed_margins, Margins, save_png
from .diagnose import Diagnosis, EffectFound

if TYPE_CHECKING:
    from matplotlib.figure import Figure

CLIP_PCT_FS = 0.5  # the memo's vertical range of Figs. 4-9


def _save(figure: Figure, path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return save_png(figure, path, 110)


def _clipped_scatter(axes, x, y, clip, **style):
    inside = np.abs(y) <= clip
    axes.plot(x[inside], y[inside], linestyle='none', **style)
    for sign, marker in ((1, '^'), (-1, 'v')):
        outside = sign * y > clip
        if outside.any():
            axes.plot(
                x[outside],
                np.full(outside.sum(), sign * clip * 0.97),
                linestyle='none',
                marker=marker,
                markersize=5,
                markerfacecolor='none',
                color=style.get('color', 'k'),
            )


def plot_residuals(
    diagnosis: Diagnosis, path, *, which: str = 'after', clip_pct_fs: float = CLIP_PCT_FS
) -> Path:
    """Six panels of residual (% FS) vs point number for the base ('before') or adopted
    ('after') model.
    """
    if which not in ('before', 'after'):
        raise ValueError("which must be 'before' or 'after'")
    residuals = diagnosis.residuals_pct_fs(which)
    sigma = diagnosis.sigma_pct_fs[which]
    model = diagnosis.base_fit.name if which == 'before' else diagnosis.adopted.name
    labels = np.asarray(diagnosis.point_labels, dtype=float)
    from matplotlib.figure import Figure  # imported on drawing: a plan costs no matplotlib

    figure = Figure(figsize=(12, 6.5))
    figure.suptitle(
        f'{diagnosis.balance} — residuals of the {model} model '
        f'(exp − th, % F.S.; axis ±{clip_pct_fs:g} %)'
    )
    for k, component in enumerate(diagnosis.components):
        axes = figure.add_subplot(2, 3, k + 1)
        axes.axhline(0.0, color='0.6', linewidth=0.8)
        _clipped_scatter(
            axes, labels, residuals[:, k], clip_pct_fs, marker='o', markersize=2.5, color='C0'
        )
        axes.set_ylim(-clip_pct_fs, clip_pct_fs)
        axes.set_title(f'{component}: σ = {sigma[component]:.3f} % FS', fontsize=10)
        axes.set_xlabel('point number')
        axes.set_ylabel('residual (% FS)')
        axes.grid(True, linewidth=0.3)
    figure.tight_layout(rect=(0, 0, 1, 0.95))
    return _save(figure, path)


def draw_partial_residual(
    axes,
    x: np.ndarray,
    partial: np.ndarray,
    contribution: np.ndarray,
    *,
    sizes: tuple[float, float] = (2.5, 3),
    colors: tuple[str, str] = ('C0', 'C3'),
) -> None:
    """Draw on `axes` an effect's partial residual (residual + effect) against the variable x that
    explains it as dots, and the fitted effect in the order of x (marker sizes and colours: the
    partial residual's, then the effect's); returns nothing. Shared with refit/plots.py.
    """
    axes.plot(
        x,
        partial,
        linestyle='none',
        marker='o',
        markersize=sizes[0],
        color=colors[0],
        label='residual + effect',
    )
    order = np.argsort(x, kind='stable')
    axes.plot(
        x[order],
        contribution[order],
        linestyle='none',
        marker='.',
        markersize=sizes[1],
        color=colors[1],
        label='fitted effect',
    )


def plot_effect(diagnosis: Diagnosis, effect: EffectFound, path) -> Path:
    """Partial residual (final residual + this effect's contribution, % FS) vs its explaining
    variable.
    """
    components = list(effect.components)
    from matplotlib.figure import Figure

    figure = Figure(figsize=(max(6.0, 4.2 * len(components) + 0.5), 4.2))
    figure.suptitle(f'{diagnosis.balance} — {effect.name}: residual with the effect put back')
    for i, component in enumerate(components):
        k = diagnosis.components.index(component)
        scale = 100.0 / diagnosis.capacity[k]
        x = np.asarray(effect.explaining_values[component], dtype=float)
        contribution = np.asarray(effect.contribution[component]) * scale
        partial = diagnosis.residuals_after[:, k] * scale + contribution
        axes = figure.add_subplot(1, len(components), i + 1)
        draw_partial_residual(axes, x, partial, contribution)
        axes.set_xlabel(effect.explaining_variable[component])
        axes.set_ylabel(f'{component} residual (% FS)')
        axes.set_title(
            f'{component}: r = {effect.correlation[component]:.2f}, '
            f'removes {effect.removed_pct_fs[component]:.3f} % FS',
            fontsize=9,
        )
        axes.grid(True, linewidth=0.3)
        if i == 0:
            axes.legend(fontsize=8, loc='best')
    figure.tight_layout(rect=(0, 0, 1, 0.92))
    return _save(figure, path)


def plot_diagnosis(diagnosis: Diagnosis, directory) -> list[Path]:
    """Every figure of a diagnosis into `directory`: residuals before/after, one per effect."""
    directory = Path(directory)
    paths = [
        plot_residuals(
            diagnosis, directory / f'residuals_{diagnosis.base_model}.png', which='before'
        )
    ]
    if diagnosis.effects:
        paths.append(plot_residuals(diagnosis, directory / 'residuals_adopted.png', which='after'))
    for effect in diagnosis.effects:
        paths.append(plot_effect(diagnosis, effect, directory / f'effect_{effect.name}.png'))
    return paths + unexplained_figures(diagnosis, directory)


def plot_unexplained(diagnosis: Diagnosis, entry, path) -> Path:
    """What is left and unexplained (% FS): against what it tracks, and against point number."""
    component = entry.components[0]
    k = diagnosis.components.index(component)
    residual = (
        np.asarray(
            entry.residual if entry.residual is not None else diagnosis.residuals_after[:, k],
            dtype=float,
        )
        / diagnosis.capacity[k]
        * 100.0
    )
    from matplotlib.figure import Figure

    figure = Figure(figsize=(10, 4.2))
    figure.suptitle(
        f'{diagnosis.balance} — {component}: left over and not explained '
        f'(σ {entry.sigma_pct_fs[component]:.3f} % FS, repeatability '
        f'{diagnosis.repeatability_pct_fs.get(component, float("nan")):.3f} % FS)'
    )
    axes = figure.add_subplot(1, 2, 1)
    if entry.tracks_values is not None:
        x = np.asarray(entry.tracks_values, dtype=float)
        keep = np.isfinite(x)
        axes.plot(
            x[keep], residual[keep], linestyle='none', marker='o', markersize=2.5, color='C3'
        )
        axes.set_xlabel(f'{entry.tracks} (scaled to ±1; loaded points)')
    else:
        axes.text(
            0.5,
            0.5,
            'follows nothing examined',
            ha='center',
            va='center',
            transform=axes.transAxes,
        )
    axes.set_ylabel(f'{component} residual (% FS)')
    axes.grid(True, linewidth=0.3)
    axes = figure.add_subplot(1, 2, 2)
    axes.plot(
        np.asarray(diagnosis.point_labels, dtype=float),
        residual,
        linestyle='none',
        marker='o',
        markersize=2.5,
        color='C3',
    )
    axes.set_xlabel('point number')
    axes.grid(True, linewidth=0.3)
    figure.tight_layout(rect=(0, 0, 1, 0.92))
    return _save(figure, path)


def unexplained_figures(diagnosis: Diagnosis | None, directory) -> list[Path]:
    """One figure per unexplained entry (none without a diagnosis)."""
    return [draw(Path(directory) / name) for name, draw in unexplained_plan(diagnosis)]


def unexplained_plan(diagnosis: Diagnosis | None) -> list:
    """unexplained_figures as (file name, draw(path) -> path), nothing drawn yet."""
    if diagnosis is None:
        return []
    return [
        (
            f'unexplained_{entry.components[0]}.png',
            lambda path, entry=entry: plot_unexplained(diagnosis, entry, path),
        )
        for entry in diagnosis.unexplained
    ]


def plot_contrasts(diagnosis: Diagnosis, path, contrasts=None) -> Path | None:
    """Direction contrast (falling - rising at equal load, left) and sign contrast (r(+L) + r(-L),
    right) of the base model's residual (% FS) against the load (fraction of capacity), one row per
    component (diagnosis/contrasts.py), with the ±2√2 s band of two points' repeatability.
    None when the schedule offers no pair.
    """
    from .contrasts import schedule_contrasts

    contrasts = contrasts if contrasts is not None else schedule_contrasts(diagnosis)
    if not any(c.count for pair in contrasts.values() for c in pair):
        return None
    # only the contrasts the schedule offers pairs for: an empty panel says nothing
    shown = [
        (component, contrast)
        for component in diagnosis.components
        for contrast in contrasts[component]
        if contrast.count
    ]
    missing = [
        f'{component} {contrast.kind}'
        for component in diagnosis.components
        for contrast in contrasts[component]
        if not contrast.count
    ]
    rows = (len(shown) + 1) // 2
    from matplotlib.figure import Figure

    figure = Figure(figsize=(9, 1.2 + 1.9 * rows))  # two panels wide
    figure.suptitle(
        f'{diagnosis.balance} — what the schedule tells: loop (direction) vs sign '
        f'(base model residuals, % F.S.)'
        + (f'\nno pairs in the schedule for: {", ".join(missing)}' if missing else ''),
        fontsize=10,
    )
    for index, (component, contrast) in enumerate(shown):
        s = float(diagnosis.repeatability_pct_fs.get(component, float('nan')))
        axes = figure.add_subplot(rows, 2, index + 1)
        axes.axhline(0.0, color='0.6', linewidth=0.8)
        if np.isfinite(s) and s > 0:
            axes.axhspan(-2 * np.sqrt(2) * s, 2 * np.sqrt(2) * s, color='0.9')
        axes.plot(
            contrast.load_fraction,
            contrast.value_pct_fs,
            'o',
            markersize=3,
            color='C3' if contrast.kind == 'direction' else 'C0',
        )
        what = 'falling − rising' if contrast.kind == 'direction' else 'r(+L) + r(−L)'
        ratio = f'{contrast.ratio:.1f}' if np.isfinite(contrast.ratio) else '–'
        axes.set_title(
            f'{component} {contrast.kind}: {contrast.count} pairs, {ratio}× s²', fontsize=8
        )
        axes.set_xlabel(f'|{component}| / capacity of {component} (–)', fontsize=7)
        axes.set_ylabel(f'{what}, % FS', fontsize=7)
        axes.tick_params(labelsize=7)
    fixed_margins(
        figure,
        rows,
        2,
        Margins(
            left=0.65,
            right=0.15,
            bottom=0.45,
            top=0.4 + 0.17 * (2 if missing else 1),
            row_gap=0.7,
            column_gap=0.75,
        ),
    )
    return _save(figure, path)


def contrast_figures(diagnosis: Diagnosis | None, directory) -> list[Path]:
    """contrasts.png (none without a diagnosis or without pairs)."""
    return [draw(Path(directory) / name) for name, draw in contrast_plan(diagnosis)]


def contrast_plan(diagnosis: Diagnosis | None) -> list:
    """contrast_figures as (file name, draw(path) -> path): the contrasts are computed here (to
    know whether the schedule offers pairs), the figure is drawn later.
    """
    if diagnosis is None:
        return []
    from .contrasts import schedule_contrasts

    contrasts = schedule_contrasts(diagnosis)
    if not any(c.count for pair in contrasts.values() for c in pair):
        return []

    def draw(path: Path) -> Path:
        drawn = plot_contrasts(diagnosis, path, contrasts)
        if drawn is None:  # cannot happen: pairs were found above
            raise ValueError('the schedule offers no pairs to draw')
        return drawn

    return [('contrasts.png', draw)]
