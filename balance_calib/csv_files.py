"""What the CSV readers share (schedule_file.py, coverage/run_inputs.py): the file's text, and
rows of numbers checked finite, each error one line naming the file and the row.
"""

from __future__ import annotations

from contextlib import contextmanager
import csv
import math
from pathlib import Path
from typing import Iterator, Sequence


def read_csv_text(path: Path, what: str, error: type[Exception]) -> str:
    """The text of a CSV file, a UTF-8 byte-order mark (as spreadsheets write it) dropped.

    Raises `error` '<path>: cannot read the <what>: <reason>' for a missing, unreadable or
    non-UTF-8 file.
    """
    try:
        return path.read_text(encoding='utf-8-sig')
    except (OSError, UnicodeDecodeError) as err:
        reason = getattr(err, 'strerror', None) or err
        raise error(f'{path}: cannot read the {what}: {reason}') from None


def require_finite_loads(
    values: Sequence[float], path: Path, row: int, error: type[Exception]
) -> None:
    """Raise `error` '<path>: row <row>: loads must be finite numbers' for a NaN or infinity
    (row: the data row, 1 = the first after the header).
    """
    if not all(math.isfinite(v) for v in values):
        raise error(f'{path}: row {row}: loads must be finite numbers')


@contextmanager
def csv_errors(path: Path, error: type[Exception]) -> Iterator[None]:
    """Turn the csv module's own complaint (a field over its size limit, a broken quote) into
    `error` '<path>: not readable as CSV: <reason>'.
    """
    try:
        yield
    except csv.Error as err:
        raise error(f'{path}: not readable as CSV: {err}') from None
