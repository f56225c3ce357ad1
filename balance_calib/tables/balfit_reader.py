"""Reader of calibration tables in the BALFIT-style CSV layout (interfaces.md,
field_data_format.md).

FILE_TYPE DATA_FOR_ITERATIVE_REGRESSION_ANALYSIS: keyword rows, then blocks announced by comment
rows (symbols, units, capacities, natural zeros, data). Any number of loads and outputs. Values are
kept as the file writes them (so that the writer reproduces them exactly) and converted to the
package's units on demand: loads to N / N·m, outputs to mV (mV/V for ratio units; counts and -
outputs as written: see units.py).
Every malformed input raises TableError with one line naming the file, row and column.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field, replace
from functools import cached_property
import io
from pathlib import Path
import re
from typing import Sequence

import numpy as np

from .units import is_load_unit, is_output_unit, known_unit, known_units, unit_factor

KEYWORDS = ('FILE_TYPE', 'BALANCE_NAME', 'DESCRIPTION')
FILE_TYPE = 'DATA_FOR_ITERATIVE_REGRESSION_ANALYSIS'
FIRST_DATA_COLUMN = 4  # column E: loads, then outputs
_SERIES_RE = re.compile(r'^\+?\d+$')


class TableError(ValueError):
    """A malformed calibration table; the message names the file, row and column."""


def column_letter(index: int) -> str:
    """Spreadsheet letter of a 0-based column index (0 -> A, 26 -> AA)."""
    letters = ''
    index += 1
    while index:
        index, rest = divmod(index - 1, 26)
        letters = chr(65 + rest) + letters
    return letters


@dataclass(frozen=True)
class CalibrationTable:
    """One table file (or several of one campaign, concatenated). Numbers in the file's units."""

    source: str
    file_type: str
    balance_name: str
    description: str
    load_symbols: tuple[str, ...]
    output_symbols: tuple[str, ...]
    load_units: tuple[str, ...]
    output_units: tuple[str, ...]
    load_capacity: np.ndarray  # (n_loads,) file units
    output_capacity: np.ndarray  # (n_outputs,) file units, NaN where blank
    zero_id: tuple[str, ...]  # natural-zero readings
    zero_set: tuple[str, ...]
    zero_roll_deg: np.ndarray
    zero_outputs: np.ndarray  # (n_zero, n_outputs) file units
    point_id: tuple[str, ...]  # data points (disabled ones skipped)
    series: np.ndarray  # (N,) positive ints: load series, one tare each
    point_zero_set: tuple[str, ...]  # natural-zero set label as written
    applied_loads: np.ndarray  # (N, n_loads) file units
    outputs: np.ndarray  # (N, n_outputs) file units, natural zero NOT removed
    disabled_points: int = 0
    row: np.ndarray = field(default_factory=lambda: np.zeros(0, int))  # file row of each point

    # --- units --------------------------------------------------------------------------------
    @cached_property
    def load_factor(self) -> np.ndarray:
        """(n_loads,) factor file unit -> N or N·m."""
        return np.array([known_unit(u)[0] for u in self.load_units])

    @cached_property
    def output_factor(self) -> np.ndarray:
        # an extra channel in a unit of its own (mm, %RH) is read as written
        return np.array([(unit_factor(u) or (1.0,))[0] for u in self.output_units])

    @property
    def load_si_units(self) -> tuple[str, ...]:
        return tuple(known_unit(u)[1] for u in self.load_units)

    @cached_property
    def bridge_columns(self) -> tuple[int, ...]:
        """Output columns that are bridge signals (volts or ratios); others are extra channels."""
        return tuple(i for i, u in enumerate(self.output_units) if is_output_unit(u))

    @property
    def bridge_symbols(self) -> tuple[str, ...]:
        return tuple(self.output_symbols[i] for i in self.bridge_columns)

    @property
    def output_internal_unit(self) -> str:
        units = {known_unit(self.output_units[i])[1] for i in self.bridge_columns}
        return units.pop() if len(units) == 1 else 'mixed'

    @property
    def n_loads(self) -> int:
        return len(self.load_symbols)

    @property
    def points(self) -> int:
        return len(self.point_id)

    @property
    def load_capacity_si(self) -> np.ndarray:
        return self.load_capacity * self.load_factor

    @property
    def applied_loads_si(self) -> np.ndarray:
        return self.applied_loads * self.load_factor

    # --- natural zeros ------------------------------------------------------------------------
    @cached_property
    def natural_zeros(self) -> dict[str, np.ndarray]:
        """Set label -> (n_outputs,) natural zero, file units: mean over roll angles of the mean
        per angle (gravity on the metric part cancels over opposite rolls).
        """
        zeros = {}
        for label in dict.fromkeys(self.zero_set):
            mask = np.array([s == label for s in self.zero_set])
            rolls = self.zero_roll_deg[mask]
            readings = self.zero_outputs[mask]
            per_angle = [readings[rolls == angle].mean(axis=0) for angle in np.unique(rolls)]
            zeros[label] = np.mean(per_angle, axis=0)
        return zeros

    @cached_property
    def resolved_zero_set(self) -> tuple[str, ...]:
        """The natural-zero set of each point ('' = none: the file has no natural zeros)."""
        sets = list(self.natural_zeros)
        return tuple(
            label if label in self.natural_zeros else (sets[0] if len(sets) == 1 else '')
            for label in self.point_zero_set
        )

    @cached_property
    def zeroed_outputs(self) -> np.ndarray:
        """(N, n_outputs) outputs minus their natural zero, file units."""
        zero = np.array(
            [
                self.natural_zeros[s] if s else np.zeros(len(self.output_symbols))
                for s in self.resolved_zero_set
            ]
        ).reshape(self.outputs.shape)
        return self.outputs - zero

    @property
    def bridge_outputs(self) -> np.ndarray:
        """(N, n_bridges) zeroed bridge outputs in mV (or mV/V), the columns of
        `bridge_columns`.
        """
        columns = list(self.bridge_columns)
        return self.zeroed_outputs[:, columns] * self.output_factor[columns]

    def series_labels(self) -> list[int]:
        return sorted(int(s) for s in np.unique(self.series))


def _cells(row: Sequence[str]) -> list[str]:
    return [cell.strip().strip('"').strip() for cell in row]


def _number(text: str, where: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise TableError(f'{where}: {what} {text!r} is not a number') from None
    if not np.isfinite(value):
        raise TableError(f'{where}: {what} {text!r} is not a finite number')
    return value


def read_table(
    path: str | Path, text: str | None = None, natural_zeros_from: CalibrationTable | None = None
) -> CalibrationTable:
    """Read one table file. TableError names the file, row and column of anything malformed.

    natural_zeros_from: a table of the same campaign (the calibration file) whose natural-zero
    readings a file without its own (a validation file) uses.
    """
    path = Path(path)
    name = str(path)
    if text is None:
        try:
            text = path.read_text(encoding='utf-8-sig')
        except UnicodeDecodeError:
            text = path.read_text(encoding='latin-1')
        except OSError as err:
            raise TableError(f'{name}: cannot read: {err.strerror or err}') from None
    try:
        rows = []
        reader = csv.reader(io.StringIO(text))
        for raw in reader:
            rows.append((reader.line_num, _cells(raw)))
    except csv.Error as err:
        raise TableError(f'{name}: row {reader.line_num}: not valid CSV: {err}') from None

    width = None
    for line, cells in rows:
        if not cells:
            continue
        if width is None:
            width, width_line = len(cells), line
        elif len(cells) != width:
            raise TableError(
                f'{name}: row {line}: {len(cells)} fields where row {width_line} has {width} '
                f'(ragged rows: every row must have the same number of fields)'
            )
    if width is None:
        raise TableError(f'{name}: empty file')

    keywords: dict[str, str] = {}
    block = None
    symbols_row = units_row = capacity_row = None
    zero_rows, data_rows = [], []
    disabled = 0
    data_title_seen = False
    for line, cells in rows:
        if not cells or not any(cells):
            continue
        first = cells[0]
        if first.startswith(';'):
            if len(cells) > 1 and cells[1].lower() == 'point id':
                data_title_seen = data_title_seen or block == 'data'
                continue
            if block == 'data' and data_title_seen:
                disabled += 1  # a switched-off point (or a remark) inside the data block
                continue
            text_lower = first.lstrip(';').strip().lower()
            if 'data' in text_lower:  # before 'zero': "; data for analysis (... natural zero ...)"
                block = 'data'
            elif 'capacit' in text_lower:
                block = 'capacities'
            elif 'zero' in text_lower:
                block = 'zeros'
            elif 'unit' in text_lower:
                block = 'units'
            elif 'symbol' in text_lower or 'name' in text_lower:
                block = 'symbols'
            continue
        if first.upper() in KEYWORDS:
            keywords[first.upper()] = cells[1] if len(cells) > 1 else ''
            continue
        if first:
            raise TableError(
                f'{name}: row {line}, column A: unexpected {first!r} (expected empty, a comment '
                f'starting with ";" or one of {", ".join(KEYWORDS)})'
            )
        if block == 'symbols':
            symbols_row = (line, cells)
        elif block == 'units':
            units_row = (line, cells)
        elif block == 'capacities':
            capacity_row = (line, cells)
        elif block == 'zeros':
            zero_rows.append((line, cells))
        elif block == 'data':
            if not data_title_seen and len(cells) > 1 and cells[1].lower() == 'point id':
                data_title_seen = True
                continue
            data_rows.append((line, cells))
        else:
            raise TableError(
                f'{name}: row {line}: a value row before any block comment '
                f'("; load and output symbols", "; units", ...)'
            )

    if keywords.get('FILE_TYPE', FILE_TYPE).upper() != FILE_TYPE:
        raise TableError(f'{name}: FILE_TYPE {keywords["FILE_TYPE"]!r} is not {FILE_TYPE}')
    if symbols_row is None:
        raise TableError(
            f'{name}: no symbols block ("; load and output symbols" then one row from column E)'
        )
    if units_row is None:
        raise TableError(f'{name}: no units block ("; units" then one row from column E)')
    if not data_rows:
        raise TableError(
            f'{name}: no data rows (a "; data for analysis" comment, a "Point ID" title row, '
            f'then one row per point)'
        )
    sym_line, sym_cells = symbols_row
    symbols = sym_cells[FIRST_DATA_COLUMN:]
    while symbols and not symbols[-1]:
        symbols.pop()
    if not symbols:
        raise TableError(f'{name}: row {sym_line}: no symbols from column E')
    for i, symbol in enumerate(symbols):
        if not symbol:
            raise TableError(
                f'{name}: row {sym_line}, column {column_letter(FIRST_DATA_COLUMN + i)}: '
                f'empty symbol between symbols'
            )
    n_columns = len(symbols)
    last = FIRST_DATA_COLUMN + n_columns
    unit_line, unit_cells = units_row
    units = unit_cells[FIRST_DATA_COLUMN:last]
    for i, unit in enumerate(units):
        where = f'{name}: row {unit_line}, column {column_letter(FIRST_DATA_COLUMN + i)}'
        if not unit:
            raise TableError(f'{where}: symbol {symbols[i]} has no unit')

    n_loads = _count_loads(zero_rows, capacity_row, units, n_columns)
    for i, unit in enumerate(units):
        # an extra channel may carry any unit (field_data_format.md: mm, %RH); a load may not,
        # nor an output in volts we cannot convert (mV/mA): that is a bridge signal
        where = f'{name}: row {unit_line}, column {column_letter(FIRST_DATA_COLUMN + i)}'
        if unit_factor(unit) is None and (i < n_loads or 'V' in unit):
            raise TableError(
                f'{where}: unit {unit!r} of {symbols[i]} is not known (known: {known_units()})'
            )
    if not 0 < n_loads < n_columns:
        raise TableError(
            f'{name}: cannot tell loads from outputs ({n_loads} loads among {n_columns} symbols)'
        )
    for i in range(n_columns):
        where = f'{name}: row {unit_line}, column {column_letter(FIRST_DATA_COLUMN + i)}'
        if i < n_loads and not is_load_unit(units[i]):
            raise TableError(
                f'{where}: load {symbols[i]} has unit {units[i]!r}, not a force or moment unit'
            )
    if not any(is_output_unit(u) for u in units[n_loads:]):
        raise TableError(
            f'{name}: row {unit_line}: no output has a bridge unit (mV, mV/V, microV/V, '
            f'counts, - ...)'
        )

    load_capacity = np.full(n_loads, np.nan)
    output_capacity = np.full(n_columns - n_loads, np.nan)
    if capacity_row is not None:
        cap_line, cap_cells = capacity_row
        for i in range(n_columns):
            text_value = cap_cells[FIRST_DATA_COLUMN + i]
            where = f'{name}: row {cap_line}, column {column_letter(FIRST_DATA_COLUMN + i)}'
            if not text_value:
                if i < n_loads:
                    raise TableError(f'{where}: load {symbols[i]} has no capacity')
                continue
            value = _number(text_value, where, f'capacity of {symbols[i]}')
            if i < n_loads:
                if value <= 0:
                    raise TableError(
                        f'{where}: capacity of {symbols[i]} must be positive, not {value:g}'
                    )
                load_capacity[i] = value
            else:
                output_capacity[i - n_loads] = value
    else:
        raise TableError(
            f'{name}: no capacities block ("; load capacities" then one row from column E)'
        )

    zero_id, zero_set, zero_roll, zero_outputs = [], [], [], []
    for line, cells in zero_rows:
        zero_id.append(cells[1])
        zero_set.append(cells[2])
        zero_roll.append(_number(cells[3], f'{name}: row {line}, column D', 'roll angle'))
        for i in range(n_loads):
            if cells[FIRST_DATA_COLUMN + i] not in ('',):
                value = _number(
                    cells[FIRST_DATA_COLUMN + i],
                    f'{name}: row {line}, column {column_letter(FIRST_DATA_COLUMN + i)}',
                    'load',
                )
                if value != 0.0:
                    raise TableError(
                        f'{name}: row {line}, column {column_letter(FIRST_DATA_COLUMN + i)}: '
                        f'a natural-zero reading carries load {value:g} (load cells must be blank)'
                    )
        zero_outputs.append(
            [
                _number(
                    cells[c],
                    f'{name}: row {line}, column {column_letter(c)}',
                    f'output {symbols[c - FIRST_DATA_COLUMN]}',
                )
                for c in range(FIRST_DATA_COLUMN + n_loads, last)
            ]
        )
    if not zero_rows and natural_zeros_from is not None and natural_zeros_from.zero_id:
        if natural_zeros_from.output_symbols != tuple(symbols[n_loads:]):
            raise TableError(
                f'{name}: outputs {", ".join(symbols[n_loads:])} differ from '
                f"{natural_zeros_from.source}'s, whose natural zeros it would use"
            )
        zero_id, zero_set = list(natural_zeros_from.zero_id), list(natural_zeros_from.zero_set)
        zero_roll = list(natural_zeros_from.zero_roll_deg)
        zero_outputs = [list(row) for row in natural_zeros_from.zero_outputs]
    sets = list(dict.fromkeys(zero_set))

    point_id, series, point_set, loads, outputs, point_row = [], [], [], [], [], []
    for line, cells in data_rows:
        if not cells[1]:
            raise TableError(f'{name}: row {line}, column B: empty point id')
        label = cells[2]
        if not _SERIES_RE.match(label) or int(label) <= 0:
            raise TableError(
                f'{name}: row {line}, column C: load series {label!r} is not a positive integer'
            )
        set_label = cells[3]
        if set_label not in sets and not (len(sets) == 1 or (not sets and not set_label)):
            known = ', '.join(repr(s) for s in sets) or 'none'
            raise TableError(
                f'{name}: row {line}, column D: natural-zero set {set_label!r} does not exist '
                f'(the file has {known})'
            )
        values = [
            _number(
                cells[c],
                f'{name}: row {line}, column {column_letter(c)}',
                f'{"load" if c - FIRST_DATA_COLUMN < n_loads else "output"} '
                f'{symbols[c - FIRST_DATA_COLUMN]}',
            )
            for c in range(FIRST_DATA_COLUMN, last)
        ]
        point_id.append(cells[1])
        series.append(int(label))
        point_set.append(set_label)
        loads.append(values[:n_loads])
        outputs.append(values[n_loads:])
        point_row.append(line)
    n_outputs = n_columns - n_loads
    return CalibrationTable(
        name,
        keywords.get('FILE_TYPE', FILE_TYPE),
        keywords.get('BALANCE_NAME', ''),
        keywords.get('DESCRIPTION', ''),
        tuple(symbols[:n_loads]),
        tuple(symbols[n_loads:]),
        tuple(units[:n_loads]),
        tuple(units[n_loads:]),
        load_capacity,
        output_capacity,
        tuple(zero_id),
        tuple(zero_set),
        np.array(zero_roll, float),
        np.array(zero_outputs, float).reshape(len(zero_id), n_outputs),
        tuple(point_id),
        np.array(series, dtype=int),
        tuple(point_set),
        np.array(loads, float).reshape(-1, n_loads),
        np.array(outputs, float).reshape(-1, n_outputs),
        disabled,
        np.array(point_row, dtype=int),
    )


def _count_loads(zero_rows, capacity_row, units: Sequence[str], n_columns: int) -> int:
    """field_data_format.md: blank load cells of a natural-zero row; else filled load capacities
    when the output capacities are blank; else, where the units tell (force and moment units first,
    none after: e.g. 6 loads and 8 outputs), their count; else half the symbols.
    """
    if zero_rows:
        line, cells = zero_rows[0]
        count = 0
        for cell in cells[FIRST_DATA_COLUMN : FIRST_DATA_COLUMN + n_columns]:
            if cell:
                break
            count += 1
        return count
    if capacity_row is not None:
        cells = capacity_row[1][FIRST_DATA_COLUMN : FIRST_DATA_COLUMN + n_columns]
        filled = [bool(c) for c in cells]
        count = 0
        while count < len(filled) and filled[count]:
            count += 1
        if count < n_columns and not any(filled[count:]):
            return count
    kinds = [is_load_unit(u) for u in units]
    count = kinds.index(False) if False in kinds else len(kinds)
    if 0 < count < n_columns and not any(kinds[count:]):
        return count
    return n_columns // 2


def read_tables(
    paths: Sequence[str | Path], natural_zeros_from: CalibrationTable | None = None
) -> CalibrationTable:
    """Several files of one campaign as one table (same symbols and units; series numbers shared).
    Files without natural zeros use those of `natural_zeros_from` (the campaign's calibration
    table).
    """
    tables = [read_table(p, natural_zeros_from=natural_zeros_from) for p in paths]
    if not tables:
        raise TableError('no table files given')
    first = tables[0]
    for table in tables[1:]:
        for key in ('load_symbols', 'output_symbols', 'load_units', 'output_units'):
            if getattr(table, key) != getattr(first, key):
                raise TableError(
                    f'{table.source}: {key.replace("_", " ")} {", ".join(getattr(table, key))} '
                    f'differ from {first.source}\'s {", ".join(getattr(first, key))}'
                )
    if len(tables) == 1:
        return first
    return _concatenate(tables)


def _concatenate(tables: Sequence[CalibrationTable]) -> CalibrationTable:
    first = tables[0]
    # natural-zero sets are per file: prefix them where files disagree
    zero_set, point_set = [], []
    for k, table in enumerate(tables):
        resolved = table.resolved_zero_set
        zero_set += [f'{k + 1}:{s}' for s in table.zero_set]
        point_set += [f'{k + 1}:{s}' if s else '' for s in resolved]
    return replace(
        first,
        source=', '.join(t.source for t in tables),
        zero_id=sum((t.zero_id for t in tables), ()),
        zero_set=tuple(zero_set),
        zero_roll_deg=np.concatenate([t.zero_roll_deg for t in tables]),
        zero_outputs=np.concatenate([t.zero_outputs for t in tables]),
        point_id=sum((t.point_id for t in tables), ()),
        series=np.concatenate([t.series for t in tables]),
        point_zero_set=tuple(point_set),
        applied_loads=np.concatenate([t.applied_loads for t in tables]),
        outputs=np.concatenate([t.outputs for t in tables]),
        disabled_points=sum(t.disabled_points for t in tables),
        row=np.concatenate([t.row for t in tables]),
    )
