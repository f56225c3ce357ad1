"""A matplotlib Figure into a PNG file through the Agg canvas directly, and cheap figure helpers.

Figures are `matplotlib.figure.Figure` on their own Agg canvas (no pyplot state: safe in a worker
thread). `save_png` draws once and hands the RGBA buffer to the PNG writer at a low zlib level:
the same pixels as `savefig`, without its second pass and a third of its encoding time.
`decimated` keeps what a panel can show of a long series: per column the lowest and highest point.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

PNG_COMPRESS_LEVEL = 1  # zlib 1: ~20 % larger files, encoding 3x faster than the default 6
MAX_POINTS_PER_SERIES = 2000  # above this a series is decimated (decimated())
DECIMATION_COLUMNS = 500  # columns of a decimated series: two points each (lowest, highest)


def _agg_canvas(figure):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    if isinstance(figure.canvas, FigureCanvasAgg):
        return figure.canvas
    return FigureCanvasAgg(figure)


def _write_png(canvas, path, dpi: float) -> Path:
    from matplotlib.image import imsave  # Pillow underneath, as savefig

    path = Path(path)
    rgba = np.asarray(canvas.buffer_rgba())
    imsave(path, rgba, format='png', dpi=dpi, pil_kwargs={'compress_level': PNG_COMPRESS_LEVEL})
    return path


def save_png(figure, path, dpi: float) -> Path:
    """Draw `figure` with Agg at `dpi` and write it to `path` as PNG; returns path."""
    canvas = _agg_canvas(figure)
    figure.set_dpi(dpi)
    canvas.draw()
    return _write_png(canvas, path, dpi)


class Backdrop:
    """A figure whose static part (axes, ticks, labels, legend) is rendered once and whose
    `moving` artists (points, titles) are drawn over a copy of it for each file: the figures of
    several models that share axes cost one full draw.
    """

    def __init__(self, figure, moving, dpi: float) -> None:
        self.figure, self.moving, self.dpi = figure, list(moving), dpi
        for artist in self.moving:
            artist.set_animated(True)  # left out of canvas.draw(): the backdrop
        self._key: object = None
        self._background = None

    def save(self, path, key) -> Path:
        """Write the figure to path; `key` (e.g. the axis limits) changes when the backdrop
        must be drawn again.
        """
        canvas = _agg_canvas(self.figure)
        if self._background is None or key != self._key:
            self.figure.set_dpi(self.dpi)
            canvas.draw()
            self._background = canvas.copy_from_bbox(self.figure.bbox)
            self._key = key
        else:
            canvas.restore_region(self._background)
        for artist in self.moving:
            self.figure.draw_artist(artist)
        return _write_png(canvas, path, self.dpi)


def decimated(x, y, limit: int = MAX_POINTS_PER_SERIES, columns: int = DECIMATION_COLUMNS):
    """Indices of the points of (x, y) worth drawing: all of them up to `limit`, else in each of
    `columns` equal bins of x the lowest and the highest finite y (the envelope a scatter shows at
    that size; a point beyond an axis limit is an extreme of its bin and stays). Sorted, unique.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if len(x) <= limit:
        return np.arange(len(x))
    finite = np.flatnonzero(np.isfinite(x) & np.isfinite(y))
    if not len(finite):
        return finite
    xs, ys = x[finite], y[finite]
    low, high = float(xs.min()), float(xs.max())
    span = high - low if high > low else 1.0
    column = np.minimum(((xs - low) / span * columns).astype(np.intp), columns - 1)
    # lowest y per column: the first of each column in (column, y) order; highest: the last
    order = np.lexsort((ys, column))
    starts = np.flatnonzero(np.r_[True, np.diff(column[order]) != 0])
    ends = np.r_[starts[1:], len(order)] - 1
    return np.unique(finite[np.r_[order[starts], order[ends]]])


@dataclass(frozen=True)
class Margins:
    """A grid's margins around its panels and gaps between them, in inches."""

    left: float
    right: float
    bottom: float
    top: float
    row_gap: float
    column_gap: float


def fixed_margins(figure, rows: int, columns: int, margins: Margins) -> None:
    """Place a rows x columns grid of panels with `margins`: the layout tight_layout would find
    for known label sizes, without the extra drawing pass it costs.
    """
    m = margins
    width, height = figure.get_figwidth(), figure.get_figheight()
    panel_width = (width - m.left - m.right - (columns - 1) * m.column_gap) / columns
    panel_height = (height - m.bottom - m.top - (rows - 1) * m.row_gap) / rows
    figure.subplots_adjust(
        left=m.left / width,
        right=1.0 - m.right / width,
        bottom=m.bottom / height,
        top=1.0 - m.top / height,
        wspace=m.column_gap / panel_width if columns > 1 else 0.2,
        hspace=m.row_gap / panel_height if rows > 1 else 0.2,
    )


def _why(err: BaseException) -> str:
    return f'{type(err).__name__}: {" ".join(str(err).split())}'.rstrip(': ')


def _draw_each(figures, directory: Path) -> dict[str, str]:
    """Draw each (name, draw) as directory/name; name -> why for those that failed."""
    failed = {}
    for name, draw in figures:
        try:
            draw(directory / name)
        except Exception as err:  # one figure is not worth the others
            failed[name] = _why(err)
    return failed


def draw_figures(figures, directory, *, beside=lambda name: False) -> dict[str, str]:
    """Draw (name, draw(path)) into `directory`; returns name -> why for each that failed.

    The figures for which `beside(name)` is true are drawn in a forked child at the same time
    as the others (matplotlib holds the GIL: a thread would not overlap), when the process is
    single-threaded (a fork beside other threads could inherit a held lock) and both shares are
    non-empty; the child reports its failures in `.NAME.error` files and leaves with os._exit.
    """
    import os
    import threading

    directory = Path(directory)
    mine = [f for f in figures if not beside(f[0])]
    theirs = [f for f in figures if beside(f[0])]
    if not mine or not theirs or not hasattr(os, 'fork') or threading.active_count() > 1:
        return _draw_each(figures, directory)
    pid = os.fork()
    if pid == 0:  # the child: draw its share, say what failed, never return into the caller
        status = 1
        try:
            for name, why in _draw_each(theirs, directory).items():
                (directory / f'.{name}.error').write_text(why)
            status = 0
        finally:
            os._exit(status)
    failed = _draw_each(mine, directory)
    _, status = os.waitpid(pid, 0)
    for name, _ in theirs:
        error = directory / f'.{name}.error'
        if error.exists():
            failed[name] = error.read_text()
        elif not (directory / name).exists():
            failed[name] = f'the drawing process ended with status {status} before drawing it'
    return failed
