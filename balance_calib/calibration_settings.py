"""What a calibration is asked to do and where its record goes (calibrate/path.py).

A module of its own beside calibration_points.py: both sides of the path (refit/, tables/) and
the calibrate/ package above them read it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, TYPE_CHECKING

if TYPE_CHECKING:
    from .model.calibration import Calibration

Progress = Callable[[str], None]


@dataclass(frozen=True)
class RecordOptions:
    """Where the calibration record is written (calibrate/write_record.py) and how.

    written(result, out_dir): called once calibration.yaml, report.json and report.md are in
    out_dir, before the figures are drawn (~/refit replies then).
    """

    out_dir: Path
    plots: bool = True
    overwrite: bool = True
    written: Callable[[Any, Path], None] | None = None


@dataclass(frozen=True)
class TableOptions:
    """The choices only a table calibration has (balance-calib fit, interfaces.md)."""

    method: str = 'auto'  # auto, direct or iterative
    terms: str = 'auto'  # auto, a term set's name or a file of term names
    validation: Any = None  # a tables.balfit_reader.CalibrationTable, or None
    excitation_v: float | None = None
    select: bool = False  # backward elimination of terms
    inputs: tuple[str, ...] = ()  # the files read, for the signed record


@dataclass(frozen=True)
class CalibrationSettings:
    """Everything calibrate(points, settings) needs besides the points.

    model: the TM-663 base model of a bag calibration; diagnose: examine the residuals for
    effects the model lacks; force: write a calibration that failed an acceptance gate (the
    report says so); active: the calibration in use, whose sensitivities a bag calibration must
    stay near; serial (default the balance config's) and operator: the signed record's; out: where
    the record is written (None: nothing is written).
    """

    model: str = 'cubic'
    diagnose: bool = True
    force: bool = False
    active: Calibration | None = None
    serial: str | None = None
    operator: str | None = None
    progress: Progress | None = None
    table: TableOptions = TableOptions()
    out: RecordOptions | None = None
