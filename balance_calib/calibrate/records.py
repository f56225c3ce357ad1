"""What the record writer (write_record.py) writes for each side of the path: a bag calibration's
figures (refit/plots.py) and report.md (refit/report.py); a table calibration's residual figures
(tables/plots.py), report.md (tables/table_markdown.py) and point_uncertainty.csv.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Sequence, TYPE_CHECKING

from .write_record import Figure, Record

if TYPE_CHECKING:
    from ..refit.pipeline import CalibrationResult
    from ..tables.calibrate import TableCalibration


def bag_record(result: CalibrationResult) -> Record:
    """The record of a bag (or simulated) calibration."""
    from ..refit.plots import figure_plan
    from ..refit.report import report_markdown

    return Record(
        result.calibration,
        result.report,
        lambda report: report_markdown(report, result),
        figure_plan=lambda: figure_plan(result),
        result=result,
    )


def table_record(result: TableCalibration) -> Record:
    """The record of a table calibration, point_uncertainty.csv beside it."""
    from ..tables.table_markdown import report_markdown

    return Record(
        result.calibration,
        result.report,
        report_markdown,
        figure_plan=lambda: table_residual_plan(result),
        files={'point_uncertainty.csv': rows_csv(result.point_rows)},
        tool='fit',
        result=result,
    )


def table_residual_plan(result: TableCalibration) -> list[Figure]:
    """(residuals_METHOD.png, draw(path)) for each form fitted, residuals in % of capacity."""
    from ..tables.plots import residual_figure

    table = result.table
    capacity = table.load_capacity_si

    def plan(method: str, fit) -> Figure:
        def draw(path: Path) -> Path:
            return residual_figure(
                fit.load_residuals / capacity * 100.0,
                table.load_symbols,
                f'{table.balance_name or "balance"}: {method} method residuals',
                path,
            )

        return f'residuals_{method}.png', draw

    return [plan(method, fit) for method, fit in result.fits.items()]


def rows_csv(rows: Sequence[dict]) -> str:
    """point_uncertainty.csv's text: one row per point, floats to 6 significant digits."""
    buffer = io.StringIO()
    if rows:
        writer = csv.DictWriter(buffer, fieldnames=list(rows[0]), lineterminator='\n')
        writer.writeheader()
        for row in rows:
            writer.writerow(
                {k: (f'{v:.6g}' if isinstance(v, float) else v) for k, v in row.items()}
            )
    return buffer.getvalue()
