"""Residual plots of a refit in the style of TM-663 Figs. 4-9, one figure per model.

Every model (linear, quadratic, cubic and the adopted one) gets the same figure: six panels in
three rows of two (forces left, moments right), residual (exp − th, % FS, eqs. (38)-(43)) against
load point number on a fixed ±0.5 % FS axis as in the memo. Single-component loads, combined loads
and zero points have their own marker and colour (the memo's point: the linear model fails at
combined loads); points beyond ±0.5 % are drawn on the edge as open triangles and counted in the
panel title. Each effect the diagnosis adopted gets a figure of its partial residual against the
variable that explains it, at most two panels wide, axes in words and units.

Figures use `matplotlib.figure.Figure` with the Agg canvas (no pyplot state), so plotting is safe
inside a node's worker thread. 100 dpi: a figure is about 1000 px wide.
"""

from __future__ import annotations

from pathlib import Path
import re

import numpy as np

from .report_sections import combined_load_mask, PLOT_RANGE_PCT_FS

CLIP_PCT = PLOT_RANGE_PCT_FS
DPI = 100
_NICE = {'FX': 'F_X', 'FY': 'F_Y', 'FZ': 'F_Z', 'MX': 'M_X', 'MY': 'M_Y', 'MZ': 'M_Z'}
_CATEGORIES = (  # key, legend, marker, colour
    ('single', 'single-component load', 'o', 'tab:blue'),
    ('combined', 'combined load', 's', 'tab:orange'),
    ('zero', 'zero point (body only)', 'x', '0.45'),
)


def _nice(name: str) -> str:
    return _NICE.get(name, name)


def _save(figure, path: Path) -> Path:
    from ..figure_png import save_png

    return save_png(figure, path, DPI)


class ResidualFigure:
    """The six-panel residual figure, built once and redrawn for each model.

    Axes, labels, legend and layout are made once (fixed margins in inches, no tight_layout pass);
    `draw` only replaces the points and the titles, so a refit's 3-4 residual figures cost one
    build and one Agg draw each.
    """

    def __init__(self, components, rows: int | None = None) -> None:
        from matplotlib.figure import Figure
        from matplotlib.lines import Line2D

        from ..figure_png import Backdrop, fixed_margins, Margins

        self.components = list(components)
        rows = rows or int(np.ceil(len(self.components) / 2))
        self.rows = rows
        figure = Figure(figsize=(10.0, 2.75 * rows + 1.2))
        height = figure.get_figheight()
        # the layout tight_layout found for these labels, as fixed margins (inches)
        fixed_margins(
            figure,
            rows,
            2,
            Margins(left=0.75, right=0.15, bottom=0.55, top=1.05, row_gap=0.75, column_gap=0.95),
        )
        self.figure = figure
        self.panels = []
        for k, component in enumerate(self.components):
            # forces in the left column, moments in the right, as the memo's figures pair them
            column, row = divmod(k, rows)
            axes = figure.add_subplot(rows, 2, 2 * row + column + 1)
            axes.axhline(0.0, color='0.6', linewidth=0.8)
            series = {}
            for key, _, marker, colour in _CATEGORIES:
                inside = axes.plot(
                    [],
                    [],
                    linestyle='none',
                    marker=marker,
                    markersize=3.5,
                    markerfacecolor=colour if marker != 'x' else None,
                    markeredgewidth=0.8,
                    color=colour,
                )[0]
                edges = [
                    axes.plot(
                        [],
                        [],
                        linestyle='none',
                        marker=edge_marker,
                        markersize=6,
                        markerfacecolor='none',
                        markeredgewidth=1.0,
                        color=colour,
                    )[0]
                    for edge_marker in ('^', 'v')
                ]
                series[key] = (inside, edges)
            axes.set_ylim(-CLIP_PCT * 1.04, CLIP_PCT * 1.04)
            axes.grid(True, linewidth=0.3)
            axes.set_ylabel(f'residual {_nice(component)} (% FS)', fontsize=9)
            if row == rows - 1:
                axes.set_xlabel('load point number', fontsize=9)
            axes.tick_params(labelsize=8)
            self.panels.append((axes, series))
        handles = [
            Line2D(
                [],
                [],
                linestyle='none',
                marker=m,
                color=c,
                markerfacecolor=c if m != 'x' else None,
                label=name,
            )
            for _, name, m, c in _CATEGORIES
        ]
        handles.append(
            Line2D(
                [],
                [],
                linestyle='none',
                marker='^',
                markerfacecolor='none',
                color='k',
                label=f'beyond ±{CLIP_PCT:g} % FS, drawn on the edge',
            )
        )
        figure.legend(
            handles=handles,
            loc='upper center',
            ncol=4,
            fontsize=9,
            frameon=False,
            bbox_to_anchor=(0.5, 1.0 - 0.45 / height),
        )
        self.title = figure.suptitle('', fontsize=12)
        moving: list = [self.title] + [axes.title for axes, _ in self.panels]
        moving += [
            line
            for _, series in self.panels
            for inside, edges in series.values()
            for line in (inside, *edges)
        ]
        self.backdrop = Backdrop(figure, moving, DPI)

    def draw(self, residuals_pct: np.ndarray, labels, categories: np.ndarray, title: str, path):
        """residuals_pct (N, n_components); categories (N,) of 'single', 'combined', 'zero'."""
        from ..figure_png import decimated

        labels = np.asarray(labels, dtype=float)
        categories = np.asarray(categories, dtype=object)
        for k, (component, (axes, series)) in enumerate(zip(self.components, self.panels)):
            values = np.asarray(residuals_pct[:, k], dtype=float)
            sigma = float(np.sqrt(np.mean(values**2)))
            beyond = int(np.sum(np.abs(values) > CLIP_PCT))
            for key, _, _, _ in _CATEGORIES:
                chosen = np.flatnonzero(categories == key)
                chosen = chosen[decimated(labels[chosen], values[chosen])]
                x, y = labels[chosen], values[chosen]
                inside, (up, down) = series[key]
                keep = np.abs(y) <= CLIP_PCT
                inside.set_data(x[keep], y[keep])
                for sign, edge in ((1, up), (-1, down)):
                    out = sign * y > CLIP_PCT
                    edge.set_data(x[out], np.full(int(out.sum()), sign * CLIP_PCT * 0.96))
            axes.relim()
            axes.autoscale_view(scalex=True, scaley=False)
            clipped = f'; {beyond} beyond ±{CLIP_PCT:g} %' if beyond else ''
            # y given: matplotlib then leaves the title where it is instead of measuring every
            # tick label at each draw to lift it above them (nothing is above the axes here)
            axes.set_title(
                f'{_nice(component)}: σ = {sigma:.3f} %, 2σ = {2 * sigma:.3f} %{clipped}',
                fontsize=10,
                y=1.0,
            )
        self.title.set_text(title)
        limits = tuple(axes.get_xlim() for axes, _ in self.panels)
        return self.backdrop.save(Path(path), limits)


def residual_figure(
    residuals_pct: np.ndarray, labels, categories: np.ndarray, components, title: str, path: Path
) -> Path:
    """Six panels (3 rows x 2 columns) of residual % FS vs point number; returns path.

    residuals_pct (N, n_components); categories (N,) of 'single', 'combined', 'zero'.
    """
    return ResidualFigure(components).draw(residuals_pct, labels, categories, title, path)


def point_categories(points, config) -> np.ndarray:
    """'single', 'combined' or 'zero' per load point (TM-663 Table 2 blocks when the config has
    them).
    """
    categories = np.full(len(points.label), 'single', dtype=object)
    categories[combined_load_mask(points, config)] = 'combined'
    categories[np.asarray(points.is_zero_point)] = 'zero'
    return categories


_FACTOR_WORDS = [
    (re.compile(r'^dT$'), '(T − T_ref)', 'K'),
    (
        re.compile(r'^dir_(\w+)$'),
        '{0} load direction, referred to the zero points (+1 rising, −1 falling)',
        '',
    ),
    (re.compile(r'^\|(\w+)V\|$'), '|{0} bridge output|', 'mV'),
    (re.compile(r'^(\w+)V$'), '{0} bridge output', 'mV'),
    (re.compile(r'^drift_(sin|cos)_(\d+)$'), 'zero-drift {0} basis, harmonic {1}', ''),
]


def describe_variable(name: str) -> tuple[str, str]:
    """Words and unit for a diagnosis variable or term name ('dT*FXV' -> ('ΔT × F_X bridge
    output', 'K·mV')).
    """
    if name.startswith('time'):
        return 'time since the first point', 'h'
    if name.startswith('orientation'):
        return 'calibration body orientation I_g', ''
    words: list[str] = []
    powers: dict[str, int] = {}
    for factor in name.split('*'):
        base, _, power = factor.partition('^')
        text, unit = base, ''
        for pattern, template, factor_unit in _FACTOR_WORDS:
            match = pattern.match(base)
            if match:
                text = template.format(*(_nice(g) for g in match.groups()))
                unit = factor_unit
                break
        exponent = int(power) if power.isdigit() else 1
        if exponent != 1:
            wrapped = ' ' in text and not (text.startswith('(') and text.endswith(')'))
            text = (
                f'({text}){_superscript(exponent)}'
                if wrapped
                else f'{text}{_superscript(exponent)}'
            )
        words.append(text)
        if unit:
            powers[unit] = powers.get(unit, 0) + exponent
    return ' × '.join(words), '·'.join(
        u + (_superscript(n) if n != 1 else '') for u, n in powers.items()
    )


def _superscript(number: int) -> str:
    return str(number).translate(str.maketrans('0123456789', '⁰¹²³⁴⁵⁶⁷⁸⁹'))


def effect_figure(
    balance: str, effect, residuals_after: np.ndarray, capacity, components, path: Path
) -> Path:
    """Partial residual (residual of the adopted model + this effect, % FS) against the variable
    that explains it, with the fitted effect; at most two panels per row.
    """
    from matplotlib.figure import Figure

    from ..diagnosis.plots import draw_partial_residual

    chosen = list(effect.components)
    columns = min(2, len(chosen))
    rows = int(np.ceil(len(chosen) / columns))
    figure = Figure(figsize=(max(6.5, 5.0 * columns), 3.6 * rows + 0.8))
    figure.suptitle(f'{balance}: {effect.name} — residual with the effect put back', fontsize=11)
    for i, component in enumerate(chosen):
        k = list(components).index(component)
        scale = 100.0 / float(capacity[k])
        variable = effect.explaining_variable.get(component, '')
        x = np.asarray(effect.explaining_values[component], dtype=float)
        if variable.startswith('time'):
            x = (x - np.nanmin(x)) / 3600.0
        contribution = np.asarray(effect.contribution[component], dtype=float) * scale
        partial = residuals_after[:, k] * scale + contribution
        axes = figure.add_subplot(rows, columns, i + 1)
        draw_partial_residual(
            axes, x, partial, contribution, sizes=(3, 4), colors=('tab:blue', 'tab:red')
        )
        words, unit = describe_variable(variable)
        axes.set_xlabel(f'{words} ({unit})' if unit else words, fontsize=9)
        axes.set_ylabel(f'residual {_nice(component)} (% FS)', fontsize=9)
        axes.ticklabel_format(axis='x', useOffset=False, style='plain')
        axes.set_title(
            f'{_nice(component)}: r = {effect.correlation[component]:.2f}, '
            f'removes {effect.removed_pct_fs[component]:.3f} % FS',
            fontsize=10,
        )
        axes.grid(True, linewidth=0.3)
        axes.tick_params(labelsize=8)
        if i == 0:
            axes.legend(fontsize=8, loc='best')
    figure.tight_layout(rect=(0, 0, 1, 1.0 - 0.5 / figure.get_figheight()))
    return _save(figure, path)


def residual_figures(result, directory: Path) -> list[Path]:
    """One figure per model (linear, quadratic, cubic, and the adopted one when the diagnosis
    adopted effects), then one per effect.
    """
    directory = Path(directory)
    return [draw(directory / name) for name, draw in _residual_plan(result)]


def _residual_plan(result) -> list:
    """(file name, draw(path) -> path) of residual_figures, in its order; nothing drawn yet."""
    config = result.config
    labels = result.points.label
    capacity = np.asarray(config.capacity, dtype=float)
    categories = point_categories(result.points, config)
    shared: list[ResidualFigure] = []  # one figure, built at the first draw, reused

    def residuals(pct, point_labels, point_categories_, title):
        def draw(path: Path) -> Path:
            if not shared:
                shared.append(ResidualFigure(config.components))
            return shared[0].draw(pct, point_labels, point_categories_, title, path)

        return draw

    plan = [
        (
            f'residuals_{order}.png',
            residuals(
                model_fit.fit.residuals / capacity * 100.0,
                labels,
                categories,
                f'{config.name}: residuals of the {order} model (cf. TM-663 Figs. 4-9)',
            ),
        )
        for order, model_fit in result.fits.items()
    ]
    diagnosis = result.diagnosis
    if diagnosis is not None and diagnosis.effects:
        adopted_labels = np.asarray(diagnosis.point_labels)
        adopted_categories = categories
        if not np.array_equal(adopted_labels, np.asarray(labels)):
            lookup = dict(zip(np.asarray(labels).tolist(), categories))
            adopted_categories = np.array(
                [lookup.get(label, 'single') for label in adopted_labels.tolist()], object
            )
        plan.append(
            (
                'residuals_adopted.png',
                residuals(
                    diagnosis.residuals_after / capacity * 100.0,
                    adopted_labels,
                    adopted_categories,
                    f'{config.name}: residuals of the adopted model {diagnosis.adopted.name}',
                ),
            )
        )
        for effect in diagnosis.effects:

            def draw_effect(path: Path, effect=effect) -> Path:
                return effect_figure(
                    config.name,
                    effect,
                    diagnosis.residuals_after,
                    capacity,
                    config.components,
                    path,
                )

            plan.append((f'effect_{effect.name}.png', draw_effect))
    return plan


def figure_plan(result) -> list:
    """Every figure of a refit as (file name, draw(path) -> path), in report.md's order: the
    residual figures, one per unexplained leftover, the contrasts when the schedule offers pairs.
    The names are known before anything is drawn, so the report can be written first.
    """
    from ..diagnosis.plots import contrast_plan, unexplained_plan

    return (
        _residual_plan(result)
        + unexplained_plan(result.diagnosis)
        + contrast_plan(result.diagnosis)
    )
