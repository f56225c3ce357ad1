"""Writer of the BALFIT-style CSV layout: what `balfit_reader` reads, so a campaign recorded as a
bag can be handed to other tools. Numbers are written in the table's own units with Python's
shortest round-trip repr, so writer -> reader gives back identical arrays.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Sequence

import numpy as np

from .balfit_reader import CalibrationTable, FILE_TYPE, FIRST_DATA_COLUMN


def _number(value: float) -> str:
    return repr(float(value))


def table_text(table: CalibrationTable, comments: Sequence[str] = ()) -> str:
    """The CSV text of a table; every row has the same number of fields."""
    n_loads, n_outputs = len(table.load_symbols), len(table.output_symbols)
    width = FIRST_DATA_COLUMN + n_loads + n_outputs
    rows: list[list[str]] = []

    def row(*cells, values=()):
        cells = list(cells) + [''] * (FIRST_DATA_COLUMN - len(cells)) + list(values)
        rows.append(cells + [''] * (width - len(cells)))

    for comment in comments:
        row('; ' + comment)
    row('FILE_TYPE', FILE_TYPE)
    row('BALANCE_NAME', table.balance_name)
    row('DESCRIPTION', table.description)
    row('; load and output symbols')
    row(values=list(table.load_symbols) + list(table.output_symbols))
    row('; units')
    row(values=list(table.load_units) + list(table.output_units))
    row('; capacities')
    row(
        values=[_number(v) for v in table.load_capacity]
        + ['' if not np.isfinite(v) else _number(v) for v in table.output_capacity]
    )
    row('; natural zeros (roll angle in degrees in column D; load cells blank)')
    row(
        ';',
        'Point ID',
        'Set',
        'Roll (deg)',
        values=list(table.load_symbols) + list(table.output_symbols),
    )
    for zid, zset, roll, outputs in zip(
        table.zero_id, table.zero_set, table.zero_roll_deg, table.zero_outputs
    ):
        row('', zid, zset, _number(roll), values=[''] * n_loads + [_number(v) for v in outputs])
    row(
        '; data for analysis (C = load series, D = natural-zero set; applied loads, then raw '
        'outputs)'
    )
    row(
        '',
        'Point ID',
        'Load series',
        'Natural-zero set',
        values=list(table.load_symbols) + list(table.output_symbols),
    )
    for pid, series, zset, loads, outputs in zip(
        table.point_id, table.series, table.point_zero_set, table.applied_loads, table.outputs
    ):
        row(
            '',
            pid,
            str(int(series)),
            zset,
            values=[_number(v) for v in loads] + [_number(v) for v in outputs],
        )
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator='\n').writerows(rows)
    return buffer.getvalue()


def write_table(path: str | Path, table: CalibrationTable, comments: Sequence[str] = ()) -> Path:
    """Write atomically (a reader never sees half a table)."""
    from ..calibration_file import write_text_atomically

    write_text_atomically(path, table_text(table, comments))
    return Path(path)
